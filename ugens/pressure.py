"""SoundPressure: the sound pressure (Pa) at a listening distance from a vibrating body.

The body is a pulsating sphere of radius a whose surface moves with the input's normal
velocity u (m/s). At distance r >= a its pressure is (Kinsler, Frey, Coppens & Sanders,
*Fundamentals of Acoustics*, 4th ed., 2000, sec. 7.4, eq. 7.4.8)

    p(r, omega) = rho c u (a / r) (j k a) / (1 + j k a) e^{-j k (r - a)},   k = omega / c,

so |p| = rho c |u| (a / r) ka / sqrt(1 + (ka)^2): 1/r spreading, and a 6 dB/octave roll-off
below the corner c / (2 pi a). Well below it the sphere is a monopole of volume velocity
Q = 4 pi a^2 u, p = j omega rho Q / (4 pi r) (eq. 7.3.4); well above it the surface
radiates plane waves, p(a) = rho c u. A panel or a shell of vibrating area S is mapped to
the sphere of the same area, a = sqrt(S / (4 pi)): the power-equivalent radiator for
radiation efficiency 1 (bending waves above the coincidence frequency); below coincidence a
flat panel radiates less (Fahy & Gardonio, *Sound and Structural Vibration*, 2007, ch. 3),
so the estimate is an upper bound there. The propagation delay (r - a) / c is not applied:
sound stays aligned with force (add a ``Delay`` node of (r - a) / c s to hear it).

Input: the surface velocity in m/s (``input_kind = "velocity"``), or a displacement in m
(``"displacement"``: differentiated by the first difference (x[n] - x[n-1]) fs, whose
magnitude is 2 sin(omega T / 2) / T, within 0.2 dB of omega up to 5 kHz at 48 kHz). The
finite-element models of the object library have displacement gains (m per N s), the
plate models velocity gains (m/s per N s); feed it a bank at ``level = "raw"`` (a calibrated
bank's output is in full scale, not in m), and models whose gains are in physical units (the
formula models of the bar and the bell are not). A source that already radiates a pressure (in Pa
at distance ``radius`` from it: ``input_kind = "pressure"``, e.g. Explosion's pressure at its
own listener with radius = distance) is only spread, p radius / distance. Output: p divided by the pressure of
``full_scale_spl`` (dB re 20 uPa), by default 105 dB SPL (3.56 Pa, the cinema reference:
pink noise at -20 dB re full scale plays at 85 dB SPL), so a level in dB re full scale plus
105 is the sound pressure level at the listening distance; ``full_scale_spl = 93.98`` gives
pascals (jassy.levels.spl_db). The high-pass is the bilinear transform (not prewarped) of s / (s + c / a):
exact in both asymptotes (the monopole's omega / omega_c, and 1 at Nyquist as at infinity);
around the corner the frequency axis is warped by 2 fs tan(omega T / 2) / omega: within
0.3 dB of the closed form from 100 Hz to 10 kHz for a >= 1 cm (corner <= 5.5 kHz) at 48 kHz.
"""

from __future__ import annotations

from typing import NamedTuple

import numba as nb
import numpy as np

from jassy.errors import PatchError
from jassy.levels import P_REF
from jassy.params import ParamSpec
from jassy.registry import register
from jassy.ugen import UGen

#: Speed of sound (m/s) and density (kg/m^3) of air at 20 C and 101.325 kPa.
SPEED_OF_SOUND = 343.2
AIR_DENSITY = 1.204
#: Default level of full scale (dB SPL re 20 uPa): pink noise at -20 dB re full scale (RMS) plays
#: at 85 dB SPL, the cinema reference calibration (SMPTE RP 200); 1.0 at the output is 3.56 Pa.
FULL_SCALE_SPL = 105.0


def sphere_pressure(freqs, velocity, radius, distance, rho=AIR_DENSITY, c=SPEED_OF_SOUND):
    """|p| (Pa) at ``distance`` m of a pulsating sphere of ``radius`` m whose surface velocity
    has amplitude ``velocity`` m/s at ``freqs`` Hz (the closed form above)."""
    ka = 2.0 * np.pi * np.asarray(freqs, dtype=float) * radius / c
    return rho * c * np.asarray(velocity) * (radius / distance) * ka / np.sqrt(1.0 + ka * ka)


def pressure_coefficients(
    radius: float, distance: float, rho: float, c: float, sample_rate: float
) -> np.ndarray:
    """[b0, pole, gain]: y = gain * b0 (u - u1) + pole y1, the bilinear high-pass s / (s + c/a)
    times rho c a / r."""
    big_k = 2.0 * sample_rate  # s -> 2 fs (1 - z^-1) / (1 + z^-1), not prewarped
    wc = c / radius
    return np.array([big_k / (big_k + wc), (big_k - wc) / (big_k + wc), rho * c * radius / distance])


