"""Test-only ugens and helpers."""

from __future__ import annotations

import numpy as np

from jassy.ugen import UGen


class ArraySource(UGen):
    """Plays a fixed numpy array from frame 0 (zeros after its end)."""

    type_name = "ArraySource"

    def __init__(self, data, name=None):
        super().__init__(name=name)
        self.data = np.asarray(data, dtype=np.float64)

    def process(self, start, n):
        seg = self.data[start : start + n]
        self.out[: seg.size] = seg
        self.out[seg.size : n] = 0.0


class FailingSource(UGen):
    """Outputs zeros, then raises ``error`` once frame ``at`` is reached."""

    type_name = "FailingSource"

    def __init__(self, at, error, name=None):
        super().__init__(name=name)
        self.at, self.error = at, error

    def process(self, start, n):
        if start + n > self.at:
            raise self.error
        self.out[:n] = 0.0


class NaNSource(UGen):
    """A resonator-like ugen whose state turns NaN at frame ``at``."""

    type_name = "NaNSource"

    def __init__(self, at, name=None):
        super().__init__(name=name)
        self.at = at

    def _prepare(self):
        self.state = np.zeros(1)

    def _reset(self):
        self.state[0] = 0.0

    def process(self, start, n):
        t = start + np.arange(n)
        if start + n > self.at:
            self.state[0] = np.nan
        self.out[:n] = 0.5 * np.sin(0.05 * t) + self.state[0]

    def state_arrays(self):
        return {"state": self.state}


def max_abs_diff(a, b):
    return float(np.max(np.abs(np.asarray(a) - np.asarray(b))))
