"""Biquad (RBJ Audio-EQ-Cookbook low-, high- and band-pass) and OnePole low-pass filters.

Coefficients are designed in float64. While a smoothed parameter ramps, coefficients are
recomputed every sample from the per-sample parameter values, so the output does not
depend on block boundaries; once the ramps are steady the last coefficients are reused.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba as nb
import numpy as np

from jassy.errors import PatchError
from jassy.jit import drop_stale_cache
from jassy.params import ParamSpec
from jassy.registry import register
from jassy.ugen import UGen
from ugens import cells
from ugens.cells import store
from ugens.kernels import FASTMATH

drop_stale_cache(__file__, [cells])  # its cache holds copies of their kernels

MODES = ("lowpass", "highpass", "bandpass")
_LOWPASS, _HIGHPASS = 0, 1


class BiquadCoefficients(NamedTuple):
    """A biquad's coefficients normalised by a0, stored in this order in the float64 array
    ``coef``: H(z) = (b0 + b1 z^-1 + b2 z^-2) / (1 + a1 z^-1 + a2 z^-2)."""

    b0: float
    b1: float
    b2: float
    a1: float
    a2: float


@nb.njit(inline="always", cache=True)
def biquad_coefficients(coef):
    """The BiquadCoefficients record held in ``coef``."""
    return BiquadCoefficients(coef[0], coef[1], coef[2], coef[3], coef[4])


class BiquadState(NamedTuple):
    """The Direct Form II transposed state, stored in this order in the float64 array ``state``."""

    s1: float
    s2: float


@nb.njit(inline="always", cache=True)
def biquad_state(state):
    """The BiquadState record held in ``state``."""
    return BiquadState(state[0], state[1])


@nb.njit(inline="always", cache=True)
def biquad_step(c, x, s1, s2):
    """One sample of Direct Form II transposed with coefficients ``c`` (a BiquadCoefficients
    record): (output y, state s1, state s2) after input x."""
    y = c.b0 * x + s1
    return y, c.b1 * x - c.a1 * y + s2, c.b2 * x - c.a2 * y


@nb.njit(fastmath=FASTMATH, cache=True)
def design_biquad(mode, freq, q, inv_fs, coef):
    """RBJ cookbook coefficients normalised by a0 into ``coef`` (a BiquadCoefficients).

    mode 0 low-pass, 1 high-pass, 2 band-pass with 0 dB peak gain; freq in Hz.
    """
    w0 = 2.0 * math.pi * freq * inv_fs
    cw = math.cos(w0)
    alpha = math.sin(w0) / (2.0 * q)
    if mode == _LOWPASS:
        b1 = 2.0 * math.sin(0.5 * w0) ** 2  # 1 - cos(w0), accurate at low freq
        b0 = 0.5 * b1
        b2 = b0
    elif mode == _HIGHPASS:
        b1 = -2.0 * math.cos(0.5 * w0) ** 2  # -(1 + cos(w0))
        b0 = -0.5 * b1
        b2 = b0
    else:
        b0 = alpha
        b1 = 0.0
        b2 = -alpha
    inv_a0 = 1.0 / (1.0 + alpha)
    normalised = BiquadCoefficients(
        b0 * inv_a0, b1 * inv_a0, b2 * inv_a0, -2.0 * cw * inv_a0, (1.0 - alpha) * inv_a0
    )
    store(coef, normalised)


@nb.njit(cache=True)
def biquad(x, out, n, coef, state):
    """Direct Form II transposed with fixed coefficients (``coef``: a BiquadCoefficients,
    ``state``: a BiquadState).

    Compiled without fastmath, as is :func:`biquad_ramp`: a recurrence has nothing to
    vectorise, and reassociation across unrolled iterations made the output depend on
    where a block was cut."""
    c = biquad_coefficients(coef)
    s1, s2 = biquad_state(state)
    for i in range(n):
        out[i], s1, s2 = biquad_step(c, x[i], s1, s2)
    store(state, BiquadState(s1, s2))


@nb.njit(cache=True)
def biquad_ramp(x, out, n, mode, freqs, qs, inv_fs, coef, state):
    """Direct Form II transposed, coefficients redesigned each sample from freqs[i], qs[i]."""
    s1, s2 = biquad_state(state)
    for i in range(n):
        design_biquad(mode, freqs[i], qs[i], inv_fs, coef)
        out[i], s1, s2 = biquad_step(biquad_coefficients(coef), x[i], s1, s2)
    store(state, BiquadState(s1, s2))


@register
class Biquad(UGen):
    """Second-order RBJ filter: low-pass, high-pass or band-pass (0 dB peak) at ``freq``."""

    type_name = "Biquad"
    inputs = ("input",)
    param_specs = {
        "mode": ParamSpec("str", "lowpass", choices=MODES, fixed=True, doc="filter response"),
        "freq": ParamSpec(
            "float",
            1000.0,
            low=0.0,
            low_open=True,
            unit="Hz",
            smooth=True,
            doc="cutoff (low/high-pass) or centre (band-pass) frequency, below Nyquist",
        ),
        "q": ParamSpec(
            "float", 1.0 / math.sqrt(2.0), low=0.0, low_open=True, smooth=True, doc="quality factor"
        ),
    }

    def check_param(self, key, value, where):
        """Also reject ``freq`` at or above Nyquist once the sample rate is known."""
        value = super().check_param(key, value, where)
        if key == "freq" and self.sample_rate is not None and value >= 0.5 * self.sample_rate:
            raise PatchError(
                f"{where}: expected a frequency below Nyquist ({0.5 * self.sample_rate:g} Hz), got {value!r}"
            )
        return value

    def _prepare(self) -> None:
        self.check_param("freq", self.values["freq"], f"nodes.{self.name}.freq")
        self.mode = MODES.index(self.values["mode"])
        self.freq = self.smoothed("freq")
        self.q = self.smoothed("q")
        self.coef = np.zeros(len(BiquadCoefficients._fields))
        self.state = np.zeros(len(BiquadState._fields))
        self._freqs = np.zeros(self.max_block)
        self._qs = np.zeros(self.max_block)

    def _design(self) -> None:
        """Coefficients for the current values (the ramp kernel redesigns while ramping)."""
        design_biquad(self.mode, self.freq.value, self.q.value, 1.0 / self.sample_rate, self.coef)

    def _reset(self) -> None:
        for ramp in (self.freq, self.q):
            ramp.set(ramp.target, 0, jump=True)
        self.state[:] = 0.0
        self._design()

    def _param_changed(self, key, value, jump) -> None:
        getattr(self, key).set(value, self.ramp_samples(), jump)
        self._design()

    def process(self, start: int, n: int) -> None:
        x = self.sources["input"].out
        if self.freq.steady and self.q.steady:
            biquad(x, self.out, n, self.coef, self.state)
        else:
            freqs = self.freq.fill(self._freqs, n)
            qs = self.q.fill(self._qs, n)
            biquad_ramp(x, self.out, n, self.mode, freqs, qs, 1.0 / self.sample_rate, self.coef, self.state)
            if self.freq.steady and self.q.steady:
                self._design()  # the ramps just ended: coefficients for the targets

    def state_arrays(self):
        return {"state": self.state, "coef": self.coef, "freq": self.freq.ramp, "q": self.q.ramp}


@nb.njit(fastmath=FASTMATH, cache=True)
def onepole_coefficient(cutoff, inv_fs):
    """a = 1 - exp(-2 pi cutoff / fs), cutoff in Hz."""
    return -math.expm1(-2.0 * math.pi * cutoff * inv_fs)


@nb.njit(fastmath=FASTMATH, cache=True)
def onepole(x, out, n, a, state):
    """y[i] = y[i-1] + a (x[i] - y[i-1]); state = [y]."""
    y = state[0]
    for i in range(n):
        y += a * (x[i] - y)
        out[i] = y
    state[0] = y


@nb.njit(fastmath=FASTMATH, cache=True)
def onepole_ramp(x, out, n, cutoffs, inv_fs, coef, state):
    """One-pole with a recomputed each sample from cutoffs[i]; the last a is left in coef[0]."""
    y = state[0]
    a = coef[0]
    for i in range(n):
        a = onepole_coefficient(cutoffs[i], inv_fs)
        y += a * (x[i] - y)
        out[i] = y
    state[0] = y
    coef[0] = a


@register
class OnePole(UGen):
    """One-pole low-pass y[n] = y[n-1] + a (x[n] - y[n-1]), a = 1 - exp(-2 pi cutoff / fs)."""

    type_name = "OnePole"
    inputs = ("input",)
    param_specs = {
        "cutoff": ParamSpec(
            "float", 1000.0, low=0.0, low_open=True, unit="Hz", smooth=True, doc="cutoff frequency"
        ),
    }

    def _prepare(self) -> None:
        self.cutoff = self.smoothed("cutoff")
        self.coef = np.zeros(1)
        self.state = np.zeros(1)
        self._cutoffs = np.zeros(self.max_block)

    def _design(self) -> None:
        self.coef[0] = onepole_coefficient(self.cutoff.value, 1.0 / self.sample_rate)

    def _reset(self) -> None:
        self.cutoff.set(self.cutoff.target, 0, jump=True)
        self.state[0] = 0.0
        self._design()

    def _param_changed(self, key, value, jump) -> None:
        self.cutoff.set(value, self.ramp_samples(), jump)
        self._design()

    def process(self, start: int, n: int) -> None:
        x = self.sources["input"].out
        if self.cutoff.steady:
            onepole(x, self.out, n, self.coef[0], self.state)
        else:
            cutoffs = self.cutoff.fill(self._cutoffs, n)
            onepole_ramp(x, self.out, n, cutoffs, 1.0 / self.sample_rate, self.coef, self.state)
            if self.cutoff.steady:
                self._design()  # the ramp just ended: coefficient for the target

    def state_arrays(self):
        return {"state": self.state, "coef": self.coef, "cutoff": self.cutoff.ramp}
