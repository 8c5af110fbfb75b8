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

Control rate. The geometry (distance, delays, gains, filter coefficients) is evaluated
every CONTROL_PERIOD samples of the stream (whatever the blocks) and each value ramps
linearly in between, aimed at the geometry of the position extrapolated one period on
(2 p(m) - p(m - N)): no lag for a source moving at constant velocity, no steps (zipper
noise). A still source is at its exact geometry, as if evaluated per sample. Against the
per-sample model (tests/test_spatial.py), rms error relative to the output: 3.5e-7 for a
0.5 m/s walk, 2e-5 for a 2 m/s pass 0.5 m from the head, 1.1e-3 for a circle at 1 m once a
second (the ITD's kink in time as the source crosses the ear axis is rounded off over one
period).

Output: the left ear or loudspeaker; extra output ``right``. JASS counterpart:
``SpatialMixer`` / HRTF; SDT has none (it leaves space to the host).
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numba as nb
import numpy as np

from jassy.jit import drop_stale_cache, specialise
from jassy.params import Control, ParamSpec
from jassy.registry import register
from jassy.ugen import UGen
from ugens import pitchshift
from ugens.cells import slot
from ugens.kernels import FASTMATH
from ugens.pitchshift import MIN_DELAY, hermite_read

drop_stale_cache(__file__, [pitchshift])  # its cache holds copies of their kernels

#: Air-absorption low-pass cut-off at 1 m (Hz), falling as 1 / sqrt(r).
ABSORPTION_CUTOFF = 53800.0
#: Brown & Duda's head-shadow constants.
ALPHA_MIN = 0.1
PHI_MIN = math.radians(150.0)
MODES = ("stereo", "binaural")

#: Samples between two evaluations of the geometry (0.33 ms at 48 kHz); see the module doc.
CONTROL_PERIOD = 16


class SpatialParams(NamedTuple):
    """Settings of :func:`spatialise`, stored in this order in the float64 array ``par``."""

    fs: float  #: sample rate (Hz)
    c: float  #: speed of sound (m/s)
    a: float  #: head radius (m)
    reference: float  #: distance of unit gain (m)
    min_distance: float  #: closest distance (m)
    binaural: float  #: 1 for the binaural model, 0 for equal-power stereo
    absorb: float  #: 1 to low-pass with distance (air absorption)


@nb.njit(inline="always", cache=True)
def spatial_params(par):
    """The SpatialParams record held in ``par``."""
    return SpatialParams(par[0], par[1], par[2], par[3], par[4], par[5], par[6])


class Path(NamedTuple):
    """The source's position at each sample of a block (m)."""

    xs: np.ndarray
    ys: np.ndarray
    zs: np.ndarray


class SpatialData(NamedTuple):
    """The arrays :func:`spatialise` updates."""

    ring: np.ndarray  #: the input's delay line (a power of two long)
    ist: np.ndarray  #: int64 integer state, a SpatialCounters
    st: np.ndarray  #: float state: a SpatialState, then three rows of RampedValues


class SpatialState(NamedTuple):
    """The first fields of the float state ``st``, in this order; the kernels read and write
    them in place through the slots below (cells.slot)."""

    lp_l: float  #: air low-pass, left
    lp_r: float  #: air low-pass, right
    hx_l: float  #: head shadow, left: last input
    hy_l: float  #: head shadow, left: last output
    hx_r: float  #: head shadow, right: last input
    hy_r: float  #: head shadow, right: last output
    last_x: float  #: the source's position at the last control point (m; NaN: none yet)
    last_y: float
    last_z: float
    still: float  #: control points since the source last moved


class RampedValues(NamedTuple):
    """The values ramped between control points, one row of the float state each: their
    current values, their per-sample steps, and the targets of the ramps being set."""

    g_l: float  #: ear gains
    g_r: float
    d_l: float  #: ear delays (samples)
    d_r: float
    k: float  #: air low-pass coefficient
    bl0: float  #: head-shadow numerator coefficients (b0, b1) of each ear
    bl1: float
    br0: float
    br1: float


class SpatialCounters(NamedTuple):
    """The int64 state ``ist``, in this order."""

    write: int  #: the ring's write slot
    phase: int  #: samples left to the next control point


