"""Reading what the user hands over: files as bytes, decoded and parsed with bounds, numbers
checked by type and range before any work starts.

Every failure is a :class:`jassy.errors.JassyError` whose message names the file (or the
option) and the key, and says what was expected, so the CLI prints one line and exits 2.

* Files are read as bytes from regular files only (a FIFO or a device such as /dev/zero
  would block or never end) and at most :data:`MAX_FILE_BYTES`; text must be UTF-8 and
  the error gives the byte offset of the first bad byte.
* TOML nests at most :data:`MAX_DEPTH` tables or arrays deep (the parser recurses per
  level; deeper input is refused instead of exhausting the stack).
* :func:`number` accepts int/float only (not booleans, strings or arrays), finite, within
  the range given, integral where a count is meant; a 20-digit integer or 1e308 is a range
  error, never an overflow later.
* :func:`require_extra`: an optional package an option needs is installed (before any work).
"""

from __future__ import annotations

import importlib.util
import math
import os
import stat
import tomllib
from pathlib import Path
from typing import Any

import numpy as np

from jassy.errors import JassyError

#: Largest input file read (bytes): patches, grids, designs and models are far smaller.
MAX_FILE_BYTES = 256 * 2**20
#: Largest text file parsed (bytes): TOML parses at a few MB/s, so this bounds the time too.
MAX_TEXT_BYTES = 64 * 2**20
#: Deepest nesting of tables/arrays accepted in a TOML file.
MAX_DEPTH = 32
#: Largest time in seconds an event, ramp or duration may name (1e7 s, 116 days): at
#: 768 kHz that is 7.7e12 samples, exact in float64 and int64.
MAX_SECONDS = 1e7


def regular_file(path: str | os.PathLike, what: str = "file") -> Path:
    """``path`` as a Path if it names an existing regular file, else a JassyError."""
    text = os.fspath(path)
    if not isinstance(text, str) or not text or "\0" in text:
        raise JassyError(f"{what}: expected a file name, got {text!r}")
    p = Path(text)
    try:
        info = p.stat()
    except FileNotFoundError:
        raise JassyError(f"{p}: no such {what}") from None
    except OSError as exc:
        raise JassyError(f"{p}: cannot read {what} ({exc.strerror or exc})") from None
    if stat.S_ISDIR(info.st_mode):
        raise JassyError(f"{p}: is a directory, expected a {what}")
    if not stat.S_ISREG(info.st_mode):
        raise JassyError(f"{p}: not a regular file (a device or pipe), expected a {what}")
    if info.st_size > MAX_FILE_BYTES:
        raise JassyError(f"{p}: {info.st_size / 2**20:.0f} MiB, larger than {what}s may be (256 MiB)")
    return p


def read_bytes(path: str | os.PathLike, what: str = "file") -> bytes:
    """The bytes of a regular file of at most MAX_FILE_BYTES (JassyError otherwise)."""
    p = regular_file(path, what)
    try:
        with open(p, "rb") as fh:
            data = fh.read(MAX_FILE_BYTES + 1)
    except OSError as exc:
        raise JassyError(f"{p}: cannot read {what} ({exc.strerror or exc})") from None
    if len(data) > MAX_FILE_BYTES:
        raise JassyError(f"{p}: larger than {what}s may be (256 MiB)")
    return data


def decode(data: bytes, where: str) -> str:
    """UTF-8 text of ``data`` (a leading byte-order mark is dropped); JassyError naming the
    offset of the first byte that is not UTF-8."""
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise JassyError(
            f"{where}: not UTF-8 text (byte 0x{data[exc.start]:02x} at offset {exc.start})"
        ) from None


def read_text(path: str | os.PathLike, what: str = "file") -> str:
    """The UTF-8 text of a regular file of at most MAX_TEXT_BYTES (see :func:`decode`)."""
    data = read_bytes(path, what)
    if len(data) > MAX_TEXT_BYTES:
        raise JassyError(f"{path}: {len(data) / 2**20:.0f} MiB, larger than text {what}s may be (64 MiB)")
    return decode(data, str(path))


