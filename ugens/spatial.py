"""Spatialiser: a mono source placed around a listener, for loudspeakers or headphones.

Position. The source sits at (x, y, z) m from the centre of the listener's head (x to the
right, y ahead, z up): the smoothed parameters ``x``, ``y``, ``z``, or the audio-rate inputs
``track_x``, ``track_y``, ``track_z`` (a physics scene's trajectory), which override them
when connected.
Distance r = |(x, y, z)| (at least ``min_distance``), lateral angle theta = asin(x / r).

Distance (both modes). Spherical spreading: gain ``reference_distance`` / r. Propagation:
a fractional delay of r / c read from a delay line (4-point Hermite: at worst, half-way
between samples, -0.08 dB at 6 kHz and -1.1 dB at 12 kHz), so a moving source is
Doppler-shifted. Air absorption: a one-pole low-pass at 53.8 kHz / sqrt(r m) (its
attenuation 4.34 (f / f_c)^2 dB matches ISO 9613-1's ~1.5e-9 f^2 dB/m at 20 degC, 50 %
relative humidity, the f^2 regime of the high frequencies).

``mode = "stereo"``: equal-power panning, left cos(pi (1 + s) / 4), right
sin(pi (1 + s) / 4), s = x / r (Blumlein's sine law pan position).

``mode = "binaural"``: a rigid spherical head of radius a (Brown & Duda, "A structural
model for binaural sound synthesis", IEEE Trans. Speech Audio Proc. 6(5), 1998):

* ITD (Woodworth): the near ear hears the wave (a / c) sin theta earlier than the head's
  centre, the far ear (a / c) |theta| later (around the head), so ITD = (a / c)
  (|theta| + sin |theta|);
* head shadow, per ear: H(s) = (1 + alpha s / (2 w0)) / (1 + s / (2 w0)), w0 = c / a,
  alpha(phi) = (1 + alpha_min / 2) + (1 - alpha_min / 2) cos(pi phi / phi_min) with phi
  the angle between the source and the ear's axis, alpha_min = 0.1, phi_min = 150 deg:
  +6 dB at high frequencies facing the ear, -20 dB behind the head; discretised by the
  bilinear transform.

Output: the left ear or loudspeaker; extra output ``right``. JASS counterpart:
``SpatialMixer`` / HRTF; SDT has none (it leaves space to the host).
"""

from __future__ import annotations

import math
from typing import Any

import numba as nb
import numpy as np

from jassy.jit import specialise
from jassy.params import Control, ParamSpec
from jassy.registry import register
from jassy.ugen import UGen
from ugens.kernels import FASTMATH
from ugens.pitchshift import MIN_DELAY, hermite_read

#: Air-absorption low-pass cut-off at 1 m (Hz), falling as 1 / sqrt(r).
ABSORPTION_CUTOFF = 53800.0
#: Brown & Duda's head-shadow constants.
ALPHA_MIN = 0.1
PHI_MIN = math.radians(150.0)
MODES = ("stereo", "binaural")

# parameter vector layout
_FS, _C, _A, _REF, _MIN_R, _BINAURAL, _ABSORB = range(7)
# float state layout: air low-pass (left, right), head shadow (left x1, y1, right x1, y1)
_LP_L, _LP_R, _HX_L, _HY_L, _HX_R, _HY_R = range(6)


@nb.njit(fastmath=FASTMATH, cache=True)
def shadow_coefficients(alpha, w0, fs):
    """Bilinear-transform coefficients (b0, b1, a1) of (1 + alpha s / (2 w0)) / (1 + s / (2 w0))."""
    k = 2.0 * fs
    den = 2.0 * w0 + k
    return (2.0 * w0 + alpha * k) / den, (2.0 * w0 - alpha * k) / den, (2.0 * w0 - k) / den


@nb.njit(fastmath=FASTMATH, cache=True)
def shadow_alpha(phi):
    """Brown & Duda's alpha for the angle phi (rad) between the source and the ear axis."""
    return (1.0 + 0.5 * ALPHA_MIN) + (1.0 - 0.5 * ALPHA_MIN) * math.cos(math.pi * phi / PHI_MIN)