_LP_L, _LP_R, _HX_L, _HY_L, _HX_R, _HY_R, _LAST_X, _LAST_Y, _LAST_Z, _STILL = (
    slot(SpatialState, key) for key in SpatialState._fields
)
_G_L, _G_R, _D_L, _D_R, _K, _BL0, _BL1, _BR0, _BR1 = (slot(RampedValues, key) for key in RampedValues._fields)
_VALUES = len(RampedValues._fields)
_NOW, _STEP, _TARGET = (
    len(SpatialState._fields) + row * _VALUES for row in range(3)
)  # where each row starts
_STATE_SIZE = len(SpatialState._fields) + 3 * _VALUES
_WRITE, _PHASE = (slot(SpatialCounters, key) for key in SpatialCounters._fields)


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
def geometry(px, py, pz, par, max_delay, out, row):
    """The ramped values (offsets _G_L .. _BR1 from out[row]) of a source at (px, py, pz) m;
    par holds the SpatialParams."""
    prm = spatial_params(par)
    fs = prm.fs
    c = prm.c
    a = prm.a
    r = max(math.sqrt(px * px + py * py + pz * pz), prm.min_distance)
    s = min(max(px / r, -1.0), 1.0)
    gain = prm.reference / r
    delay = r / c * fs
    if prm.binaural != 0.0:
        theta = math.asin(s)
        near = -a / c * abs(s) * fs  # sin |theta| = |s|
        far = a / c * abs(theta) * fs
        d_r = delay + (near if theta >= 0.0 else far)
        d_l = delay + (far if theta >= 0.0 else near)
        g_l = gain
        g_r = gain
        phi_r = math.acos(s)
        w0 = c / a
        bl0, bl1, _ = shadow_coefficients(shadow_alpha(math.pi - phi_r), w0, fs)  # acos(-s)
        br0, br1, _ = shadow_coefficients(shadow_alpha(phi_r), w0, fs)
    else:
        d_l = delay
        d_r = delay
        angle = 0.25 * math.pi * (1.0 + s)
        g_l = gain * math.cos(angle)
        g_r = gain * math.sin(angle)
        bl0 = br0 = 1.0
        bl1 = br1 = 0.0
    out[row + _G_L] = g_l
    out[row + _G_R] = g_r
    out[row + _D_L] = min(max(d_l, MIN_DELAY), max_delay)
    out[row + _D_R] = min(max(d_r, MIN_DELAY), max_delay)
    out[row + _K] = -math.expm1(-2.0 * math.pi * ABSORPTION_CUTOFF / math.sqrt(r) / fs)
    out[row + _BL0] = bl0
    out[row + _BL1] = bl1
    out[row + _BR0] = br0
    out[row + _BR1] = br1


@nb.njit(fastmath=FASTMATH, cache=True)
def control_point(px, py, pz, st, par, max_delay):
    """At a control point with the source at (px, py, pz): set each ramped value's step so
    that it reaches, CONTROL_PERIOD samples on, the geometry of the position extrapolated
    from the last control point (the value itself carries on where its ramp ended). A
    source that has not moved for a whole period is at its own geometry (the ramp aimed
    there ends there, bar rounding) and stays there without evaluating it again; so is
    the first control point of a stream."""
    if math.isnan(st[_LAST_X]):
        still = 2.0
    elif px == st[_LAST_X] and py == st[_LAST_Y] and pz == st[_LAST_Z]:
        still = st[_STILL] + 1.0
    else:
        still = 0.0
    st[_STILL] = still
    if still > 2.0:
        return
    if still == 2.0:
        geometry(px, py, pz, par, max_delay, st, _NOW)
        st[_STEP : _STEP + _VALUES] = 0.0
    else:
        ex = 2.0 * px - st[_LAST_X]
        ey = 2.0 * py - st[_LAST_Y]
        ez = 2.0 * pz - st[_LAST_Z]
        geometry(ex, ey, ez, par, max_delay, st, _TARGET)
        for v in range(_VALUES):
            st[_STEP + v] = (st[_TARGET + v] - st[_NOW + v]) * (1.0 / CONTROL_PERIOD)
    st[_LAST_X] = px
    st[_LAST_Y] = py
    st[_LAST_Z] = pz


