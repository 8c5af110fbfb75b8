"""Bubbles: van den Doel's physically based liquid sounds (single bubbles and streams).

K. van den Doel, "Physically based models for liquid sounds", ACM Trans. Applied
Perception 2(4), 2005 (and ICAD 2004); SDT ``bubble~`` / ``fluidflow~`` (references/audio.md
section 3.3 "Bubbles"). A bubble of radius r (m) born at t = 0 radiates

    p(t) = a e^{-d t} sin(phi(t)),   phi(t) = 2 pi f0 (t + sigma d t^2 / 2),

i.e. a damped sinusoid whose instantaneous frequency phi'(t) / 2 pi = f0 (1 + sigma d t)
rises linearly (the bubble rising towards the surface), with

    f0 = 3 / r Hz (Minnaert),   d = 0.13 / r + 0.0072 r^(-3/2) 1/s,
    a = gain * depth * (r / 1 mm)^(3/2)    (amplitude proportional to r^(3/2) * depth,
                                            normalised to 1 for a 1 mm bubble at depth 1)

and sigma the rise factor (``rise``, about 0.1). The output is this sound pressure,
normalised as above (a pressure at an arbitrary reference distance), not a force, in
full-scale units: ``gain`` is the peak of a 1 mm bubble at depth 1. Its default follows the
level convention of calibrated modal models (jassy.levels): a single 1 mm Bubble peaks at
-18 dBFS like the reference strike (0.125); a default BubbleStream, whose 5 mm bubbles are
5^1.5 = 11 times louder and overlap, takes 0.02 and peaks near -12 dBFS.

Each bubble is a voice of a numba kernel, all voices updated together per sample. A
voice's phase accumulator is kept as a phasor z = a e^{i phi}: per sample z <- z c with
c = R e^{i dphi} (R = e^{-d / fs}), and c <- c e^{i ddphi}, ddphi = 2 pi f0 sigma d / fs^2,
so that a decays by R and the phase step dphi grows linearly: exact for the quadratic
phase above, and no sine per sample (a voice starting between samples is initialised at
its first sample). A voice ends when its amplitude falls below ``floor``
times its initial amplitude, or when its frequency reaches Nyquist. When all
``max_voices`` voices are busy, a new bubble takes over the quietest one (as SDT's
fluidflow~).
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numba as nb
import numpy as np

from jassy.jit import drop_stale_cache, specialise
from jassy.params import ParamSpec
from jassy.registry import register
from jassy.ugen import UGen
from ugens import cells, stochastic
from ugens.cells import slot, with_room
from ugens.kernels import FASTMATH
from ugens.noise import seed_spec
from ugens.stochastic import next_event, u01

drop_stale_cache(__file__, [cells, stochastic])  # its cache holds copies of their kernels

#: Radius at which a bubble at depth 1 has amplitude 1 (m).
R_REF = 1e-3
TWO_PI = 2.0 * math.pi


class VoiceRows(NamedTuple):
    """The rows of the voices array (struct of arrays, one column per voice), in this order."""

    zr: np.ndarray  #: the phasor z = a e^{i phi}: real part
    zi: np.ndarray  #: imaginary part
    cr: np.ndarray  #: its per-sample factor c = R e^{i dphi}: real part
    ci: np.ndarray  #: imaginary part
    qr: np.ndarray  #: the factor's own rotation q = e^{i ddphi}: real part
    qi: np.ndarray  #: imaginary part
    end: np.ndarray  #: the squared level at which the voice ends


class BubbleCounts(NamedTuple):
    """The int64 array ``meta``, in this order."""

    active: int  #: voices sounding
    pending: int  #: scheduled bubbles not yet born
    births: int  #: bubbles born since the render started
    logged: int  #: rows of the birth log filled


class StreamState(NamedTuple):
    """The float64 array ``st``, in this order (the first two as :func:`next_event` expects:
    ImpactState's acc and target)."""

    acc: float  #: integrated birth rate since the last birth
    target: float  #: the Exp(1) threshold of the next birth
    radius: float  #: the last bubble's radius, held on the radius output (m)


class ScheduledBubble(NamedTuple):
    """A row of the float64 arrays ``pending`` (scheduled bubbles) and ``log`` (stream births),
    in this order."""

    at: float  #: birth time (samples, fractional)
    radius: float  #: radius (m)
    depth: float  #: depth factor


_ZR, _ZI, _CR, _CI, _QR, _QI, _END = (slot(VoiceRows, key) for key in VoiceRows._fields)
_ACTIVE, _PENDING, _BIRTHS, _LOGGED = (slot(BubbleCounts, key) for key in BubbleCounts._fields)
_ACC, _TARGET, _RADIUS = (slot(StreamState, key) for key in StreamState._fields)
_AT, _BUBBLE_RADIUS, _DEPTH = (slot(ScheduledBubble, key) for key in ScheduledBubble._fields)


class BubbleParams(NamedTuple):
    """Settings read at each birth, stored in this order in the float64 array ``par``."""

    r_lo: float  #: smallest stream radius (m)
    r_hi: float  #: largest stream radius (m)
    exponent: float  #: radius density p(r) ~ r^-exponent
    d_lo: float  #: smallest depth factor
    d_hi: float  #: largest depth factor
    rise: float  #: rise factor sigma: frequency f0 (1 + sigma d t)
    gain: float  #: full-scale amplitude of a 1 mm bubble at depth 1
    floor: float  #: a bubble ends below floor times its initial amplitude


@nb.njit(inline="always", cache=True)
def bubble_params(par):
    """The BubbleParams record held in ``par``."""
    return BubbleParams(par[0], par[1], par[2], par[3], par[4], par[5], par[6], par[7])


class BubbleData(NamedTuple):
    """The arrays :func:`bubbles` updates."""

    voices: np.ndarray  #: (7, max voices): phasor, its factor and rotation, end level per voice
    meta: np.ndarray  #: int64 counts: active voices, pending bubbles, births, logged births
    pending: np.ndarray  #: (rows, 3) scheduled bubbles, a ScheduledBubble per row, in time order
    st: np.ndarray  #: stream state: accumulated rate, threshold, held radius (m)
    rng: np.ndarray  #: splitmix64 state, one uint64
    log: np.ndarray  #: (rows, 3) stream births, a ScheduledBubble per row


def minnaert_frequency(radius):
    """f0 = 3 / r (Hz) for a radius in m (van den Doel 2005)."""
    return 3.0 / radius


def bubble_decay(radius):
    """d = 0.13 / r + 0.0072 r^(-3/2) (1/s), viscous plus thermal damping (van den Doel 2005)."""
    return 0.13 / radius + 0.0072 * radius**-1.5


@nb.njit(fastmath=FASTMATH, cache=True)
def spawn(voices, active, t, fs, radius, depth, rise, gain, floor):
    """Start a bubble whose next computed sample is t seconds after its birth.

    Takes a free voice, or the quietest one when all are busy. Returns the active count.
    Bubbles at or above Nyquist are not started.
    """
    f0 = 3.0 / radius
    d = 0.13 / radius + 0.0072 * radius**-1.5
    if f0 * (1.0 + rise * d * max(t, 0.0)) >= 0.5 * fs:
        return active
    a0 = gain * depth * (radius / R_REF) ** 1.5
    if a0 == 0.0:
        return active
    if active < voices.shape[1]:
        k = active
        active += 1
    else:
        k = 0
        quietest = voices[_ZR, 0] ** 2 + voices[_ZI, 0] ** 2
        for j in range(1, active):
            level = voices[_ZR, j] ** 2 + voices[_ZI, j] ** 2
            if level < quietest:
                quietest = level
                k = j
    w = TWO_PI * f0
    amp = a0 * math.exp(-d * t)
    phase = w * (t + 0.5 * rise * d * t * t)
    phase -= TWO_PI * math.floor(phase / TWO_PI)
    inc = w * (1.0 + rise * d * (t + 0.5 / fs)) / fs
    decay = math.exp(-d / fs)
    dinc = w * rise * d / (fs * fs)
    voices[_ZR, k] = amp * math.cos(phase)
    voices[_ZI, k] = amp * math.sin(phase)
    voices[_CR, k] = decay * math.cos(inc)
    voices[_CI, k] = decay * math.sin(inc)
    voices[_QR, k] = math.cos(dinc)
    voices[_QI, k] = math.sin(dinc)
    voices[_END, k] = (a0 * floor) ** 2
    return active


@nb.njit(fastmath=FASTMATH, cache=True)
def voices_frame(voices, active):
    """Sum of the active voices at this sample (Im z), advanced to the next sample
    (z <- z c, c <- c q); voices that fall below their end level or whose frequency
    reaches Nyquist (Im c <= 0: the phase step passed pi) are removed. Returns
    (sum, active count).
    """
    zr, zi, cr, ci = voices[_ZR], voices[_ZI], voices[_CR], voices[_CI]
    qr, qi, end = voices[_QR], voices[_QI], voices[_END]
    s = 0.0
    ended = 0
    for k in range(active):
        a, b = zr[k], zi[k]
        s += b
        c, e = cr[k], ci[k]
        a2 = a * c - b * e
        b2 = a * e + b * c
        e2 = c * qi[k] + e * qr[k]
        zr[k] = a2
        zi[k] = b2
        cr[k] = c * qr[k] - e * qi[k]
        ci[k] = e2
        ended += (a2 * a2 + b2 * b2 < end[k]) | (e2 <= 0.0)
    if ended:
        k = 0
        while k < active:
            if zr[k] * zr[k] + zi[k] * zi[k] < end[k] or ci[k] <= 0.0:
                active -= 1
                for j in range(7):
                    voices[j, k] = voices[j, active]
            else:
                k += 1
    return s, active


@nb.njit(fastmath=FASTMATH, cache=True)
def power_law_radius(u, lo, hi, exponent):
    """Inverse CDF of p(r) ~ r^-exponent on [lo, hi] at u in [0, 1)."""
    if hi <= lo:
        return lo
    q = 1.0 - exponent
    if abs(q) < 1e-12:
        return lo * (hi / lo) ** u
    a = lo**q
    return (a + u * (hi**q - a)) ** (1.0 / q)


@nb.njit(fastmath=FASTMATH, cache=True)
def bubbles(out, radius_out, start, n, fs, rate, par, d):
    """Frames start .. start + n - 1 of scheduled bubbles (pending) plus a Poisson stream.

    d: a BubbleData; pending[j] = a ScheduledBubble (at, radius, depth), in time order; a bubble
    sounds from the first frame after ``at``. Stream births in [idx, idx + 1) start at frame
    idx + 1. par holds a BubbleParams; rate: births per second at each frame.
    """
    voices, meta, pending, st, rng, log = d
    prm = bubble_params(par)
    r_lo, r_hi, exponent, d_lo, d_hi, rise, gain, floor = prm
    active = meta[_ACTIVE]
    for i in range(n):
        idx = start + i
        while meta[_PENDING] > 0 and math.floor(pending[0, _AT]) + 1 <= idx:
            t = (idx - pending[0, _AT]) / fs
            active = spawn(
                voices, active, t, fs, pending[0, _BUBBLE_RADIUS], pending[0, _DEPTH], rise, gain, floor
            )
            meta[_PENDING] -= 1
            for j in range(meta[_PENDING]):
                pending[j, _AT] = pending[j + 1, _AT]
                pending[j, _BUBBLE_RADIUS] = pending[j + 1, _BUBBLE_RADIUS]
                pending[j, _DEPTH] = pending[j + 1, _DEPTH]
        s, active = voices_frame(voices, active)
        out[i] = s
        radius_out[i] = st[_RADIUS]
        h = rate[i] / fs
        pos = 0.0
        while h > 0.0:
            pos = next_event(st, rng, h, pos)
            if pos < 0.0:
                break
            radius = power_law_radius(u01(rng), r_lo, r_hi, exponent)
            depth = d_lo + (d_hi - d_lo) * u01(rng)
            t0 = idx + pos
            active = spawn(voices, active, (idx + 1 - t0) / fs, fs, radius, depth, rise, gain, floor)
            st[_RADIUS] = radius
            meta[_BIRTHS] += 1
            k = meta[_LOGGED]
            if k < log.shape[0]:
                log[k, _AT] = t0
                log[k, _BUBBLE_RADIUS] = radius
                log[k, _DEPTH] = depth
                meta[_LOGGED] = k + 1
    meta[_ACTIVE] = active


_RISE = ParamSpec("float", 0.1, low=0.0, high=10.0, doc="rise factor sigma: frequency f0 (1 + sigma d t)")


def _gain(default: float) -> ParamSpec:
    """The ``gain`` of Bubble and BubbleStream with its default (module docstring)."""
    return ParamSpec(
        "float", default, doc="full-scale amplitude of a 1 mm bubble at depth 1 (bubbles born after a change)"
    )


_VOICES = ParamSpec("int", 32, low=1, high=4096, fixed=True, doc="maximum number of sounding bubbles")
_FLOOR = ParamSpec(
    "float",
    1e-5,
    low=0.0,
    low_open=True,
    high=0.1,
    fixed=True,
    doc="a bubble ends when its amplitude falls below floor * its initial amplitude",
)


class _Bubbles(UGen):
    """Voices, pending births and the stream state shared by Bubble and BubbleStream."""

    #: Rows kept by the birth log (see :meth:`birth_log`); 0 disables it.
    log_capacity = 0

    def _prepare(self) -> None:
        self.voices = np.zeros((len(VoiceRows._fields), self.values["max_voices"]))
        self.meta = np.zeros(len(BubbleCounts._fields), dtype=np.int64)
        self.pending = np.zeros((8, len(ScheduledBubble._fields)))
        self.st = np.zeros(len(StreamState._fields))
        self.rng = np.zeros(1, dtype=np.uint64)
        self.log = np.zeros((int(self.log_capacity), len(ScheduledBubble._fields)))
        self._rates = np.zeros(self.max_block)
        self._radii = np.zeros(self.max_block)
        self.par = np.zeros(len(BubbleParams._fields))
        self._update_params()
        x = self.out
        self._kernel = specialise(bubbles, x, x, 0, 0, 1.0, x, self.par, self._data())
        self._steady_rate: float | None = None

    def _data(self) -> BubbleData:
        return BubbleData(self.voices, self.meta, self.pending, self.st, self.rng, self.log)

    def _reset(self) -> None:
        self.voices[:] = 0.0
        self.meta[:] = 0
        self.pending[:] = 0.0
        self.st[:] = 0.0
        self.rng[0] = self.values.get("seed", 0)

    @property
    def active_voices(self) -> int:
        """Bubbles sounding now."""
        return int(self.meta[_ACTIVE])

    @property
    def births(self) -> int:
        """Bubbles born from the stream since the render started."""
        return int(self.meta[_BIRTHS])

    def birth_log(self) -> np.ndarray:
        """Logged stream births as rows (time s, radius m, depth); set ``log_capacity`` first."""
        rows = self.log[: int(self.meta[_LOGGED])].copy()
        rows[:, _AT] /= self.sample_rate
        return rows

    def _update_params(self) -> None:
        """Pack the parameters read at each birth for the kernel (bounds in either order)."""
        v = self.values
        radii = (v.get("min_radius", 1.0), v.get("max_radius", 1.0))
        depths = (v.get("min_depth", 0.0), v.get("max_depth", 0.0))
        self.par[:] = (
            min(radii),
            max(radii),
            v.get("exponent", 0.0),
            min(depths),
            max(depths),
            v["rise"],
            v["gain"],
            v["floor"],
        )

    def _param_changed(self, key: str, value: Any, jump: bool) -> None:
        self._update_params()

    def _run(self, start: int, n: int, rates: np.ndarray, radius_out: np.ndarray) -> None:
        self._kernel(self.out, radius_out, start, n, self.sample_rate, rates, self.par, self._data())

    def state_arrays(self) -> dict[str, np.ndarray]:
        return {
            "voices": self.voices,
            "meta": self.meta,
            "pending": self.pending,
            "st": self.st,
            "rng": self.rng,
        }

    def set_state(self, state: dict[str, np.ndarray]) -> None:
        self.pending = np.zeros_like(state["pending"])  # the queue may have grown since
        super().set_state(state)


@register
class Bubble(_Bubbles):
    """Single bubbles on demand (SDT bubble~, van den Doel 2005): sound pressure (normalised).

    ``bubble`` {radius (m), depth} starts a bubble at the event's sub-sample time:
    p = a e^{-d t} sin(2 pi f0 (t + rise d t^2 / 2)), f0 = 3 / r Hz,
    d = 0.13 / r + 0.0072 r^(-3/2) 1/s, a = gain * depth * (r / 1 mm)^(3/2).
    """

    type_name = "Bubble"
    param_specs = {"rise": _RISE, "gain": _gain(0.125), "max_voices": _VOICES, "floor": _FLOOR}
    actions = {
        "bubble": {
            "radius": ParamSpec(
                "float",
                1e-3,
                low=1e-5,
                high=1.0,
                unit="m",
                doc="bubble radius: f0 = 3 / r Hz (0.15 mm = 20 kHz .. 150 mm = 20 Hz)",
            ),
            "depth": ParamSpec("float", 1.0, low=0.0, high=1e6, doc="depth factor: amplitude ~ depth"),
        }
    }

    def act(self, action: str, args: dict[str, Any], sample_time: float) -> None:
        """``bubble`` {radius, depth}: start a bubble at fractional sample ``sample_time``."""
        if action != "bubble":
            return super().act(action, args, sample_time)
        k = int(self.meta[_PENDING])
        self.pending = with_room(self.pending, k + 1)
        self.pending[k] = ScheduledBubble(sample_time, args["radius"], args["depth"])
        self.meta[_PENDING] = k + 1

    def process(self, start: int, n: int) -> None:
        self._run(start, n, self._rates, self._radii)


@register
class BubbleStream(_Bubbles):
    """A stream of bubbles (SDT fluidflow~, van den Doel 2005): sound pressure (normalised).

    Bubbles are born as a Poisson process of ``rate`` per second (exact, sub-sample birth
    times, seeded), with radius r drawn from the power law p(r) ~ r^-exponent on
    [min_radius, max_radius] and depth uniform in [min_depth, max_depth]; each sounds as a
    Bubble (f0 = 3 / r, d = 0.13 / r + 0.0072 r^(-3/2), a = gain depth (r / 1 mm)^(3/2),
    rising frequency). At most ``max_voices`` sound at once (the quietest is reused).
    Extra output ``radius``: the radius (m) of the latest bubble, held.
    """

    type_name = "BubbleStream"
    outputs = ("radius",)
    param_specs = {
        "rate": ParamSpec("float", 100.0, low=0.0, high=1e6, unit="1/s", smooth=True, doc="mean births"),
        "min_radius": ParamSpec("float", 1e-3, low=1e-5, high=1.0, unit="m", doc="smallest bubble radius"),
        "max_radius": ParamSpec("float", 5e-3, low=1e-5, high=1.0, unit="m", doc="largest bubble radius"),
        "exponent": ParamSpec(
            "float", 1.5, low=-10.0, high=10.0, doc="radius density p(r) ~ r^-exponent (larger: more small)"
        ),
        "min_depth": ParamSpec("float", 0.5, low=0.0, high=1e6, doc="smallest depth factor"),
        "max_depth": ParamSpec("float", 1.0, low=0.0, high=1e6, doc="largest depth factor"),
        "rise": _RISE,
        "gain": _gain(0.02),
        "max_voices": ParamSpec(
            "int", 64, low=1, high=4096, fixed=True, doc="maximum number of sounding bubbles"
        ),
        "floor": _FLOOR,
        "seed": seed_spec("random seed (splitmix64 stream)"),
    }

    def _prepare(self) -> None:
        super()._prepare()
        self.rate = self.smoothed("rate")

    def _reset(self) -> None:
        super()._reset()
        self.rate.set(self.rate.target, 0, jump=True)

    def _param_changed(self, key: str, value: Any, jump: bool) -> None:
        if key == "rate":
            self.rate.set(value, self.ramp_samples(), jump)
        else:
            super()._param_changed(key, value, jump)

    def process(self, start: int, n: int) -> None:
        if self.rate.steady:  # a steady rate is written into the buffer once
            if self._steady_rate != self.rate.value:
                self._rates[:] = self._steady_rate = self.rate.value
        else:
            self._steady_rate = None
            self.rate.fill(self._rates, n)
        self._run(start, n, self._rates, self.extra["radius"])

    def state_arrays(self) -> dict[str, np.ndarray]:
        return {**super().state_arrays(), "rate": self.rate.ramp}
