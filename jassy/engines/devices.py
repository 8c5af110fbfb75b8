"""Audio devices as ``sounddevice.query_devices()`` lists them (names and indices).

The listing runs in a short-lived child process with a time limit, for two reasons: a
sound server that accepts connections but never answers (a stopped JACK server) makes
PortAudio's initialisation block forever, and the calling process stays free of an
initialised PortAudio (the live engine forks its producer only from such a process).
Indices are PortAudio's device indices, the same ones the stream binding in
:mod:`jassy.engines.portaudio` opens.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from typing import NamedTuple

from jassy.engines.portaudio import LiveError

#: Seconds a device listing may take before the sound server counts as not answering.
LIST_TIMEOUT = 10.0

_LIST = """
import json, sys
try:
    import sounddevice as sd
except OSError as exc:
    print(json.dumps({"error": str(exc)}))
    sys.exit(0)
apis = sd.query_hostapis()
default_out = sd.default.device[1]
print(json.dumps({"devices": [
    dict(d, host_api=apis[d["hostapi"]]["name"], default=d["index"] == default_out)
    for d in sd.query_devices()
]}))
"""


class Device(NamedTuple):
    """One PortAudio device as sounddevice describes it."""

    index: int
    name: str
    host_api: str
    max_output_channels: int
    default_sample_rate: float
    default_low_output_latency: float
    default: bool


def list_devices(timeout: float = LIST_TIMEOUT) -> list[Device]:
    """Every device (input and output) from ``sounddevice.query_devices()``.

    Raises LiveError when PortAudio is missing or the listing takes longer than
    ``timeout`` seconds (the child is killed)."""
    try:
        run = subprocess.run(
            [sys.executable, "-c", _LIST],
            capture_output=True,
            text=True,
            timeout=timeout,
            env=os.environ.copy(),
        )
    except subprocess.TimeoutExpired:
        raise LiveError(
            f"listing audio devices took more than {timeout:g} s: the sound server does not answer"
        ) from None
    try:
        listing = json.loads(run.stdout.strip().splitlines()[-1])
    except (IndexError, json.JSONDecodeError):
        detail = run.stderr.strip()[-300:] or f"exit status {run.returncode}"
        raise LiveError(f"listing audio devices failed: {detail}") from None
    if "error" in listing:
        raise LiveError(
            "live audio needs the PortAudio library (Debian/Ubuntu: apt-get install libportaudio2); "
            f"offline rendering works without it ({listing['error']})"
        )
    return [
        Device(
            int(d["index"]),
            d["name"],
            d["host_api"],
            int(d["max_output_channels"]),
            float(d["default_samplerate"]),
            float(d["default_low_output_latency"]),
            bool(d["default"]),
        )
        for d in listing["devices"]
    ]


def output_devices(timeout: float = LIST_TIMEOUT) -> list[Device]:
    """The devices with at least one output channel."""
    return [d for d in list_devices(timeout) if d.max_output_channels > 0]


def find_device(spec: str | int | None, timeout: float = LIST_TIMEOUT) -> int:
    """The index of an output device: an index, a name substring, or None for the default."""
    found = output_devices(timeout)
    if not found:
        raise LiveError("no output devices found (see 'jassy devices')")
    if spec is None:
        default = [d.index for d in found if d.default]
        if not default:
            raise LiveError("no default output device (see 'jassy devices')")
        return default[0]
    if isinstance(spec, int) or (isinstance(spec, str) and spec.strip().isdigit()):
        index = int(spec)
        if not any(d.index == index for d in found):
            raise LiveError(f"--device {spec}: no output device with that index (see 'jassy devices')")
        return index
    matches = [d for d in found if spec.lower() in d.name.lower()]
    if len(matches) != 1:
        names = ", ".join(d.name for d in found)
        raise LiveError(f"--device {spec!r}: expected one matching output device; output devices: {names}")
    return matches[0].index


def describe(devices: list[Device]) -> str:
    """The ``jassy devices`` listing: one line per output device, * marks the default."""
    lines = [
        f"{'*' if d.default else ' '}{d.index:>3}  {d.name} ({d.host_api}): {d.max_output_channels} out, "
        f"{d.default_sample_rate:g} Hz, low latency {d.default_low_output_latency * 1e3:.1f} ms"
        for d in devices
        if d.max_output_channels > 0
    ]
    return "\n".join(lines) if lines else "no output devices found"