def depth(value: Any) -> int:
    """Nesting depth of dicts and lists in ``value`` (iterative: any depth is measured)."""
    deepest, stack = 0, [(value, 0)]
    while stack:
        item, level = stack.pop()
        if isinstance(item, dict):
            items = item.values()
        elif isinstance(item, list):
            items = item
        else:
            continue
        level += 1
        deepest = max(deepest, level)
        if deepest > MAX_DEPTH:
            return deepest
        stack.extend((v, level) for v in items)
    return deepest


def parse_toml(text: str, where: str) -> dict:
    """Parse TOML text; JassyError for bad syntax, nesting deeper than MAX_DEPTH or more
    than MAX_TEXT_BYTES of text."""
    if len(text) > MAX_TEXT_BYTES:
        raise JassyError(f"{where}: larger than TOML files may be (64 MiB)")
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise JassyError(f"{where}: not valid TOML ({exc})") from None
    except RecursionError:
        raise JassyError(f"{where}: nested deeper than {MAX_DEPTH} tables/arrays") from None
    if depth(data) > MAX_DEPTH:
        raise JassyError(f"{where}: nested deeper than {MAX_DEPTH} tables/arrays")
    return data


def load_toml(path: str | os.PathLike, what: str = "file") -> dict:
    """Read, decode and parse a TOML file (JassyError naming the file on any problem)."""
    return parse_toml(read_text(path, what), str(path))


def _num(x: float) -> str:
    return str(int(x)) if float(x).is_integer() and abs(x) < 1e9 else f"{x:g}"


def _interval(low, high, low_open: bool, high_open: bool) -> str:
    if low is not None and high is not None:
        return f" in {'(' if low_open else '['}{_num(low)}, {_num(high)}{')' if high_open else ']'}"
    if low is not None:
        return f" {'>' if low_open else '>='} {_num(low)}"
    if high is not None:
        return f" {'<' if high_open else '<='} {_num(high)}"
    return ""


def number(
    value: Any,
    where: str,
    low: float | None = None,
    high: float | None = None,
    *,
    integer: bool = False,
    low_open: bool = False,
    high_open: bool = False,
) -> float | int:
    """``value`` checked as a finite number (an int if ``integer``) within the bounds.

    Booleans, strings, arrays and None are refused; an integral float is accepted for an
    integer (``1e3``), but not ``2.5``. Raises JassyError "WHERE: expected ..., got VALUE".
    """
    kind = "an integer" if integer else "a number"
    expected = f"{where}: expected {kind}{_interval(low, high, low_open, high_open)}, got {value!r}"
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise JassyError(expected)
    if isinstance(value, (float, np.floating)):
        if not math.isfinite(value) or (integer and not float(value).is_integer()):
            raise JassyError(expected)
        value = int(value) if integer else float(value)
    else:
        value = int(value)
        if not integer:
            if abs(value) > 1e300:  # float(value) would overflow or lose all meaning
                raise JassyError(expected)
            value = float(value)
    if low is not None and (value < low or (low_open and value == low)):
        raise JassyError(expected)
    if high is not None and (value > high or (high_open and value == high)):
        raise JassyError(expected)
    return value


def seconds(value: Any, where: str, *, allow_zero: bool = False) -> float:
    """A duration or time in seconds: finite, > 0 (>= 0 if ``allow_zero``), at most MAX_SECONDS."""
    try:
        return float(number(value, where, 0.0, MAX_SECONDS, low_open=not allow_zero))
    except JassyError:
        what = "a time in seconds >= 0" if allow_zero else "seconds > 0"
        raise JassyError(f"{where}: expected {what} (at most {_num(MAX_SECONDS)}), got {value!r}") from None


def text_value(value: Any, where: str, what: str = "a string") -> str:
    """``value`` if it is a non-empty string without NUL bytes, else a JassyError."""
    if not isinstance(value, str) or not value or "\0" in value:
        raise JassyError(f"{where}: expected {what}, got {value!r}")
    return value


def require_extra(module: str, extra: str, option: str) -> None:
    """Fail before any work if the optional ``module`` is missing, naming the extra to install."""
    try:
        found = importlib.util.find_spec(module) is not None
    except (ImportError, ValueError):
        found = False
    if not found:
        raise JassyError(f"{option}: {module} is not installed; install it with pip install 'jassy[{extra}]'")
