"""Start a private JACK server with the dummy driver: a paced, real callback clock on
machines without a sound card (tests and ``jassy bench live``)."""

from __future__ import annotations

import contextlib
import os
import shutil
import subprocess
import time
from collections.abc import Iterator

from jassy.portaudio import LiveError


@contextlib.contextmanager
def dummy_jack(name: str, sample_rate: int = 48000, period: int = 64, channels: int = 2) -> Iterator[str]:
    """Run ``jackd -n NAME -d dummy`` for the duration of the block; yields the name.

    Sets JACK_DEFAULT_SERVER so PortAudio's JACK host API (loaded afterwards in this
    process) talks to this server only. Raises LiveError if jackd is missing or fails.
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
    previous = os.environ.get("JACK_DEFAULT_SERVER")
    try:
        deadline = time.monotonic() + 5.0
        while not _server_socket(name):
            if proc.poll() is not None:
                raise LiveError(f"jackd exited: {proc.stderr.read().strip()[-300:]}")
            if time.monotonic() > deadline:
                raise LiveError(f"jackd server {name!r} did not come up within 5 s")
            time.sleep(0.05)
        os.environ["JACK_DEFAULT_SERVER"] = name
        yield name
    finally:
        if previous is None:
            os.environ.pop("JACK_DEFAULT_SERVER", None)
        else:
            os.environ["JACK_DEFAULT_SERVER"] = previous
        proc.terminate()
        try:
            proc.wait(timeout=3)
        except subprocess.TimeoutExpired:
            proc.kill()


def _server_socket(name: str) -> bool:
    """jackd 1.9 listens on <tmpdir>/jack_<name>_<uid>_0 (tmpdir /dev/shm on Linux)."""
    return any(os.path.exists(f"{d}/jack_{name}_{os.getuid()}_0") for d in ("/dev/shm", "/tmp"))