@nb.njit(fastmath=FASTMATH, cache=True)
def spatialise(x, left, right, n, xs, ys, zs, ring, ist, st, par):
    """n samples of the source x at positions (xs, ys, zs)[i]; ring: the input's delay line."""
    fs = par[_FS]
    c = par[_C]
    a = par[_A]
    ref = par[_REF]
    min_r = par[_MIN_R]
    binaural = par[_BINAURAL] != 0.0
    absorb = par[_ABSORB] != 0.0
    w0 = c / a
    mask = ring.size - 1
    max_delay = ring.size - 4.0
    w = ist[0]
    lp_l = st[_LP_L]
    lp_r = st[_LP_R]
    hx_l = st[_HX_L]
    hy_l = st[_HY_L]
    hx_r = st[_HX_R]
    hy_r = st[_HY_R]
    last_x = math.nan  # no geometry yet: the first sample computes it
    last_y = math.nan
    last_z = math.nan
    g_l = g_r = d_l = d_r = k = 0.0
    bl0 = bl1 = al1 = br0 = br1 = ar1 = 0.0
    for i in range(n):
        w = (w + 1) & mask
        ring[w] = x[i]
        px = xs[i]
        py = ys[i]
        pz = zs[i]
        if px != last_x or py != last_y or pz != last_z:  # new geometry (else reuse it)
            last_x = px
            last_y = py
            last_z = pz
            r = max(math.sqrt(px * px + py * py + pz * pz), min_r)
            s = min(max(px / r, -1.0), 1.0)
            gain = ref / r
            delay = r / c * fs
            if binaural:
                theta = math.asin(s)
                near = -a / c * abs(s) * fs  # sin |theta| = |s|
                far = a / c * abs(theta) * fs
                d_r = delay + (near if theta >= 0.0 else far)
                d_l = delay + (far if theta >= 0.0 else near)
                g_l = gain
                g_r = gain
                phi_r = math.acos(s)
                bl0, bl1, al1 = shadow_coefficients(shadow_alpha(math.pi - phi_r), w0, fs)  # acos(-s)
                br0, br1, ar1 = shadow_coefficients(shadow_alpha(phi_r), w0, fs)
            else:
                d_l = delay
                d_r = delay
                angle = 0.25 * math.pi * (1.0 + s)
                g_l = gain * math.cos(angle)
                g_r = gain * math.sin(angle)
            d_l = min(max(d_l, MIN_DELAY), max_delay)
            d_r = min(max(d_r, MIN_DELAY), max_delay)
            k = -math.expm1(-2.0 * math.pi * ABSORPTION_CUTOFF / math.sqrt(r) / fs)
        yl = g_l * hermite_read(ring, w, d_l)
        yr = g_r * hermite_read(ring, w, d_r)
        if absorb:
            lp_l += k * (yl - lp_l)
            lp_r += k * (yr - lp_r)
            yl = lp_l
            yr = lp_r
        if binaural:
            out_l = bl0 * yl + bl1 * hx_l - al1 * hy_l
            hx_l = yl
            hy_l = out_l
            out_r = br0 * yr + br1 * hx_r - ar1 * hy_r
            hx_r = yr
            hy_r = out_r
            yl = out_l
            yr = out_r
        left[i] = yl
        right[i] = yr
    ist[0] = w
    st[_LP_L] = lp_l
    st[_LP_R] = lp_r
    st[_HX_L] = hx_l
    st[_HY_L] = hy_l
    st[_HX_R] = hx_r
    st[_HY_R] = hy_r


def _coordinate(name: str, default: float, axis: str) -> ParamSpec:
    return ParamSpec(
        "float", default, low=-1e5, high=1e5, unit="m", smooth=True, doc=f"source position: {name} ({axis})"
    )


