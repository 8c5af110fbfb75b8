"""Start a private JACK server with the dummy driver: a paced, real callback clock on
machines without a sound card (tests and ``jassy bench live``)."""

from __future__ import annotations

import contextlib
import os
import shutil
import subprocess
import time
from collections.abc import Iterator
from typing import NamedTuple

from jassy.portaudio import LiveError

#: Seconds a fresh server has to come up, and then to answer a client.
START_TIMEOUT = 5.0
ANSWER_TIMEOUT = 10.0


class JackServer(NamedTuple):
    """A running private server: its name (JACK_DEFAULT_SERVER) and jackd's process id."""

    name: str
    pid: int


class ServerNotAnswering(LiveError):
    """jackd runs (its socket exists) but a client cannot connect within the time limit."""


@contextlib.contextmanager
def dummy_jack(
    name: str, sample_rate: int = 48000, period: int = 64, channels: int = 2
) -> Iterator[JackServer]:
    """Run ``jackd -n NAME -d dummy`` for the duration of the block.

    Sets JACK_DEFAULT_SERVER so PortAudio's JACK host API (loaded afterwards in this
    process) talks to this server only. Raises LiveError if jackd is missing or fails, and
    ServerNotAnswering if a client (a device listing in a child process, killed at the
    limit) cannot talk to it within ``ANSWER_TIMEOUT`` seconds.
    """
    jackd = shutil.which("jackd")
    if jackd is None:
        raise LiveError("jackd not found (Debian/Ubuntu: apt-get install jackd2)")
    env = {**os.environ, "JACK_NO_AUDIO_RESERVATION": "1", "JACK_NO_START_SERVER": "1"}
    cmd = [
        jackd,
        "-n",
        name,
        "-d",
        "dummy",
        "-r",
        str(sample_rate),
        "-p",
        str(period),
        "-C",
        "0",
        "-P",
        str(channels),
    ]
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    previous = {key: os.environ.get(key) for key in ("JACK_DEFAULT_SERVER", "JACK_NO_START_SERVER")}
    try:
        deadline = time.monotonic() + START_TIMEOUT
        while not _server_socket(name):
            if proc.poll() is not None:
                raise LiveError(f"jackd exited: {proc.stderr.read().strip()[-300:]}")
            if time.monotonic() > deadline:
                raise LiveError(f"jackd server {name!r} did not come up within {START_TIMEOUT:g} s")
            time.sleep(0.05)
        os.environ["JACK_DEFAULT_SERVER"] = name
        os.environ["JACK_NO_START_SERVER"] = "1"  # a client never starts a server of its own
        check_answers(name)
        yield JackServer(name, proc.pid)
    finally:
        for key, value in previous.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value
        proc.terminate()
        try:
            proc.wait(timeout=3)
        except subprocess.TimeoutExpired:
            proc.kill()


def check_answers(name: str, timeout: float = ANSWER_TIMEOUT) -> None:
    """Raise ServerNotAnswering unless PortAudio, as a client of the JACK server ``name``
    (JACK_DEFAULT_SERVER), lists a JACK device within ``timeout`` seconds."""
    from jassy.devices import list_devices

    try:
        found = list_devices(timeout)
    except LiveError as exc:
        raise ServerNotAnswering(f"JACK server {name!r} does not answer: {exc}") from None
    if not any(d.host_api.upper().startswith("JACK") for d in found):
        raise ServerNotAnswering(f"JACK server {name!r}: PortAudio lists no JACK device")


def _server_socket(name: str) -> bool:
    """jackd 1.9 listens on <tmpdir>/jack_<name>_<uid>_0 (tmpdir /dev/shm on Linux)."""
    return any(os.path.exists(f"{d}/jack_{name}_{os.getuid()}_0") for d in ("/dev/shm", "/tmp"))
