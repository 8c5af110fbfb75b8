"""Scraping and sliding contact forces: Scrape (phonograph needle) and ResonantScrape (JASS AR).

Both are open-loop force generators: their output is a force in N, to drive a ModalBank
(and the haptic channel). They are controlled by the contact parameters ``force``
(normal force F, N) and ``speed`` (slip speed v, m/s), smoothed per sample (``set``
events ramp over ``smooth`` s or their own ``ramp``, or jump; a ContactTrack drives them
through :func:`jassy.events.track_events`).

**Amplitude law** (JASS ``ContactForce.setSlideProperties``: g sqrt(F v / vmax)). The
force is shaped by a dimensionless contact factor

    s(F, v) = sqrt(F |v| / (f_ref v_ref))    (law = "sqrt", default: power ~ F v)
    s(F, v) = F |v| / (f_ref v_ref)          (law = "linear")
    s(F, v) = 1                              (law = "height": the profile's own height)

and s = 0 while |v| < ``min_speed`` (JASS: silent below vslide0) or F <= 0, so at the
reference contact (f_ref, v_ref) s = 1. "height" is for a contact filter that makes the
force from the height itself (Roll with a ``model``), where an amplitude law would count
the speed and the load a second time.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numba as nb
import numpy as np

from jassy.errors import PatchError
from jassy.jit import drop_stale_cache, specialise
from jassy.levels import ForceSpectrum
from jassy.params import ParamSpec
from jassy.registry import register
from jassy.ugen import UGen
from ugens import cells, filters, noise, tonal_level
from ugens.cells import store
from ugens.filters import biquad_coefficients, biquad_step, design_biquad
from ugens.kernels import FASTMATH
from ugens.noise import seed_spec, uniform
from ugens.profile import ProfileError, fractal_profile, load_profile
from ugens.tonal_level import LEVEL_POINTS, TONAL_LEVEL_SPECS, TonalLevel, log_table

drop_stale_cache(__file__, [cells, filters, noise, tonal_level])  # its cache holds copies of their kernels

LAWS = ("sqrt", "linear", "height")
#: Force per m of profile height of the needle contacts (Scrape, Roll).
STIFFNESS_SPEC = ParamSpec(
    "float",
    1e5,
    low=0.0,
    high=1e12,
    unit="N/m",
    fixed=True,
    doc="contact stiffness: force per m of profile height at the reference contact",
)
INTERPOLATIONS = ("linear", "cubic")
#: Speed-dependent filter cutoffs are clamped to [F_MIN, NYQUIST_FRACTION * fs].
F_MIN = 0.5
NYQUIST_FRACTION = 0.45
_BUTTERWORTH_Q = 1.0 / math.sqrt(2.0)
#: "No coefficients designed yet" (outside every valid speed), kept finite for NaN checks.
UNDESIGNED = 1e300
#: A speed-tracking low-pass is redesigned when its cutoff should move by more than this
#: fraction: a 1% cutoff error changes a second-order Butterworth response by < 0.09 dB
#: (d ln|H| / d ln fc <= 1), and a speed read from a curve changes every sample.
CUTOFF_STEP = 0.01


# ------------------------------------------------------------------------------ kernels
@nb.njit(fastmath=FASTMATH, cache=True)
def contact_factor(force, speed, law, inv_ref, min_speed):
    """s(F, v) of the module docstring (law 0 = sqrt, 1 = linear, 2 = height); inv_ref = 1/(f_ref v_ref)."""
    av = abs(speed)
    if av < min_speed or force <= 0.0:
        return 0.0
    if law == 2:
        return 1.0
    p = force * av * inv_ref
    return math.sqrt(p) if law == 0 else p


@nb.njit(fastmath=FASTMATH, cache=True)
def read_profile(prof, pos, cubic):
    """Height at fractional index pos in [0, L) of the looped profile (linear or Catmull-Rom)."""
    L = prof.shape[0]
    i = int(pos)
    t = pos - i
    if i >= L:  # pos rounded up to L
        i -= L
    p1 = prof[i]
    p2 = prof[i + 1 if i + 1 < L else i + 1 - L]
    if not cubic:
        return p1 + t * (p2 - p1)
    p0 = prof[i - 1 if i > 0 else L - 1]
    p3 = prof[i + 2 if i + 2 < L else i + 2 - L]
    return p1 + 0.5 * t * (
        p2 - p0 + t * (2.0 * p0 - 5.0 * p1 + 4.0 * p2 - p3 + t * (3.0 * (p1 - p2) + p3 - p0))
    )


@nb.njit(fastmath=FASTMATH, cache=True)
def wrap(pos, length):
    """pos modulo length, in [0, length)."""
    if pos >= length or pos < 0.0:
        pos -= length * math.floor(pos / length)
        if pos >= length:
            pos = 0.0
    return pos


class ProfileConfig(NamedTuple):
    """Settings of :func:`profile_contact`, stored in this order in the float64 array ``cfg``."""

    inv_dxfs: float  #: 1/(dx fs): profile points per (m/s) per sample
    cutoff_per_speed: float  #: kc, low-pass cutoff per slip speed (Hz per m/s; 0 = no filter)
    f_max: float  #: highest cutoff (Hz)
    inv_fs: float  #: sample period (s)
    gain: float  #: amplitude at the reference contact
    law: float  #: index of the amplitude law in LAWS
    inv_ref: float  #: 1/(f_ref v_ref) (1/(N m/s))
    min_speed: float  #: slip speed below which the contact is silent (m/s)
    cubic: float  #: 1.0 for cubic profile interpolation, 0.0 for linear


@nb.njit(inline="always", cache=True)
def profile_config(cfg):
    """The ProfileConfig record held in ``cfg``."""
    return ProfileConfig(cfg[0], cfg[1], cfg[2], cfg[3], cfg[4], cfg[5], cfg[6], cfg[7], cfg[8])


class NoiseConfig(NamedTuple):
    """Settings of :func:`resonant_noise`, stored in this order in the float64 array ``cfg``."""

    f0: float  #: resonance at rest (Hz)
    slope: float  #: resonance rise per slip speed (Hz per m/s)
    d0: float  #: decay rate at rest (1/s)
    d_slope: float  #: decay rate rise per slip speed (1/s per m/s)
    inv_fs: float  #: sample period (s)
    f_max: float  #: highest resonance (Hz)
    gain: float  #: amplitude at the reference contact
    law: float  #: index of the amplitude law in LAWS
    inv_ref: float  #: 1/(f_ref v_ref) (1/(N m/s))
    min_speed: float  #: slip speed below which the contact is silent (m/s)
    level_step: float  #: speed step (m/s) of the level table after the record; 0: no table


#: ResonantScrape's level table (log of the calibrated level's factor at |v| = i x
#: level_step, LEVEL_POINTS entries) is stored in ``cfg`` after its NoiseConfig; ``cfg`` has
#: NOISE_CFG_SIZE values.
LEVEL_TABLE = len(NoiseConfig._fields)  #: index of the table's first entry in ``cfg``
NOISE_CFG_SIZE = LEVEL_TABLE + LEVEL_POINTS


@nb.njit(inline="always", cache=True)
def noise_config(cfg):
    """The NoiseConfig record held in ``cfg``."""
    return NoiseConfig(
        cfg[0], cfg[1], cfg[2], cfg[3], cfg[4], cfg[5], cfg[6], cfg[7], cfg[8], cfg[9], cfg[10]
    )


@nb.njit(inline="always", cache=True)
def table_level(cfg, x):
    """exp of the level table (after the NoiseConfig in ``cfg``) at fractional index x >= 0."""
    return log_table(cfg, LEVEL_TABLE, x)


class NeedleState(NamedTuple):
    """State of :func:`profile_contact`, stored in this order in the float64 array ``state``."""

    pos: float  #: profile position (points)
    s1: float  #: the low-pass's first state
    s2: float  #: the low-pass's second state
    fc_coef: float  #: the cutoff (Hz) coef was designed for


@nb.njit(inline="always", cache=True)
def needle_state(state):
    """The NeedleState record held in ``state``."""
    return NeedleState(state[0], state[1], state[2], state[3])


class NoiseState(NamedTuple):
    """State of :func:`resonant_noise`, stored in this order in the float64 array ``state``."""

    x1: float  #: input one sample back
    x2: float  #: input two samples back
    y1: float  #: output one sample back
    y2: float  #: output two samples back
    v_coef: float  #: the speed (m/s) c1, c2, g were designed for
    c1: float  #: 2 R cos(theta)
    c2: float  #: R^2
    g: float  #: input gain


@nb.njit(inline="always", cache=True)
def noise_state(state):
    """The NoiseState record held in ``state``."""
    return NoiseState(state[0], state[1], state[2], state[3], state[4], state[5], state[6], state[7])


@nb.njit(fastmath=FASTMATH, cache=True)
def profile_contact(out, n, forces, speeds, prof, state, coef, cfg):
    """Needle on a looped profile, low-passed with cutoff kc |v|, times gain s(F, v).

    cfg holds a ProfileConfig, state a NeedleState; coef = RBJ low-pass [b0, b1, b2, a1, a2]
    for the cutoff fc_coef, redesigned when the cutoff the speed asks for differs from it by
    more than CUTOFF_STEP (relative).
    """
    c = profile_config(cfg)
    inv_dxfs = c.inv_dxfs
    kc = c.cutoff_per_speed
    f_max = c.f_max
    inv_fs = c.inv_fs
    gain = c.gain
    law = int(c.law)
    inv_ref = c.inv_ref
    min_speed = c.min_speed
    cubic = c.cubic != 0.0
    L = prof.shape[0]
    pos, s1, s2, fc_coef = needle_state(state)
    for i in range(n):
        v = speeds[i]
        h = read_profile(prof, pos, cubic)
        if kc > 0.0:
            fc = min(max(kc * abs(v), F_MIN), f_max)
            if abs(fc - fc_coef) > CUTOFF_STEP * fc_coef:
                design_biquad(0, fc, _BUTTERWORTH_Q, inv_fs, coef)
                fc_coef = fc
            h, s1, s2 = biquad_step(biquad_coefficients(coef), h, s1, s2)
        out[i] = gain * contact_factor(forces[i], v, law, inv_ref, min_speed) * h
        pos = wrap(pos + v * inv_dxfs, L)
    store(state, NeedleState(pos, s1, s2, fc_coef))


@nb.njit(fastmath=FASTMATH, cache=True)
def resonant_noise(out, n, forces, speeds, rng, state, cfg):
    """White noise (unit RMS) through a unit-noise-gain resonator tuned by the speed.

    y = g (x - x[-2]) + 2 R cos(theta) y[-1] - R^2 y[-2], g = sqrt((1 - R^2) / 2), with
    theta = 2 pi clamp(f0 + slope |v|) / fs and R = exp(-(d0 + d_slope |v|) / fs); g times the
    level table's factor at |v| when it has one. cfg holds a NoiseConfig and the level table
    (NOISE_CFG_SIZE values); state a NoiseState.
    """
    c = noise_config(cfg)
    f0 = c.f0
    slope = c.slope
    d0 = c.d0
    d_slope = c.d_slope
    inv_fs = c.inv_fs
    f_max = c.f_max
    gain = c.gain
    law = int(c.law)
    inv_ref = c.inv_ref
    min_speed = c.min_speed
    level_step = c.level_step
    x1, x2, y1, y2, v_coef, c1, c2, g = noise_state(state)
    s = rng[0]
    root3 = math.sqrt(3.0)
    for i in range(n):
        v = speeds[i]
        if v != v_coef:
            av = abs(v)
            f = min(max(f0 + slope * av, F_MIN), f_max)
            R = math.exp(-(d0 + d_slope * av) * inv_fs)
            c1 = 2.0 * R * math.cos(2.0 * math.pi * f * inv_fs)
            c2 = R * R
            g = math.sqrt(0.5 * (1.0 - c2))
            if level_step > 0.0:
                g *= table_level(cfg, av / level_step)
            v_coef = v
        s, u = uniform(s)
        x = root3 * u
        y = g * (x - x2) + c1 * y1 - c2 * y2
        x2 = x1
        x1 = x
        y2 = y1
        y1 = y
        out[i] = gain * contact_factor(forces[i], v, law, inv_ref, min_speed) * y
    rng[0] = s
    store(state, NoiseState(x1, x2, y1, y2, v_coef, c1, c2, g))


# ------------------------------------------------------------------------------- params
def contact_specs(
    speed_doc: str = "slip speed (signed: the profile is read backwards for v < 0)",
    force: float = 1.0,
    force_doc: str = "normal contact force F",
):
    """The smoothed contact controls ``force`` and ``speed``."""
    return {
        "force": ParamSpec("float", force, low=0.0, high=1e5, unit="N", smooth=True, doc=force_doc),
        "speed": ParamSpec("float", 0.0, low=-100.0, high=100.0, unit="m/s", smooth=True, doc=speed_doc),
    }


def law_specs(v_ref: float = 1.0, min_speed: float = 1e-4):
    """Parameters of the amplitude law s(F, v) (module docstring)."""
    return {
        "law": ParamSpec(
            "str",
            "sqrt",
            choices=LAWS,
            fixed=True,
            doc="amplitude law: sqrt(F v) (power ~ F v), F v, or height (1 while loaded and moving; "
            "only under a contact filter, Roll with a model)",
        ),
        "f_ref": ParamSpec(
            "float", 1.0, low=0.0, low_open=True, high=1e5, unit="N", fixed=True, doc="reference normal force"
        ),
        "v_ref": ParamSpec(
            "float", v_ref, low=0.0, low_open=True, high=100.0, unit="m/s", fixed=True, doc="reference speed"
        ),
        "min_speed": ParamSpec(
            "float",
            min_speed,
            low=0.0,
            high=100.0,
            unit="m/s",
            fixed=True,
            doc="silent while |speed| is below this",
        ),
    }


def profile_specs(
    beta: float, roughness: float | None, dx: float, length: int, k_low: float, interp: str = "linear"
):
    """Parameters that make or load the looped surface profile (roughness None: unit RMS)."""
    specs = {
        "beta": ParamSpec(
            "float", beta, low=0.0, high=5.0, fixed=True, doc="spectral exponent of the 1/k^beta profile"
        ),
        "k_low": ParamSpec(
            "float",
            k_low,
            low=0.0,
            high=1e7,
            unit="1/m",
            fixed=True,
            doc="low spatial cutoff of the generated profile (cycles per m): longer waves, which a "
            "needle follows quasi-statically (sub-audio force), are left out; 0 keeps all",
        ),
    }
    if roughness is not None:
        specs["roughness"] = ParamSpec(
            "float",
            roughness,
            low=0.0,
            low_open=True,
            high=0.1,
            unit="m",
            fixed=True,
            doc="RMS height of the profile (also the RMS a given profile is scaled to)",
        )
    specs.update(
        {
            "seed": ParamSpec(
                "int", 0, low=0, high=2**63 - 1, fixed=True, doc="seed of the generated profile"
            ),
            "dx": ParamSpec(
                "float",
                dx,
                low=0.0,
                low_open=True,
                high=1.0,
                unit="m",
                fixed=True,
                doc="profile spacing (m per point): the profile moves |v| / (dx fs) points per sample",
            ),
            "length": ParamSpec(
                "int", length, low=16, high=2**24, fixed=True, doc="points of the generated (looped) profile"
            ),
            "profile": ParamSpec(
                "floats",
                None,
                fixed=True,
                doc="profile heights (shape only: mean removed, scaled to the RMS height); "
                "replaces the generated one",
            ),
            "profile_file": ParamSpec(
                "str",
                "",
                fixed=True,
                doc="profile file (.npy, .wav, one-column .csv; shape only, like 'profile')",
            ),
            "interp": ParamSpec(
                "str", interp, choices=INTERPOLATIONS, fixed=True, doc="interpolation between profile points"
            ),
        }
    )
    return specs


@nb.njit(cache=True)
def curves_fill(out_a, out_b, first, n, rate, times, a, b):
    """out_a[i], out_b[i] = the piecewise-linear curves through (times s, a) and (times s, b)
    at frame first + i of a clock of ``rate`` Hz, held at the end values outside the times."""
    last = times.size - 1
    t = first / rate
    j = np.searchsorted(times, t, side="right")  # times[j - 1] <= t < times[j]
    i = 0
    while i < n:
        t = (first + i) / rate
        while j <= last and times[j] <= t:
            j += 1
        if j == 0:  # before the first time: hold
            out_a[i] = a[0]
            out_b[i] = b[0]
            i += 1
            continue
        if j > last:  # after the last time: hold to the end
            for m in range(i, n):
                out_a[m] = a[last]
                out_b[m] = b[last]
            return
        t0, t1 = times[j - 1], times[j]
        slope_a = (a[j] - a[j - 1]) / (t1 - t0)
        slope_b = (b[j] - b[j - 1]) / (t1 - t0)
        while i < n:  # the frames in [t0, t1)
            t = (first + i) / rate
            if t >= t1:
                break
            out_a[i] = a[j - 1] + (t - t0) * slope_a
            out_b[i] = b[j - 1] + (t - t0) * slope_b
            i += 1


# ------------------------------------------------------------------------------ classes
class ContactControls(UGen):
    """Shared handling of the ``force`` and ``speed`` controls: smoothed parameters set by
    events, or curves given once with :meth:`follow` (physics-driven contacts)."""

    _curves: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    def follow(self, times, force, speed) -> None:
        """Drive ``force`` (N) and ``speed`` (m/s) by the piecewise-linear curves through
        (times s, force) and (times s, speed), read at each frame's time, held at their end
        values outside [times[0], times[-1]]; replaces the parameters and their events. One
        call instead of an event per control sample: a contact track of any length costs no
        scheduling. ``None`` returns to the parameters."""
        if times is None:
            self._curves = None
            return
        arrays = [np.ascontiguousarray(x, dtype=np.float64) for x in (times, force, speed)]
        where = f"{self.name}.follow"
        t = arrays[0]
        if t.ndim != 1 or t.size < 1 or np.any(np.diff(t) <= 0) or not np.all(np.isfinite(t)):
            raise PatchError(f"{where}: times: expected increasing finite times in s")
        for key, x in zip(("force", "speed"), arrays[1:], strict=True):
            if x.shape != t.shape or not np.all(np.isfinite(x)):
                raise PatchError(f"{where}: {key}: expected {t.size} finite values, one per time")
        if np.any(arrays[1] < 0) or np.any(arrays[2] < 0):
            raise PatchError(f"{where}: force and speed: expected values >= 0")
        self._curves = (arrays[0], arrays[1], arrays[2])

    def _prepare(self) -> None:
        self._force = self.smoothed("force")
        self._speed = self.smoothed("speed")
        self._forces = np.zeros(self.max_block)
        self._speeds = np.zeros(self.max_block)
        self._curves_fill = specialise(
            curves_fill, self._forces, self._speeds, 0, 0, 1.0, self._forces, self._forces, self._forces
        )

    def _reset(self) -> None:
        for ramp in (self._force, self._speed):
            ramp.set(ramp.target, 0, jump=True)

    def _param_changed(self, key: str, value: Any, jump: bool) -> None:
        if key == "force":
            self._force.set(value, self.ramp_samples(), jump)
        elif key == "speed":
            self._speed.set(value, self.ramp_samples(), jump)

    def _controls(self, start: int, n: int) -> tuple[np.ndarray, np.ndarray]:
        if self._curves is not None:
            times, force, speed = self._curves
            self._curves_fill(self._forces, self._speeds, start, n, self.sample_rate, times, force, speed)
            return self._forces[:n], self._speeds[:n]
        return self._force.fill(self._forces, n), self._speed.fill(self._speeds, n)

    def _filters_height(self) -> bool:
        """True when a contact filter makes the force from the height (Roll with a
        ``model``): only then may ``law`` be "height"."""
        return False

    def _law_config(self) -> tuple[float, float, float]:
        v = self.values
        if v["law"] == "height" and not self._filters_height():
            raise PatchError(
                f"nodes.{self.name}.law: 'height' (force = stiffness x height, with no speed or "
                "load dependence) needs a contact filter (Roll with a model); expected 'sqrt' or 'linear'"
            )
        return float(LAWS.index(v["law"])), 1.0 / (v["f_ref"] * v["v_ref"]), float(v["min_speed"])

    def state_arrays(self) -> dict[str, np.ndarray]:
        return {"force": self._force.ramp, "speed": self._speed.ramp}


class ProfileContact(ContactControls):
    """A needle reading a looped surface profile at the contact speed (base of Scrape, Roll).

    Subclasses set ``unit_rms`` (profile scaled to RMS 1 instead of ``roughness``).
    """

    unit_rms = False

    def __init__(self, *sources: UGen, name: str | None = None, where: str | None = None, **params: Any):
        self._loaded: dict[str, np.ndarray] = {}
        super().__init__(*sources, name=name, where=where, **params)
        where = where or self.type_name
        if self.values["profile"] is not None and self.values["profile_file"]:
            raise PatchError(f"{where}.profile: give either profile or profile_file, not both")
        self._generated: tuple[tuple, np.ndarray] | None = None
        self.heights(where)  # generate now: bad profile parameters fail when the patch loads

    def check_param(self, key: str, value: Any, where: str) -> Any:
        """Also read ``profile_file`` (errors name the key and the file) and check ``profile``."""
        value = super().check_param(key, value, where)
        if key == "profile_file" and value:
            if value not in self._loaded:
                try:
                    self._loaded[value] = self._shape(load_profile(value), value)
                except ProfileError as exc:
                    raise PatchError(f"{where}: {exc}") from None
        elif key == "profile" and value is not None:
            value = np.array(value, dtype=np.float64)
            try:
                self._shape(value, "profile")
            except ProfileError as exc:
                raise PatchError(f"{where}: {exc}") from None
        return value

    @staticmethod
    def _shape(heights: np.ndarray, what: str) -> np.ndarray:
        """Zero-mean, unit-RMS copy of a given profile."""
        if heights.size < 4:
            raise ProfileError(f"{what}: expected at least 4 points, got {heights.size}")
        h = heights - heights.mean()
        rms = math.sqrt(float(np.mean(h * h)))
        if not rms > 0:
            raise ProfileError(f"{what}: the profile is flat (all heights equal)")
        return h / rms

    def heights(self, where: str | None = None) -> np.ndarray:
        """The looped profile: heights in m (RMS ``roughness``), or unit RMS if ``unit_rms``."""
        v = self.values
        rms = 1.0 if self.unit_rms else v["roughness"]
        if v["profile"] is not None:
            return self._shape(v["profile"], "profile") * rms
        if v["profile_file"]:
            return self._loaded[v["profile_file"]] * rms
        return self._fractal(v["length"], rms, v["dx"], where)

    def _fractal(self, points: int, rms: float, dx: float, where: str | None) -> np.ndarray:
        """The generated fractal profile of ``points`` points ``dx`` m apart, RMS ``rms``
        (m), made again only when one of its parameters changed."""
        v = self.values
        key = (points, v["beta"], rms, v["seed"], dx, v["k_low"])
        if self._generated is None or self._generated[0] != key:
            try:
                heights = fractal_profile(*key[:5], k_low=v["k_low"] or None)
            except ProfileError as exc:
                raise PatchError(f"{where or f'nodes.{self.name}'}: {exc}") from None
            self._generated = (key, heights)
        return self._generated[1]

    def _prepare(self) -> None:
        super()._prepare()
        self.prof = self.heights()


class NeedleContact(ProfileContact):
    """The profile read by a needle, low-passed at kc |v| and scaled by the amplitude law.

    Subclasses define :meth:`cutoff_per_speed` (kc, Hz per m/s; 0 for no low-pass) and
    the ``stiffness`` and amplitude-law parameters.
    """

    def cutoff_per_speed(self) -> float:
        raise NotImplementedError

    def _prepare(self) -> None:
        super()._prepare()
        v, fs = self.values, self.sample_rate
        law, inv_ref, min_speed = self._law_config()
        config = ProfileConfig(
            inv_dxfs=1.0 / (v["dx"] * fs),
            cutoff_per_speed=self.cutoff_per_speed(),
            f_max=NYQUIST_FRACTION * fs,
            inv_fs=1.0 / fs,
            gain=v["stiffness"],
            law=law,
            inv_ref=inv_ref,
            min_speed=min_speed,
            cubic=float(v["interp"] == "cubic"),
        )
        self.cfg = np.array(config, dtype=np.float64)
        self.state = np.zeros(len(NeedleState._fields))
        self.coef = np.zeros(5)
        self._kernel = specialise(
            profile_contact,
            self.out,
            0,
            self._forces,
            self._speeds,
            self.prof,
            self.state,
            self.coef,
            self.cfg,
        )

    def _reset(self) -> None:
        super()._reset()
        self.state[:] = NeedleState(0.0, 0.0, 0.0, -UNDESIGNED)  # design the low-pass on the first sample
        self.coef[:] = 0.0

    def process(self, start: int, n: int) -> None:
        forces, speeds = self._controls(start, n)
        self._kernel(self.out, n, forces, speeds, self.prof, self.state, self.coef, self.cfg)

    def state_arrays(self) -> dict[str, np.ndarray]:
        return {**super().state_arrays(), "state": self.state, "coef": self.coef}


@register
class Scrape(NeedleContact):
    """Scraping/sliding force: a needle reading a looped fractal surface profile.

    The phonograph-needle model of FoleyAutomatic (van den Doel, Kry & Pai, SIGGRAPH 2001)
    and JASS ``ContactForce.setSlideProperties``. The profile h (m; 1/k^beta fractal noise
    of RMS ``roughness``, or a given one) is read at the slip speed, ``speed / (dx fs)``
    points per sample (linear or cubic interpolation), so its spectrum scales with speed.
    Optionally a second-order Butterworth low-pass at fc = |v| / ``patch`` (a fixed
    spatial cutoff of 1/patch cycles per m) models the smoothing by the contact patch.

    Output force (N): F_out = stiffness * s(F, v) * h_lp(x(t)), s the amplitude law of
    ugens/scrape.py (sqrt(F v / (f_ref v_ref)) by default): RMS = stiffness * roughness
    at the reference contact. The profile must be fine enough for the top speed: content
    above fs/2 aliases once |v| > dx fs (FoleyAutomatic: resolution v_max / fs; the
    default dx = 0.03 mm gives 1.44 m/s at 48 kHz).
    """

    type_name = "Scrape"
    param_specs = {
        **contact_specs(),
        **profile_specs(beta=1.0, roughness=5e-6, dx=3e-5, length=2**16, k_low=100.0),
        "stiffness": STIFFNESS_SPEC,
        "patch": ParamSpec(
            "float",
            0.0,
            low=0.0,
            high=1.0,
            unit="m",
            fixed=True,
            doc="contact patch size: low-pass at |v| / patch Hz (0: no low-pass)",
        ),
        **law_specs(),
    }

    def cutoff_per_speed(self) -> float:
        """kc (Hz per m/s) of the speed-dependent low-pass; 0 for none."""
        patch = self.values["patch"]
        return 1.0 / patch if patch > 0 else 0.0


@register
class ResonantScrape(TonalLevel, ContactControls):
    """Scraping force with a speed-dependent pitch: JASS ``ARContactForce``.

    Seeded white noise (unit RMS, splitmix64 per sample) through a resonator whose centre
    frequency is linear in speed, f = f0 + slope |v| (clamped to [0.5 Hz, 0.45 fs]), and
    whose decay rate (half the -3 dB bandwidth in rad/s; bandwidth ~ d / pi Hz) grows with
    speed, d = d0 + d_slope |v| (JASS: damping maxARd v / vmax). The resonator
    H(z) = g (1 - z^-2) / (1 - 2 R cos(theta) z^-1 + R^2 z^-2), R = exp(-d / fs),
    g = sqrt((1 - R^2) / 2), has unit white-noise power gain at every centre and bandwidth:
    with its zeros at z = +-1 (Steiglitz's constant-gain resonator) the sum of its squared
    impulse response is 2 / (1 - R^2) times g^2 whatever theta. So the output force has
    RMS gain * s(F, v) (N) at steady speed.

    Given the ``model`` it drives (``level`` 'auto' or 'calibrated'), the force is scaled by a
    table over the slip speed, computed once from the modes, so that at every speed a
    calibrated ModalBank of that model rings at jassy.levels.TONAL_RMS_DBFS x gain x s(F, v)
    (at the reference contact: TONAL_RMS_DBFS x gain; ugens/tonal_level.py).
    """

    type_name = "ResonantScrape"
    param_specs = {
        **contact_specs("slip speed (its magnitude tunes the resonance)"),
        "f0": ParamSpec(
            "float", 300.0, low=0.0, high=1e5, unit="Hz", fixed=True, doc="centre frequency at zero speed"
        ),
        "slope": ParamSpec(
            "float",
            2000.0,
            low=-1e6,
            high=1e6,
            unit="Hz s/m",
            fixed=True,
            doc="centre frequency increase per m/s",
        ),
        "damping": ParamSpec(
            "float",
            200.0,
            low=0.0,
            low_open=True,
            high=1e6,
            unit="1/s",
            fixed=True,
            doc="decay rate d0 of the resonance at zero speed (bandwidth ~ d / pi Hz)",
        ),
        "damping_slope": ParamSpec(
            "float", 500.0, low=0.0, high=1e7, unit="1/m", fixed=True, doc="decay-rate increase per m/s"
        ),
        "gain": ParamSpec(
            "float", 1.0, low=0.0, high=1e6, unit="N", fixed=True, doc="RMS force at the reference contact"
        ),
        "seed": seed_spec(),
        **law_specs(),
        **TONAL_LEVEL_SPECS,
    }

    def force_spectrum(self, speeds: np.ndarray | None = None) -> ForceSpectrum:
        """The force with gain 1 and s = 1 at each slip speed of ``speeds`` (default: v_ref):
        unit-power white noise through the resonator, one-sided PSD 2 |H(e^{i 2 pi f / fs})|^2
        / fs, one row per speed."""
        v, fs = self.values, self.sample_rate
        speed = np.atleast_1d(np.abs(v["v_ref"] if speeds is None else speeds))[:, None]
        centre = np.clip(v["f0"] + v["slope"] * speed, F_MIN, NYQUIST_FRACTION * fs)
        radius = np.exp(-(v["damping"] + v["damping_slope"] * speed) / fs)
        c1, c2 = 2.0 * radius * np.cos(2.0 * np.pi * centre / fs), radius * radius
        g = np.sqrt(0.5 * (1.0 - c2))

        def density(f: np.ndarray) -> np.ndarray:
            z = np.exp(-2j * np.pi * f / fs)[None, :]
            return 2.0 / fs * np.abs(g * (1.0 - z * z) / (1.0 - c1 * z + c2 * z * z)) ** 2

        return ForceSpectrum(np.zeros(0), np.zeros(0), density)

    def level_table(self) -> tuple[float, np.ndarray]:
        """(speed step in m/s, log of the calibrated level's factor at |v| = i x step), over
        the speeds that move the resonance from f0 to its clamp (at least to 2 v_ref); held
        beyond. Not calibrated: no table (step 0)."""
        if not self.is_calibrated():
            return 0.0, np.zeros(LEVEL_POINTS)
        v, fs = self.values, self.sample_rate
        if v["slope"] > 0:
            top = (NYQUIST_FRACTION * fs - v["f0"]) / v["slope"]
        elif v["slope"] < 0:
            top = (v["f0"] - F_MIN) / -v["slope"]
        else:
            top = 0.0
        step = min(max(top, 2.0 * v["v_ref"]), 100.0) / (LEVEL_POINTS - 1)
        gains = self.tonal_gain(self.force_spectrum(step * np.arange(LEVEL_POINTS)))
        return step, np.log(gains)

    def _prepare(self) -> None:
        super()._prepare()
        v, fs = self.values, self.sample_rate
        law, inv_ref, min_speed = self._law_config()
        config = NoiseConfig(
            f0=v["f0"],
            slope=v["slope"],
            d0=v["damping"],
            d_slope=v["damping_slope"],
            inv_fs=1.0 / fs,
            f_max=NYQUIST_FRACTION * fs,
            gain=v["gain"],
            law=law,
            inv_ref=inv_ref,
            min_speed=min_speed,
            level_step=0.0,
        )
        step, table = self.level_table()
        self.cfg = np.concatenate([np.array(config._replace(level_step=step), dtype=np.float64), table])
        self.rng = np.zeros(1, dtype=np.uint64)
        self.state = np.zeros(len(NoiseState._fields))
        self._kernel = specialise(
            resonant_noise, self.out, 0, self._forces, self._speeds, self.rng, self.state, self.cfg
        )

    def _reset(self) -> None:
        super()._reset()
        self.rng[0] = self.values["seed"]
        self.state[:] = NoiseState(
            0.0, 0.0, 0.0, 0.0, UNDESIGNED, 0.0, 0.0, 0.0
        )  # design on the first sample

    def process(self, start: int, n: int) -> None:
        forces, speeds = self._controls(start, n)
        self._kernel(self.out, n, forces, speeds, self.rng, self.state, self.cfg)

    def state_arrays(self) -> dict[str, np.ndarray]:
        return {**super().state_arrays(), "rng": self.rng, "state": self.state}
