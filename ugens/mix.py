"""Gain, Mixer and Multiply: the arithmetic of signals."""

from __future__ import annotations

import numba as nb
import numpy as np

from jassy.errors import PatchError
from jassy.jit import specialise
from jassy.params import ParamSpec
from jassy.registry import register
from jassy.ugen import UGen
from ugens.kernels import FASTMATH


@nb.njit(fastmath=FASTMATH, cache=True)
def scale(x, out, n, gain):
    for i in range(n):
        out[i] = gain * x[i]


@nb.njit(fastmath=FASTMATH, cache=True)
def scale_ramp(x, out, n, gains):
    for i in range(n):
        out[i] = gains[i] * x[i]


@register
class Gain(UGen):
    """out = gain * input; gain changes are ramped unless a jump is asked for."""

    type_name = "Gain"
    inputs = ("input",)
    param_specs = {"gain": ParamSpec("float", 1.0, smooth=True, doc="linear gain")}

    def _prepare(self) -> None:
        self.gain = self.smoothed("gain")
        self.gains = np.zeros(self.max_block)
        self._input = self.sources["input"]
        self._scale = specialise(scale, self.out, self.out, 0, 0.0)

    def _reset(self) -> None:
        self.gain.set(self.gain.target, 0, jump=True)

    def _param_changed(self, key, value, jump) -> None:
        self.gain.set(value, self.ramp_samples(), jump)

    def process(self, start: int, n: int) -> None:
        x = self._input.out
        if self.gain.steady:
            self._scale(x, self.out, n, self.gain.value)
        else:
            scale_ramp(x, self.out, n, self.gain.fill(self.gains, n))

    def state_arrays(self):
        return {"gain": self.gain.ramp}


@nb.njit(fastmath=FASTMATH, cache=True)
def accumulate(x, out, n, gain):
    for i in range(n):
        out[i] += gain * x[i]


@register
class Mixer(UGen):
    """Sum of any number of inputs, each with its gain (``gains``, default all 1)."""

    type_name = "Mixer"
    variadic = True
    param_specs = {"gains": ParamSpec("floats", None, fixed=True, doc="one linear gain per input")}

    def _prepare(self) -> None:
        names = self.input_names()
        gains = self.values["gains"]
        if gains is None:
            gains = np.ones(len(names))
        if len(gains) != len(names):
            raise PatchError(
                f"nodes.{self.name}.gains: expected {len(names)} gains (one per input), got {len(gains)}"
            )
        self._terms = [(self.sources[k], float(g)) for k, g in zip(names, gains, strict=True)]
        self._first = specialise(scale, self.out, self.out, 0, 0.0)
        self._add = specialise(accumulate, self.out, self.out, 0, 0.0)

    def process(self, start: int, n: int) -> None:
        (src, gain), *rest = self._terms
        self._first(src.out, self.out, n, gain)
        for src, gain in rest:
            self._add(src.out, self.out, n, gain)


@nb.njit(fastmath=FASTMATH, cache=True)
def multiply(a, b, out, n):
    for i in range(n):
        out[i] = a[i] * b[i]


@register
class Multiply(UGen):
    """out = a * b (ring modulation, envelopes applied to signals)."""

    type_name = "Multiply"
    inputs = ("a", "b")

    def _prepare(self) -> None:
        self._a, self._b = self.sources["a"], self.sources["b"]

    def process(self, start: int, n: int) -> None:
        multiply(self._a.out, self._b.out, self.out, n)
