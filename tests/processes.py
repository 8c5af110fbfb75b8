"""Helpers for tests that drive ``jassy`` commands in child processes."""

from __future__ import annotations

import subprocess
import threading

import pytest

#: Seconds a command may take to print its first line: its kernels load from numba's cache
#: in seconds, but compile cold (a fresh clone) for a minute or more on a loaded machine.
STARTUP = 300.0


def read_line(proc: subprocess.Popen, seconds: float = STARTUP) -> str:
    """The next line ``proc`` prints (text-mode stdout); kills it and fails the test, saying
    so, if none comes within ``seconds`` (a blocking readline would hang the test)."""
    line: list[str] = []
    reader = threading.Thread(target=lambda: line.append(proc.stdout.readline()), daemon=True)
    reader.start()
    reader.join(seconds)
    if reader.is_alive():
        proc.kill()
        pytest.fail(
            f"{' '.join(map(str, proc.args[1:5]))} printed nothing within {seconds:.0f} s", pytrace=False
        )
    return line[0]


def rest_of_output(proc: subprocess.Popen, seconds: float = 5.0) -> str:
    """Kill ``proc`` and return what it printed that was not read yet, waiting at most
    ``seconds`` for the end of its output (for a failure's message: its children may hold
    the pipe open after it died)."""
    proc.kill()
    rest: list[str] = []
    reader = threading.Thread(target=lambda: rest.append(proc.stdout.read()), daemon=True)
    reader.start()
    reader.join(seconds)
    return rest[0] if rest else "(its output did not end)"