@register
class Spatialiser(UGen):
    """A mono source at (x, y, z) m around the listener: 1/r, r/c delay (Doppler), air
    absorption, then equal-power stereo or a spherical-head binaural model (Woodworth ITD,
    Brown-Duda head shadow). Output: left; extra output ``right``.

    The position inputs track_x, track_y, track_z (audio rate, m) override the parameters
    x, y, z when connected.
    Model and sources in the module docstring; JASS ``SpatialMixer``."""

    type_name = "Spatialiser"
    inputs = ("input", "track_x", "track_y", "track_z")
    optional_inputs = ("track_x", "track_y", "track_z")
    outputs = ("right",)
    param_specs = {
        "x": _coordinate("x", 0.0, "to the right"),
        "y": _coordinate("y", 1.0, "ahead"),
        "z": _coordinate("z", 0.0, "up"),
        "mode": ParamSpec("str", "binaural", choices=MODES, fixed=True, doc="headphones or loudspeakers"),
        "head_radius": ParamSpec(
            "float", 0.0875, low=0.01, high=1.0, unit="m", fixed=True, doc="radius a of the spherical head"
        ),
        "c": ParamSpec("float", 343.0, low=100.0, high=2000.0, unit="m/s", fixed=True, doc="speed of sound"),
        "reference_distance": ParamSpec(
            "float", 1.0, low=0.01, high=1e4, unit="m", fixed=True, doc="distance of unit gain"
        ),
        "min_distance": ParamSpec(
            "float", 0.2, low=0.01, high=1e4, unit="m", fixed=True, doc="closest distance (clamps the gain)"
        ),
        "max_distance": ParamSpec(
            "float", 100.0, low=1.0, high=1e4, unit="m", fixed=True, doc="farthest distance (delay line size)"
        ),
        "air_absorption": ParamSpec("bool", True, fixed=True, doc="low-pass the source with distance"),
    }

    def _prepare(self) -> None:
        v, fs = self.values, self.sample_rate
        longest = v["max_distance"] / v["c"] * fs + v["head_radius"] / v["c"] * fs * 3.0 + 8
        self.ring = np.zeros(1 << int(math.ceil(math.log2(longest))))
        self.ist = np.zeros(1, dtype=np.int64)
        self.st = np.zeros(6)
        self.par = np.array(
            [
                fs,
                v["c"],
                v["head_radius"],
                v["reference_distance"],
                v["min_distance"],
                1.0 if v["mode"] == "binaural" else 0.0,
                1.0 if v["air_absorption"] else 0.0,
            ]
        )
        self.ramps = {key: self.smoothed(key) for key in ("x", "y", "z")}
        self.controls = {key: Control(ramp, self.max_block) for key, ramp in self.ramps.items()}
        self._run = specialise(spatialise, *self._arguments(0, self.controls["x"].buffer))

    def _position(self, key: str, n: int) -> np.ndarray:
        source = self.sources.get(f"track_{key}")
        return source.out if source is not None else self.controls[key].values(n)

    def _arguments(self, n: int, *positions: np.ndarray) -> tuple:
        xs, ys, zs = (positions * 3)[:3] if len(positions) == 1 else positions
        return (
            self.input_buffer("input"),
            self.out,
            self.extra["right"],
            n,
            xs,
            ys,
            zs,
            self.ring,
            self.ist,
            self.st,
            self.par,
        )

    def _reset(self) -> None:
        self.ring[:] = 0.0
        self.ist[:] = 0
        self.st[:] = 0.0
        for ramp in self.ramps.values():
            ramp.set(ramp.target, 0, jump=True)

    def _param_changed(self, key: str, value: Any, jump: bool) -> None:
        self.ramps[key].set(value, self.ramp_samples(), jump)

    def process(self, start: int, n: int) -> None:
        self._run(*self._arguments(n, *(self._position(key, n) for key in ("x", "y", "z"))))

    def state_arrays(self) -> dict[str, np.ndarray]:
        return {
            "ring": self.ring,
            "ist": self.ist,
            "st": self.st,
            **{key: ramp.ramp for key, ramp in self.ramps.items()},
        }
