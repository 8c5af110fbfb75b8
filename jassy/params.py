"""Parameter specifications, validation and per-sample linear smoothing.

A :class:`ParamSpec` describes one ugen parameter (type, default, range, unit). The same
spec validates Python keyword arguments, TOML patch values, ``--set`` overrides and score
events, so every entry point gives the same error for the same mistake.

Smoothing is defined per sample from the sample at which a change is applied: a linear
ramp of ``round(smooth * sample_rate)`` samples. It is therefore independent of how the
render is cut into blocks, which keeps the block-size invariance of the scheduler.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numba as nb
import numpy as np

from jassy.errors import PatchError

_KINDS = ("float", "int", "bool", "str", "location", "model", "floats")


@dataclass(frozen=True)
class ParamSpec:
    """One parameter of a ugen.

    kind: ``float``, ``int``, ``bool``, ``str`` (one of ``choices``), ``location``
    (vertex index or barycentric triple, see :func:`jassy.modal_model.parse_location`),
    ``model`` (a ModalModel or the name of one in the patch) or ``floats`` (list of numbers).
    ``smooth`` marks float parameters whose changes are ramped unless a jump is asked for.
    """

    kind: str
    default: Any = None
    low: float | None = None
    high: float | None = None
    low_open: bool = False
    unit: str = ""
    doc: str = ""
    smooth: bool = False
    required: bool = False
    fixed: bool = False
    choices: tuple[str, ...] = ()

    def __post_init__(self):
        if self.kind not in _KINDS:
            raise ValueError(f"unknown param kind {self.kind!r}")

    def expected(self) -> str:
        """Human description of an acceptable value, for error messages."""
        if self.kind == "str":
            return "one of " + ", ".join(repr(c) for c in self.choices)
        if self.kind in ("float", "int"):
            what = "a number" if self.kind == "float" else "an integer"
            if self.low is not None and self.high is not None:
                return f"{what} in {'(' if self.low_open else '['}{self.low}, {self.high}]"
            if self.low is not None:
                return f"{what} {'>' if self.low_open else '>='} {self.low}"
            if self.high is not None:
                return f"{what} <= {self.high}"
            return what
        return {
            "bool": "true or false",
            "location": "a location: vertex index, point name, {vertices=[i,j,k], weights=[u,v,w]} or "
            "{surface=[u,v]}",
            "model": "the name of a modal model",
            "floats": "a list of numbers",
        }[self.kind]

    def coerce(self, value: Any, where: str) -> Any:
        """Return ``value`` converted to this kind, or raise PatchError naming ``where``."""
        try:
            converted = self._converted(value)
        except (TypeError, ValueError, OverflowError):
            raise PatchError(f"{where}: expected {self.expected()}, got {value!r}") from None
        return value if converted is None else converted

    def _converted(self, value: Any) -> Any:
        """``value`` converted to this kind (None: location and model, checked by their
        owners); ValueError if it is not acceptable."""
        if self.kind == "float":
            if isinstance(value, bool) or not isinstance(value, (int, float, np.number)):
                raise ValueError
            value = float(value)
            if not math.isfinite(value):
                raise ValueError
        elif self.kind == "int":
            integral = isinstance(value, (int, np.integer)) or (
                isinstance(value, float) and value.is_integer()
            )
            if isinstance(value, bool) or not integral:
                raise ValueError
            value = int(value)
        elif self.kind == "bool":
            if not isinstance(value, (bool, np.bool_)):
                raise ValueError
            return bool(value)
        elif self.kind == "str":
            if not isinstance(value, str) or (self.choices and value not in self.choices):
                raise ValueError
            return value
        elif self.kind == "floats":
            arr = np.asarray(value, dtype=np.float64)
            if arr.ndim != 1 or not np.all(np.isfinite(arr)):
                raise ValueError
            return arr
        else:
            return None
        if self.low is not None and (value < self.low or (self.low_open and value == self.low)):
            raise ValueError
        if self.high is not None and value > self.high:
            raise ValueError
        return value


#: Fields of a ramp array (Smoothed.ramp and the ramps in jassy.program's records): the value
#: of the next sample, the target, the increment per sample and the samples left.
RAMP_NEXT, RAMP_TARGET, RAMP_INCREMENT, RAMP_SAMPLES = range(4)


@nb.njit(cache=True, inline="always")  # inlined, as jassy.engines.callback.apply_event
def ramp_fill(ramp, out, n):
    """Write n per-sample values of a linear ramp into out[:n] and advance it.

    ramp: the RAMP_* fields. A ramp of m samples set at frame e outputs the old value at e
    and the target from e + m on: the parameter is the straight line through (e, old) and
    (e + m, new), sampled.
    """
    cur = ramp[RAMP_NEXT]
    remaining = int(ramp[RAMP_SAMPLES])
    for i in range(n):
        out[i] = cur
        if remaining > 0:
            remaining -= 1
            cur = ramp[RAMP_TARGET] if remaining == 0 else cur + ramp[RAMP_INCREMENT]
    ramp[RAMP_NEXT] = cur
    ramp[RAMP_SAMPLES] = remaining


@nb.njit(cache=True, inline="always")
def ramp_to(ramp, value, samples):
    """Move a ramp (RAMP_* fields) to ``value``: at once if ``samples`` < 1, else linearly
    over ``samples`` samples from its next value (Smoothed.set in compiled code)."""
    if samples < 1:
        ramp[RAMP_NEXT] = value
        ramp[RAMP_TARGET] = value
        ramp[RAMP_INCREMENT] = 0.0
        ramp[RAMP_SAMPLES] = 0.0
    else:
        cur = ramp[RAMP_NEXT]
        ramp[RAMP_TARGET] = value
        ramp[RAMP_INCREMENT] = (value - cur) / samples
        ramp[RAMP_SAMPLES] = samples


class Smoothed:
    """A smoothed scalar parameter: linear ramp over a fixed number of samples.

    ``steady`` and ``value`` are plain attributes (read on every block by ugens).
    """

    __slots__ = ("ramp", "steady", "value")

    def __init__(self, value: float):
        self.ramp = np.array([value, value, 0.0, 0.0])
        self.steady = True
        self.value = float(value)

    @property
    def target(self) -> float:
        return float(self.ramp[RAMP_TARGET])

    def set(self, value: float, ramp_samples: int, jump: bool = False) -> None:
        """Move to ``value``: at once if ``jump`` or ramp_samples < 1, else linearly."""
        if jump or ramp_samples < 1:
            self.ramp[:] = (value, value, 0.0, 0.0)
        else:
            cur = self.ramp[RAMP_NEXT]
            self.ramp[:] = (cur, value, (value - cur) / ramp_samples, ramp_samples)
        self.sync()

    def sync(self) -> None:
        """Refresh ``steady``/``value`` after the ramp array changed (e.g. state restore)."""
        self.steady = bool(self.ramp[RAMP_SAMPLES] == 0)
        self.value = float(self.ramp[RAMP_NEXT])

    def fill(self, out: np.ndarray, n: int) -> np.ndarray:
        """Per-sample values for the next n samples (advances the ramp; see ramp_fill)."""
        ramp_fill(self.ramp, out, n)
        self.sync()
        return out[:n]


class Control:
    """A smoothed control's per-sample values for the kernels.

    While the control is steady its buffer holds the value throughout and is not
    rewritten on every block (the common case costs nothing).
    """

    __slots__ = ("buffer", "held", "ramp")

    def __init__(self, ramp: Smoothed, size: int):
        self.ramp = ramp
        self.buffer = np.zeros(size)
        self.held: float | None = None

    def values(self, n: int) -> np.ndarray:
        """Values for the next n samples (advances the ramp); read buffer[:n]."""
        ramp = self.ramp
        if ramp.steady:
            if self.held != ramp.value:
                self.buffer[:] = ramp.value
                self.held = ramp.value
        else:
            ramp.fill(self.buffer, n)
            self.held = None
        return self.buffer
