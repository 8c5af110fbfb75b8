"""Radiation: the sound pressure a listener hears from a vibrating body's surface velocity.

A compact body of radius a radiates like a pulsating sphere: the pressure at the surface
is p = rho c u (j k a) / (1 + j k a), k = omega / c (Kinsler et al., *Fundamentals of
Acoustics*, 4th ed., sec. 7.4). Below the corner omega_c = c / a the radiated pressure
falls 6 dB per octave towards DC: quasi-static motion (a slowly varying force pushing the
body, a contact's mean load) moves air without radiating sound. The stage applies that
high-pass, normalised to 1 at high frequencies, designed by the bilinear transform
prewarped at the corner, then a first-order DC blocker (a zero at DC, pole at
exp(-2 pi f_dc / fs), normalised to unit gain at Nyquist) for anything below the corner
that remains. Both filters have a zero at DC, so a finite signal's mean is removed.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from jassy.params import ParamSpec
from jassy.registry import register
from jassy.ugen import UGen

#: Speed of sound in air at 20 C (m/s).
SPEED_OF_SOUND = 343.0


def radiation_coefficients(radius: float, c: float, dc_cutoff: float, sample_rate: float) -> np.ndarray:
    """[b0, p, g, r]: high-pass y = b0 (x - x1) + p y1 at the corner c / (2 pi radius) Hz,
    then the DC blocker z = g (y - y1) + r z1 with corner dc_cutoff Hz."""
    corner = min(c / (2.0 * math.pi * radius), 0.45 * sample_rate)
    k = math.tan(math.pi * corner / sample_rate)
    r = math.exp(-2.0 * math.pi * dc_cutoff / sample_rate)
    return np.array([1.0 / (1.0 + k), (1.0 - k) / (1.0 + k), 0.5 * (1.0 + r), r])


def radiation_response(freqs, radius: float, c: float = SPEED_OF_SOUND) -> np.ndarray:
    """|p / (rho c u)| of the pulsating sphere, ka / sqrt(1 + (ka)^2), at ``freqs`` Hz."""
    ka = 2.0 * np.pi * np.asarray(freqs, dtype=float) * radius / c
    return ka / np.sqrt(1.0 + ka * ka)


@nb.njit(cache=True, inline="always")  # inlined, as jassy.engines.callback.apply_event
def radiate(x, out, n, coef, state):
    """The two first-order sections over x[:n]; state = [x1, y1, z1]. No fastmath: a
    recurrence has nothing to vectorise, and reassociation across unrolled iterations
    would make the output depend on where a block is cut."""
    b0, p, g, r = coef[0], coef[1], coef[2], coef[3]
    x1, y1, z1 = state[0], state[1], state[2]
    for i in range(n):
        xi = x[i]
        y = b0 * (xi - x1) + p * y1
        z = g * (y - y1) + r * z1
        x1 = xi
        y1 = y
        z1 = z
        out[i] = z
    state[0] = x1
    state[1] = y1
    state[2] = z1


@register
class Radiation(UGen):
    """Output stage: radiated pressure of a compact body (high-pass at c / (2 pi radius),
    pulsating sphere) plus a DC blocker; gain 1 well above the corner."""

    type_name = "Radiation"
    inputs = ("input",)
    param_specs = {
        "radius": ParamSpec(
            "float", 0.1, low=1e-4, high=100.0, unit="m", fixed=True, doc="size of the radiating body"
        ),
        "c": ParamSpec(
            "float", SPEED_OF_SOUND, low=1.0, high=10000.0, unit="m/s", fixed=True, doc="speed of sound"
        ),
        "dc_cutoff": ParamSpec(
            "float", 10.0, low=0.1, high=1000.0, unit="Hz", fixed=True, doc="corner of the DC blocker"
        ),
    }

    def _prepare(self) -> None:
        v = self.values
        self.coef = radiation_coefficients(v["radius"], v["c"], v["dc_cutoff"], self.sample_rate)
        self.state = np.zeros(3)

    def _reset(self) -> None:
        self.state[:] = 0.0

    def process(self, start: int, n: int) -> None:
        radiate(self.sources["input"].out, self.out, n, self.coef, self.state)

    def state_arrays(self):
        return {"state": self.state, "coef": self.coef}