@nb.njit(cache=True)
def radiate_pressure(x, out, n, coef, state, differentiate, scale):
    """The high-pass over x[:n] (first differenced when ``differentiate`` > 0, times it),
    times coef[2] * scale. state = [x1 (last input), u1 (last velocity), y1 (last output)]."""
    b0, pole, gain = coef[0], coef[1], coef[2] * scale
    x1, u1, y1 = state[0], state[1], state[2]
    for i in range(n):
        xi = x[i]
        u = (xi - x1) * differentiate if differentiate > 0.0 else xi
        y = b0 * (u - u1) + pole * y1
        x1 = xi
        u1 = u
        y1 = y
        out[i] = gain * y
    state[0] = x1
    state[1] = u1
    state[2] = y1


class PressureSetup(NamedTuple):
    """The fixed settings of a SoundPressure node, stored in this order in the float64 array
    ``setup``."""

    differentiate: float  #: fs for a displacement input, else 0
    scale: float  #: 1 / (pressure of full scale) (1/Pa)
    spreading: float  #: a pressure input: radius / distance * scale; else -1


@nb.njit(inline="always", cache=True)
def pressure_setup(setup):
    """The PressureSetup record held in ``setup``."""
    return PressureSetup(setup[0], setup[1], setup[2])


@nb.njit(cache=True)
def sound_pressure(x, out, n, coef, state, setup):
    """SoundPressure over x[:n] (setup holds a PressureSetup): a pressure input (spreading
    >= 0) is only spread, out = x spreading; otherwise radiated by :func:`radiate_pressure`."""
    s = pressure_setup(setup)
    if s.spreading >= 0.0:
        spreading = s.spreading
        for i in range(n):
            out[i] = x[i] * spreading
    else:
        radiate_pressure(x, out, n, coef, state, s.differentiate, s.scale)


@register
class SoundPressure(UGen):
    """Sound pressure at a listening distance from a vibrating body, re a full scale in dB SPL.

    The body is a pulsating sphere of ``radius`` m heard at ``distance`` m, its surface moving
    with the input (velocity in m/s, or displacement in m; or a source's own pressure in Pa
    at distance ``radius``, only spread). Output: the
    pressure re ``full_scale_spl`` (default 1.0 = 105 dB SPL re 20 uPa, 3.56 Pa). Kinsler et
    al., Fundamentals of Acoustics (2000), sec. 7.4."""

    type_name = "SoundPressure"
    inputs = ("input",)
    param_specs = {
        "radius": ParamSpec(
            "float", 0.1, low=1e-4, high=100.0, unit="m", fixed=True,
            doc="radius a of the equivalent sphere (area S: a = sqrt(S / 4 pi)); corner at c / 2 pi a",
        ),
        "distance": ParamSpec(
            "float", 1.0, low=1e-4, high=1e5, unit="m", fixed=True,
            doc="listening distance r from the centre (>= radius): pressure falls as 1/r",
        ),
        "input_kind": ParamSpec(
            "str", "velocity", choices=("velocity", "displacement", "pressure"), fixed=True,
            doc="the input: surface velocity (m/s), displacement (m, differentiated) or a pressure "
            "(Pa) at distance `radius` from the source, spread as 1/r to `distance`",
        ),
        "density": ParamSpec(
            "float", AIR_DENSITY, low=1e-3, high=2e4, unit="kg/m^3", fixed=True, doc="density of the medium"
        ),
        "c": ParamSpec(
            "float", SPEED_OF_SOUND, low=1.0, high=1e4, unit="m/s", fixed=True, doc="speed of sound"
        ),
        "full_scale_spl": ParamSpec(
            "float", FULL_SCALE_SPL, low=0.0, high=250.0, unit="dB SPL", fixed=True,
            doc="sound pressure level of 1.0 at the output: 105 (the cinema reference), 93.98 for pascals",
        ),
    }  # fmt: skip

    def _prepare(self) -> None:
        v = self.values
        if v["distance"] < v["radius"]:
            raise PatchError(
                f"nodes.{self.name}.distance: expected a distance >= radius ({v['radius']} m), "
                f"got {v['distance']}"
            )
        self.coef = pressure_coefficients(v["radius"], v["distance"], v["density"], v["c"], self.sample_rate)
        differentiate = float(self.sample_rate) if v["input_kind"] == "displacement" else 0.0
        scale = 1.0 / (P_REF * 10.0 ** (v["full_scale_spl"] / 20.0))
        spreading = v["radius"] / v["distance"] * scale if v["input_kind"] == "pressure" else -1.0
        self.setup = np.array(PressureSetup(differentiate, scale, spreading))
        self.state = np.zeros(3)

    def _reset(self) -> None:
        self.state[:] = 0.0

    def process(self, start: int, n: int) -> None:
        sound_pressure(self.sources["input"].out, self.out, n, self.coef, self.state, self.setup)

    def state_arrays(self):
        return {"state": self.state, "coef": self.coef}
