"""Start a private JACK server with the dummy driver: a paced, real callback clock on
machines without a sound card (tests and ``jassy bench live``)."""

from __future__ import annotations

import contextlib
import os
import shutil
import subprocess
import tempfile
import time
from collections.abc import Iterator
from typing import NamedTuple

from jassy.engines.portaudio import LiveError

#: Seconds a fresh server has to come up, and then to answer a client.
START_TIMEOUT = 5.0
ANSWER_TIMEOUT = 10.0
#: Seconds between device listings while a server does not show up in them.
RETRY_PAUSE = 0.2
#: SCHED_FIFO priority of jackd's cycle (``jackd -R -P``; its clients' process threads
#: run 5 below): above jassy's own real-time helpers (the UDP frame sender at 45, the ring
#: producer at 40), which at jackd's default of 10 preempt the audio cycle. Measured,
#: ``jassy bench live`` at 64 frames: 31 and 42 underruns per minute at 70, 48 and 75 at 10.
REALTIME_PRIORITY = 70


class JackServer(NamedTuple):
    """A running private server: its name (JACK_DEFAULT_SERVER), jackd's process id and the
    file its messages go to (see :func:`server_xruns`)."""

    name: str
    pid: int
    log: str


class ServerXruns(NamedTuple):
    """Cycles jackd reported late, by cause, from its messages."""

    driver: int  # the dummy driver's own timer woke too late (no client involved)
    client: int  # a client had not finished its cycle in time


class ServerNotAnswering(LiveError):
    """jackd runs (its socket exists) but a client cannot connect within the time limit."""


@contextlib.contextmanager
def dummy_jack(
    name: str,
    sample_rate: int = 48000,
    period: int = 64,
    channels: int = 2,
    priority: int = REALTIME_PRIORITY,
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
        "-R",
        "-P",
        str(priority),
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
    # messages to a file, never a pipe: a pipe nobody reads fills and blocks jackd's cycle
    fd, log = tempfile.mkstemp(prefix=f"jackd-{name}-", suffix=".log")
    try:
        proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=fd)
    finally:
        os.close(fd)
    previous = {key: os.environ.get(key) for key in ("JACK_DEFAULT_SERVER", "JACK_NO_START_SERVER")}
    try:
        deadline = time.monotonic() + START_TIMEOUT
        while not _server_socket(name):
            if proc.poll() is not None:
                raise LiveError(f"jackd exited: {_read(log).strip()[-300:]}")
            if time.monotonic() > deadline:
                raise LiveError(f"jackd server {name!r} did not come up within {START_TIMEOUT:g} s")
            time.sleep(0.05)
        os.environ["JACK_DEFAULT_SERVER"] = name
        os.environ["JACK_NO_START_SERVER"] = "1"  # a client never starts a server of its own
        try:
            check_answers(name)
        except ServerNotAnswering as exc:
            raise ServerNotAnswering(f"{exc}; jackd's last messages: {_read(log).strip()[-300:]!r}") from None
        yield JackServer(name, proc.pid, log)
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
            proc.wait()
        os.unlink(log)


def server_xruns(log: str) -> ServerXruns:
    """Count the late cycles jackd 1.9 reported in its messages so far: the timed (dummy)
    driver's ``Process XRun`` (its own wake-up came after the next cycle was due) and the
    engine's ``XRun: client ...`` (a client was still busy). Both reach every client as
    PortAudio's output-underflow flag."""
    text = _read(log)
    return ServerXruns(text.count("Driver::Process XRun"), text.count("XRun: client"))


def _read(path: str) -> str:
    with open(path, errors="replace") as f:
        return f.read()


def check_answers(name: str, timeout: float = ANSWER_TIMEOUT) -> None:
    """Raise ServerNotAnswering unless PortAudio, as a client of the JACK server ``name``
    (JACK_DEFAULT_SERVER), lists a JACK device within ``timeout`` seconds.

    A listing without a JACK device is tried again until then: PortAudio leaves its JACK
    host API out when the connection fails, which a server still starting, or one slow to
    answer on a loaded machine, causes now and then (seen: one fixture in ~30 under load 9
    on 2 cores)."""
    from jassy.engines.devices import list_devices

    deadline = time.monotonic() + timeout
    tries = 0
    while True:
        tries += 1
        try:
            found = list_devices(max(deadline - time.monotonic(), 0.1))
        except LiveError as exc:
            raise ServerNotAnswering(f"JACK server {name!r} does not answer: {exc}") from None
        if any(d.host_api.upper().startswith("JACK") for d in found):
            return
        if time.monotonic() > deadline - RETRY_PAUSE:
            raise ServerNotAnswering(
                f"JACK server {name!r} does not answer: PortAudio lists no JACK device "
                f"({tries} tries in {timeout:g} s)"
            )
        time.sleep(RETRY_PAUSE)


def _server_socket(name: str) -> bool:
    """jackd 1.9 listens on <tmpdir>/jack_<name>_<uid>_0 (tmpdir /dev/shm on Linux)."""
    return any(os.path.exists(f"{d}/jack_{name}_{os.getuid()}_0") for d in ("/dev/shm", "/tmp"))
