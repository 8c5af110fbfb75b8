"""Limiter: the brick-wall limiter of :mod:`jassy.safety` as a ugen."""

from __future__ import annotations

import numpy as np

from jassy.params import ParamSpec
from jassy.registry import register
from jassy.safety import CEILING, limit, release_coefficient
from jassy.ugen import UGen


@register
class Limiter(UGen):
    """Brick-wall limiter: |out| <= ceiling, instant attack, one-pole release; NaN/Inf -> 0.

    Changes of ``ceiling`` and ``release`` apply from the event's sample (not ramped: the
    gain itself recovers with the release time constant).
    """

    type_name = "Limiter"
    inputs = ("input",)
    param_specs = {
        "ceiling": ParamSpec(
            "float", CEILING, low=0.0, low_open=True, high=1.0, doc="peak output level (linear)"
        ),
        "release": ParamSpec("float", 0.05, low=0.0, unit="s", doc="time constant of the gain recovery"),
    }

    def _prepare(self) -> None:
        self.gain = np.ones(1)
        self._param_changed("release", self.values["release"], True)

    def _reset(self) -> None:
        self.gain[0] = 1.0

    def _param_changed(self, key, value, jump) -> None:
        if key == "release":
            self._release = release_coefficient(value, self.sample_rate)

    def process(self, start: int, n: int) -> None:
        self.out[:n] = self.sources["input"].out[:n]
        limit(self.out[None, :], n, self.gain, self.values["ceiling"], self._release)

    def state_arrays(self):
        return {"gain": self.gain}