@nb.njit(fastmath=FASTMATH, cache=True)
def spatialise(x, left, right, n, path, par, d):
    """n samples of the source x at the positions of ``path`` (a Path) to left and right;
    par holds the SpatialParams, d is the SpatialData. The geometry is evaluated at the
    control points (every CONTROL_PERIOD samples of the stream, wherever the blocks are cut)
    and ramped linearly in between."""
    xs, ys, zs = path
    ring, ist, st = d
    prm = spatial_params(par)
    fs = prm.fs
    binaural = prm.binaural != 0.0
    absorb = prm.absorb != 0.0
    w0 = prm.c / prm.a
    a1 = (2.0 * w0 - 2.0 * fs) / (2.0 * w0 + 2.0 * fs)  # the head shadow's pole (fixed)
    mask = ring.size - 1
    max_delay = ring.size - 4.0
    w = ist[_WRITE]
    phase = ist[_PHASE]
    lp_l = st[_LP_L]
    lp_r = st[_LP_R]
    hx_l = st[_HX_L]
    hy_l = st[_HY_L]
    hx_r = st[_HX_R]
    hy_r = st[_HY_R]
    i = 0
    while i < n:
        if phase == 0:
            control_point(xs[i], ys[i], zs[i], st, par, max_delay)
            phase = CONTROL_PERIOD
        g_l, g_r, d_l, d_r, k = (
            st[_NOW + _G_L],
            st[_NOW + _G_R],
            st[_NOW + _D_L],
            st[_NOW + _D_R],
            st[_NOW + _K],
        )
        bl0, bl1, br0, br1 = st[_NOW + _BL0], st[_NOW + _BL1], st[_NOW + _BR0], st[_NOW + _BR1]
        dg_l, dg_r, dd_l, dd_r = st[_STEP + _G_L], st[_STEP + _G_R], st[_STEP + _D_L], st[_STEP + _D_R]
        dk, dbl0, dbl1, dbr0, dbr1 = (
            st[_STEP + _K],
            st[_STEP + _BL0],
            st[_STEP + _BL1],
            st[_STEP + _BR0],
            st[_STEP + _BR1],
        )
        m = min(phase, n - i)
        for j in range(i, i + m):
            w = (w + 1) & mask
            ring[w] = x[j]
            yl = g_l * hermite_read(ring, w, d_l)
            yr = g_r * hermite_read(ring, w, d_r)
            if absorb:
                lp_l += k * (yl - lp_l)
                lp_r += k * (yr - lp_r)
                yl = lp_l
                yr = lp_r
            if binaural:
                out_l = bl0 * yl + bl1 * hx_l - a1 * hy_l
                hx_l = yl
                hy_l = out_l
                out_r = br0 * yr + br1 * hx_r - a1 * hy_r
                hx_r = yr
                hy_r = out_r
                yl = out_l
                yr = out_r
            left[j] = yl
            right[j] = yr
            g_l += dg_l
            g_r += dg_r
            d_l += dd_l
            d_r += dd_r
            k += dk
            bl0 += dbl0
            bl1 += dbl1
            br0 += dbr0
            br1 += dbr1
        st[_NOW + _G_L], st[_NOW + _G_R], st[_NOW + _D_L], st[_NOW + _D_R], st[_NOW + _K] = (
            g_l,
            g_r,
            d_l,
            d_r,
            k,
        )
        st[_NOW + _BL0], st[_NOW + _BL1], st[_NOW + _BR0], st[_NOW + _BR1] = bl0, bl1, br0, br1
        i += m
        phase -= m
    ist[_WRITE] = w
    ist[_PHASE] = phase
    st[_LP_L] = lp_l
    st[_LP_R] = lp_r
    st[_HX_L] = hx_l
    st[_HY_L] = hy_l
    st[_HX_R] = hx_r
    st[_HY_R] = hy_r


#: Each position coordinate and the audio-rate input that overrides it.
_TRACKS = (("x", "track_x"), ("y", "track_y"), ("z", "track_z"))


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
        self.ist = np.zeros(len(SpatialCounters._fields), dtype=np.int64)
        self.st = np.zeros(_STATE_SIZE)
        self.par = np.array(
            SpatialParams(
                fs=fs,
                c=v["c"],
                a=v["head_radius"],
                reference=v["reference_distance"],
                min_distance=v["min_distance"],
                binaural=1.0 if v["mode"] == "binaural" else 0.0,
                absorb=1.0 if v["air_absorption"] else 0.0,
            ),
            dtype=np.float64,
        )
        self.ramps = {key: self.smoothed(key) for key in ("x", "y", "z")}
        self.controls = {key: Control(ramp, self.max_block) for key, ramp in self.ramps.items()}
        xs = self.controls["x"].buffer
        self._data = SpatialData(self.ring, self.ist, self.st)
        example = (self.input_buffer("input"), self.out, self.extra["right"], 0, Path(xs, xs, xs))
        self._run = specialise(spatialise, *example, self.par, self._data)

    def _reset(self) -> None:
        self.ring[:] = 0.0
        self.ist[:] = 0
        self.st[:] = 0.0
        self.st[_LAST_X] = math.nan  # no control point yet
        for ramp in self.ramps.values():
            ramp.set(ramp.target, 0, jump=True)

    def _param_changed(self, key: str, value: Any, jump: bool) -> None:
        self.ramps[key].set(value, self.ramp_samples(), jump)

    def process(self, start: int, n: int) -> None:
        sources, controls = self.sources, self.controls
        path = Path(
            *(sources[track].out if track in sources else controls[key].values(n) for key, track in _TRACKS)
        )
        self._run(sources["input"].out, self.out, self.extra["right"], n, path, self.par, self._data)

    def state_arrays(self) -> dict[str, np.ndarray]:
        return {
            "ring": self.ring,
            "ist": self.ist,
            "st": self.st,
            **{key: ramp.ramp for key, ramp in self.ramps.items()},
        }
