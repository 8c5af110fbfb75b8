"""Sine: a phase-accumulator sine oscillator.

The phase is kept in cycles, in float64, wrapped to [0, 1) every sample, so its rounding
error stays at ~1e-16 cycles per sample however long the render. Frame n outputs

    amp[n] * sin(phase + 2 pi sum_{k<n} freq[k] / fs),

so frequency changes (ramped or jumped) bend the phase without a discontinuity.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from jassy.params import ParamSpec
from jassy.registry import register
from jassy.ugen import UGen
from ugens.kernels import FASTMATH


@nb.njit(fastmath=FASTMATH, cache=True)
def sine(out, n, phase, freqs, amps, inv_fs):
    """out[i] = amps[i] sin(2 pi p), then p += freqs[i] / fs (p in cycles, state phase[0])."""
    p = phase[0]
    for i in range(n):
        out[i] = amps[i] * math.sin(2.0 * math.pi * p)
        p += freqs[i] * inv_fs
        p -= math.floor(p)
    phase[0] = p


@register
class Sine(UGen):
    """amp * sin(phase + 2 pi freq t); freq and amp changes are ramped unless jumped."""

    type_name = "Sine"
    param_specs = {
        "freq": ParamSpec("float", 440.0, unit="Hz", smooth=True, doc="frequency"),
        "amp": ParamSpec("float", 1.0, smooth=True, doc="peak amplitude"),
        "phase": ParamSpec("float", 0.0, unit="rad", fixed=True, doc="phase at frame 0"),
    }

    def _prepare(self) -> None:
        self.ramps = {"freq": self.smoothed("freq"), "amp": self.smoothed("amp")}
        self.phase = np.zeros(1)
        self._freqs = np.zeros(self.max_block)
        self._amps = np.zeros(self.max_block)

    def _reset(self) -> None:
        for ramp in self.ramps.values():
            ramp.set(ramp.target, 0, jump=True)
        self.phase[0] = (self.values["phase"] / (2.0 * math.pi)) % 1.0

    def _param_changed(self, key, value, jump) -> None:
        self.ramps[key].set(value, self.ramp_samples(), jump)

    def process(self, start: int, n: int) -> None:
        freqs = self.ramps["freq"].fill(self._freqs, n)
        amps = self.ramps["amp"].fill(self._amps, n)
        sine(self.out, n, self.phase, freqs, amps, 1.0 / self.sample_rate)

    def state_arrays(self):
        return {"phase": self.phase, "freq": self.ramps["freq"].ramp, "amp": self.ramps["amp"].ramp}
