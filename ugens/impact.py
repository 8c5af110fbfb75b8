"""ImpactForce: raised-cosine (1 - cos) contact force pulses starting at sub-sample times.

An impact of impulse J (N s) and duration tau (s) starting at fractional sample t0 is

    F(n) = A (1 - cos(2 pi (n - t0) / T)),   t0 < n < t0 + T,   T = tau * fs samples,

with A chosen so that the sampled pulse integrates exactly to J: sum_n F(n) / fs = J.
Pulses are evaluated at absolute sample indices, so they may overlap freely and do not
depend on block boundaries. tau is at least 2 samples (a pulse must be sampled).
"""

from __future__ import annotations

import math
from typing import Any

import numba as nb
import numpy as np

from jassy.jit import drop_stale_cache
from jassy.params import ParamSpec
from jassy.registry import register
from jassy.ugen import UGen
from ugens import cells
from ugens.cells import (
    MIN_PULSE_SAMPLES,
    PULSE_AMPLITUDE,
    PULSE_COLUMNS,
    PULSE_LENGTH,
    PULSE_T0,
    append_pulse,
    append_pulses,
    pulse_amplitude,
    raised_cosine,
)

drop_stale_cache(__file__, [cells])  # render_pulses inlines cells.raised_cosine


@nb.njit(cache=True, inline="always")  # inlined, as jassy.engines.callback.apply_event
def render_pulses(out, start, n, pulses, count):
    """Write the sum of active pulses for frames start..start+n-1; return pulses left.

    pulses[i]: a cells.Pulse (t0, T, A). Finished pulses are removed (order kept).
    """
    for i in range(n):
        out[i] = 0.0
    for p in range(count):
        t0 = pulses[p, PULSE_T0]
        T = pulses[p, PULSE_LENGTH]
        A = pulses[p, PULSE_AMPLITUDE]
        first = max(start, int(math.floor(t0)) + 1)
        last = min(start + n, int(math.ceil(t0 + T)))
        for idx in range(first, last):
            x = idx - t0
            if x < T:
                out[idx - start] += A * raised_cosine(x, T)
    kept = 0
    end = start + n
    for p in range(count):
        if pulses[p, PULSE_T0] + pulses[p, PULSE_LENGTH] > end:
            for c in range(PULSE_COLUMNS):  # element-wise: a row slice copy compiles numba's shape-error text
                pulses[kept, c] = pulses[p, c]
            kept += 1
    return kept


class PulseSource(UGen):
    """Base of the ugens whose output is a table of 1 - cos pulses (ImpactForce, ImpactTrain):
    the table, its growth, rendering and saved state."""

    def _prepare(self) -> None:
        self.pulses = np.zeros((16, PULSE_COLUMNS))
        self.count = np.zeros(1, dtype=np.int64)
        self._idle = False

    def _reset(self) -> None:
        self.pulses[:] = 0.0
        self.count[0] = 0
        self._idle = False

    def add_pulse(self, sample_time: float, duration: float, impulse: float) -> None:
        """Start a pulse of ``impulse`` N s lasting ``duration`` s (at least MIN_PULSE_SAMPLES)
        at fractional sample ``sample_time``; its samples sum exactly to the impulse."""
        T = max(duration * self.sample_rate, MIN_PULSE_SAMPLES)
        c = int(self.count[0])
        amplitude = pulse_amplitude(float(impulse), float(self.sample_rate), float(sample_time), T)
        self.pulses = append_pulse(self.pulses, c, float(sample_time), T, amplitude)
        self.count[0] = c + 1
        self._idle = False

    def add_pulses(self, starts: np.ndarray, durations: np.ndarray, impulses: np.ndarray) -> None:
        """:meth:`add_pulse` for each (start, duration, impulse), in one compiled call."""
        lengths = np.maximum(np.asarray(durations, dtype=np.float64) * self.sample_rate, MIN_PULSE_SAMPLES)
        starts = np.ascontiguousarray(starts, dtype=np.float64)
        impulses = np.ascontiguousarray(impulses, dtype=np.float64)
        c = int(self.count[0])
        self.pulses = append_pulses(self.pulses, c, starts, lengths, impulses, float(self.sample_rate))
        self.count[0] = c + len(starts)
        self._idle = False

    def process(self, start: int, n: int) -> None:
        if self._idle:
            return
        c = int(self.count[0])
        self.count[0] = render_pulses(self.out, start, n, self.pulses, c)
        # out[:n] is zero from here on while no pulse is added
        self._idle = c == 0 and self.count[0] == 0 and n == self.max_block

    def state_arrays(self) -> dict[str, np.ndarray]:
        return {"pulses": self.pulses, "count": self.count}

    def set_state(self, state: dict[str, np.ndarray]) -> None:
        self.pulses = np.zeros_like(state["pulses"])  # the table may have grown since
        super().set_state(state)

    def _state_restored(self) -> None:
        self._idle = False


@register
class ImpactForce(PulseSource):
    """Contact force of impacts: 1 - cos pulses (JASS BangForce) with exact impulse.

    Output: force in N (each pulse integrates to its impulse in N s)."""

    type_name = "ImpactForce"
    param_specs = {
        "duration": ParamSpec(
            "float",
            0.001,
            low=0.0,
            low_open=True,
            high=1.0,
            unit="s",
            doc="default contact duration tau (shorter = harder)",
        ),
    }
    actions = {
        "impact": {
            "impulse": ParamSpec("float", 1e-3, low=0.0, high=1e6, unit="N s", doc="normal impulse J"),
            "duration": ParamSpec(
                "float",
                None,
                low=0.0,
                low_open=True,
                high=1.0,
                unit="s",
                doc="contact duration tau for this impact",
            ),
            "location": ParamSpec("location", None, doc="contact location on the struck model(s)"),
        }
    }

    #: Pulses are placed at their own sample time, and the parameters matter only when an
    #: impact starts (in event order): events need not split a sub-block.
    inline_events = True
    #: Its pulses are the score's impacts (listed, jassy.scheduler.ListedImpacts).
    score_impacts_only = True

    def set_param_at(self, frame: int, key: str, value: Any, jump: bool, ramp: float | None) -> None:
        """Change ``duration`` for the impacts from ``frame`` on: now, since every impact before
        ``frame`` has already been handed over (events come in time order)."""
        self.set_param(key, value, jump=jump, ramp=ramp)

    def strike(self, sample_time: float, impulse: float, duration: float | None = None) -> None:
        """Start a pulse of ``impulse`` N s at fractional sample ``sample_time``."""
        self.add_pulse(sample_time, self.values["duration"] if duration is None else duration, impulse)

    def act(self, action: str, args: dict[str, Any], sample_time: float) -> None:
        """``impact``: start a pulse (impulse N s, optional duration s) at ``sample_time``."""
        if action != "impact":
            return super().act(action, args, sample_time)
        self.strike(sample_time, args["impulse"], args.get("duration"))
