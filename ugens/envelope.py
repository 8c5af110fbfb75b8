"""Envelope: an ADSR (or AD, with sustain = 0) control signal in [0, peak].

Each stage moves the level from ``start`` to ``end`` over m = round(time * fs) samples:
sample k = 0 .. m of the stage is

    start + (end - start) * c(k / m),   c(x) = x                                (linear)
                                        c(x) = (1 - e^(-5 x)) / (1 - e^(-5))      (exponential)

i.e. the exponential curve is an RC charge/discharge spanning five time constants, rescaled
to land exactly on ``end``. ``trigger`` (at frame t0) starts the attack from the current
level (k = 0 at t0) to peak = velocity, reached at frame t0 + round(attack * fs); the decay
then falls to sustain * peak, held until ``release``, which falls from the current level
(k = 0 at its frame) to 0 in round(release * fs) samples. A stage reads its parameters when
it starts.
"""

from __future__ import annotations

import math
from typing import Any

import numba as nb
import numpy as np

from jassy.params import ParamSpec
from jassy.registry import register
from jassy.ugen import UGen
from ugens.kernels import FASTMATH

IDLE, ATTACK, DECAY, SUSTAIN, RELEASE = range(5)
#: Time constants spanned by an exponential stage.
EXP_SPAN = 5.0


@nb.njit(fastmath=FASTMATH, cache=True)
def curve_at(x, span):
    """c(x) for x in [0, 1]: linear if span == 0, else RC-shaped over ``span`` time constants."""
    if span == 0.0:
        return x
    return (1.0 - math.exp(-span * x)) / (1.0 - math.exp(-span))


@nb.njit(fastmath=FASTMATH, cache=True)
def envelope(out, n, stage, level, decay_samples, sustain, span):
    """Run the stage machine for n samples; stage = [stage, k, m], level = [level, start, end, peak]."""
    st, k, m = stage[0], stage[1], stage[2]
    lev, start, end, peak = level[0], level[1], level[2], level[3]
    for i in range(n):
        if st in (ATTACK, DECAY, RELEASE):
            lev = end if k >= m else start + (end - start) * curve_at(k / m, span)
            if k < m:
                k += 1
            elif st == ATTACK:
                st, k, m, start, end = DECAY, 1, decay_samples, lev, sustain * peak
            else:
                st = SUSTAIN if st == DECAY else IDLE
        out[i] = lev
    stage[0], stage[1], stage[2] = st, k, m
    level[0], level[1], level[2] = lev, start, end


def _time_spec(default: float, doc: str) -> ParamSpec:
    return ParamSpec("float", default, low=0.0, high=3600.0, unit="s", doc=doc)


@register
class Envelope(UGen):
    """ADSR envelope generator driven by ``trigger`` and ``release`` actions."""

    type_name = "Envelope"
    param_specs = {
        "attack": _time_spec(0.01, "rise time from the current level to peak"),
        "decay": _time_spec(0.1, "fall time from peak to sustain * peak"),
        "sustain": ParamSpec("float", 0.5, low=0.0, high=1.0, doc="held level as a fraction of peak"),
        "release": _time_spec(0.2, "fall time from the current level to 0"),
        "curve": ParamSpec(
            "str",
            "linear",
            choices=("linear", "exponential"),
            fixed=True,
            doc="stage shape (see module docstring)",
        ),
    }
    actions = {
        "trigger": {"velocity": ParamSpec("float", 1.0, low=0.0, doc="peak level")},
        "release": {},
    }

    def _prepare(self) -> None:
        self.stage = np.zeros(3, dtype=np.int64)
        self.level = np.zeros(4)

    def _reset(self) -> None:
        self.stage[:] = (IDLE, 0, 0)
        self.level[:] = 0.0

    def _samples(self, key: str) -> int:
        return int(round(self.values[key] * self.sample_rate))

    def act(self, action: str, args: dict[str, Any], sample_time: float) -> None:
        if action == "trigger":
            self.level[3] = args["velocity"]
            self.stage[:] = (ATTACK, 0, self._samples("attack"))
            self.level[1:3] = (self.level[0], self.level[3])
        elif action == "release":
            self.stage[:] = (RELEASE, 0, self._samples("release"))
            self.level[1:3] = (self.level[0], 0.0)
        else:
            super().act(action, args, sample_time)

    def process(self, start: int, n: int) -> None:
        span = EXP_SPAN if self.values["curve"] == "exponential" else 0.0
        envelope(self.out, n, self.stage, self.level, self._samples("decay"), self.values["sustain"], span)

    def state_arrays(self):
        return {"stage": self.stage, "level": self.level}
