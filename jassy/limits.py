"""Resource limits, checked up front: work that would not fit is refused before it starts.

Three limits, each with a command-line option (on every ``jassy`` command) and an
environment variable (read by worker processes and scripts too):

=================  =====================  ==================================================
option             environment            default
=================  =====================  ==================================================
``--max-memory``   ``JASSY_MAX_MEMORY``   half the machine's RAM, and no more than 90 % of
                                          what is available now (at least 256 MiB)
``--max-seconds``  ``JASSY_MAX_SECONDS``  3600 s of rendered or analysed audio per file
``--max-variants`` ``JASSY_MAX_VARIANTS`` 100000 batch variants (grid x random draws)
=================  =====================  ==================================================

Estimates (bytes) are made by the code that knows the sizes: frames x channels of arrays
held in memory, modes x locations of a model, voxel elements and subdivision levels of
``jassy modes``, samples of a recording for ``jassy fit``.
"""

from __future__ import annotations

import contextlib
import os
import re
from collections.abc import Iterator
from typing import NamedTuple

from jassy.errors import JassyError

DEFAULT_SECONDS = 3600.0
DEFAULT_VARIANTS = 100_000
MIN_MEMORY = 256 * 2**20
_UNITS = {"": 1, "k": 2**10, "m": 2**20, "g": 2**30, "t": 2**40}


class Limits(NamedTuple):
    """memory in bytes, seconds of audio per file, number of batch variants."""

    memory: int
    seconds: float
    variants: int


def _meminfo() -> dict[str, int]:
    out = {}
    try:
        with open("/proc/meminfo", "rb") as fh:
            for line in fh.read().decode("ascii", "replace").splitlines():
                key, _, rest = line.partition(":")
                parts = rest.split()
                if parts and parts[0].isdigit():
                    out[key] = int(parts[0]) * 1024
    except OSError:
        pass
    return out


def machine_memory() -> int:
    """Default memory limit (bytes): half the RAM, at most 90 % of what is available now."""
    info = _meminfo()
    try:
        total = info.get("MemTotal") or os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):  # pragma: no cover (not POSIX)
        total = 4 * 2**30
    limit = total // 2
    if "MemAvailable" in info:
        limit = min(limit, int(0.9 * info["MemAvailable"]))
    return max(MIN_MEMORY, limit)


def parse_size(text: str, where: str) -> int:
    """``"512M"``, ``"8G"``, ``"1.5g"`` or a number of bytes -> bytes (JassyError if not)."""
    match = re.fullmatch(r"\s*([0-9]+(?:\.[0-9]*)?)\s*([kKmMgGtT]?)(?:i?[bB])?\s*", str(text))
    if not match:
        raise JassyError(f"{where}: expected a size such as 512M or 8G, got {text!r}")
    value = float(match.group(1)) * _UNITS[match.group(2).lower()]
    if not 1 <= value <= 2**60:
        raise JassyError(f"{where}: expected a size between 1 byte and 1 EiB, got {text!r}")
    return int(value)


def _positive(text: str, where: str, integer: bool) -> float:
    try:
        value = int(text) if integer else float(text)
    except ValueError:
        value = -1
    if not (0 < value < float("inf")) or value > 1e12:
        raise JassyError(
            f"{where}: expected {'an integer' if integer else 'a number'} in (0, 1e12], got {text!r}"
        )
    return value


def current() -> Limits:
    """The limits in force: environment variables, else the machine-sized defaults."""
    env = os.environ
    memory = env.get("JASSY_MAX_MEMORY")
    seconds = env.get("JASSY_MAX_SECONDS")
    variants = env.get("JASSY_MAX_VARIANTS")
    return Limits(
        parse_size(memory, "JASSY_MAX_MEMORY") if memory else machine_memory(),
        _positive(seconds, "JASSY_MAX_SECONDS", False) if seconds else DEFAULT_SECONDS,
        int(_positive(variants, "JASSY_MAX_VARIANTS", True)) if variants else DEFAULT_VARIANTS,
    )


def configure(memory: str | None = None, seconds: str | None = None, variants: str | None = None) -> None:
    """Set limits from command-line values (also for child processes, via the environment)."""
    if memory is not None:
        os.environ["JASSY_MAX_MEMORY"] = str(parse_size(memory, "--max-memory"))
    if seconds is not None:
        os.environ["JASSY_MAX_SECONDS"] = repr(_positive(seconds, "--max-seconds", False))
    if variants is not None:
        os.environ["JASSY_MAX_VARIANTS"] = str(int(_positive(variants, "--max-variants", True)))


@contextlib.contextmanager
def scoped() -> Iterator[None]:
    """Limits set by :func:`configure` inside hold only until the block ends (one command)."""
    names = ("JASSY_MAX_MEMORY", "JASSY_MAX_SECONDS", "JASSY_MAX_VARIANTS")
    saved = {name: os.environ.get(name) for name in names}
    try:
        yield
    finally:
        for name, value in saved.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value


def _size(n: float) -> str:
    for unit, scale in (("TiB", 2**40), ("GiB", 2**30), ("MiB", 2**20), ("KiB", 2**10)):
        if n >= scale:
            return f"{n / scale:.3g} {unit}"
    return f"{n:.0f} B"


def check_memory(estimate: float, what: str) -> None:
    """Refuse work estimated to need more than the memory limit (``estimate`` in bytes)."""
    limit = current().memory
    if not estimate <= limit:
        raise JassyError(
            f"{what}: needs about {_size(estimate)} of memory, more than the limit of {_size(limit)}; "
            "raise it with --max-memory (or JASSY_MAX_MEMORY) if the machine has it"
        )


def check_seconds(seconds: float, what: str, default: float | None = None) -> None:
    """Refuse rendering or analysing more than the limit of seconds of audio (``default``,
    if given, replaces DEFAULT_SECONDS when no limit was set: for slower work)."""
    limit = current().seconds
    if default is not None and not os.environ.get("JASSY_MAX_SECONDS"):
        limit = default
    if not seconds <= limit:
        raise JassyError(
            f"{what}: {seconds:g} s of audio is more than the limit of {limit:g} s; "
            "raise it with --max-seconds (or JASSY_MAX_SECONDS)"
        )


def check_variants(count: float, what: str) -> None:
    """Refuse a batch of more variants than the limit (``count`` may be a float estimate)."""
    limit = current().variants
    if not count <= limit:
        raise JassyError(
            f"{what}: {count:.3g} variants, more than the limit of {limit}; "
            "raise it with --max-variants (or JASSY_MAX_VARIANTS)"
        )
