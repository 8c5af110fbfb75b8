"""Rolling contact forces: Roll (van den Doel's filtered profile) and RathRoll (Rath's rolling filter).

Both are force generators (output in N, to drive a ModalBank) controlled by the
smoothed contact parameters ``force`` (N) and ``speed`` (rolling speed, m/s); open loop,
or with a ``model`` through the ball's contact on a surface that gives way
(:mod:`ugens.driving_point`).
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numba as nb
import numpy as np

from jassy.errors import PatchError
from jassy.jit import drop_stale_cache, specialise
from jassy.params import ParamSpec
from jassy.registry import register
from ugens import cells, driving_point, filters, kernels, scrape
from ugens.cells import slot, store
from ugens.driving_point import MODE_ROWS, driving_point_modes, free_motion, move_contact, press, roll_over
from ugens.filters import biquad_coefficients, biquad_step, design_biquad
from ugens.kernels import FASTMATH
from ugens.modal import ModelParams
from ugens.scrape import (
    NYQUIST_FRACTION,
    STIFFNESS_SPEC,
    NeedleContact,
    ProfileConfig,
    ProfileContact,
    contact_specs,
    law_specs,
    profile_specs,
    read_profile,
    wrap,
)

# rolling_filter (cache=True) inlines free_motion, press and settle, the cells' and the
# profile's helpers; Roll's kernel calls roll_over.
drop_stale_cache(__file__, [cells, driving_point, filters, kernels, scrape])

#: Standard gravity, m/s^2 (SDT_EARTH).
GRAVITY = 9.81
#: Points per revolution of the ball's unevenness table.
BALL_POINTS = 256
#: Harmonics of the ball's unevenness (amplitudes 1/k^3, the first one 1).
BALL_HARMONICS = 6


def ball_unevenness(seed: int) -> np.ndarray:
    """One revolution of a ball's unevenness g(phi): sum_k k^-3 cos(k phi + psi_k),
    k = 1 .. BALL_HARMONICS, random phases psi_k from ``seed``; sampled at BALL_POINTS
    angles plus one wrap point. The fundamental (amplitude 1) dominates, as for an
    out-of-round ball whose centre rises and falls once per turn; |g| < 1.21."""
    psi = np.random.default_rng(seed).uniform(0.0, 2.0 * np.pi, BALL_HARMONICS)
    phi = 2.0 * np.pi * np.arange(BALL_POINTS + 1) / BALL_POINTS
    k = np.arange(1, BALL_HARMONICS + 1)[:, None]
    return (np.cos(k * phi + psi[:, None]) / k**3).sum(axis=0)


@nb.njit(fastmath=FASTMATH, cache=True)
def turn_weight(table, phase, depth):
    """1 + depth g(phase) from the unevenness table (phase in revolutions, [0, 1))."""
    x = phase * BALL_POINTS
    i = int(x)
    return 1.0 + depth * (table[i] + (x - i) * (table[i + 1] - table[i]))


@nb.njit(fastmath=FASTMATH, cache=True)
def modulate_by_turn(out, n, speeds, table, turn, per_metre, depth):
    """out[:n] *= 1 + depth g(phase): the ball's unevenness at its rotation phase.

    turn[0]: phase in revolutions, advanced by |v| per_metre / fs per sample (per_metre
    = 1 / (2 pi r fs))."""
    phase = turn[0]
    for i in range(n):
        out[i] *= turn_weight(table, phase, depth)
        phase += abs(speeds[i]) * per_metre
        phase -= math.floor(phase)
    turn[0] = phase


class Turning:
    """Mixin of Roll and RathRoll: with a ``radius`` r > 0 the generated profile is the
    ball's own surface, one revolution long: round(2 pi r / dx) points spaced exactly
    2 pi r / points, so the force repeats every 2 pi r of travel (a given ``profile`` or
    ``profile_file`` is read as it is)."""

    def turning(self) -> bool:
        v = self.values
        return v["radius"] > 0 and v["profile"] is None and not v["profile_file"]

    def loop_dx(self) -> float:
        """Spacing of the profile points, m."""
        v = self.values
        if not self.turning():
            return v["dx"]
        return 2.0 * math.pi * v["radius"] / max(4, round(2.0 * math.pi * v["radius"] / v["dx"]))

    def heights(self, where: str | None = None) -> np.ndarray:
        if not self.turning():
            return super().heights(where)
        v = self.values
        dx = self.loop_dx()
        n = round(2.0 * math.pi * v["radius"] / dx)
        return self._fractal(n, 1.0 if self.unit_rms else v["roughness"], dx, where)


def surface_specs(stiffness: float, doc: str) -> dict[str, ParamSpec]:
    """The surface a rolling force presses on (``model``, ``location``) and the contact
    spring between them (``contact_stiffness``, default ``stiffness``, N/m)."""
    return {
        "model": ParamSpec(
            "model",
            None,
            fixed=True,
            doc="the surface's ModalModel: the force reaches it through the contact spring and it "
            "gives way (its driving-point modes at `location`); none: a rigid surface (open loop)",
        ),
        "location": ParamSpec("location", 0, doc="contact location on the model"),
        "contact_stiffness": ParamSpec(
            "float", stiffness, low=0.0, high=1e12, unit="N/m", fixed=True, doc=doc
        ),
    }


class GivingSurface(ModelParams):
    """Mixin of the rolling forces: with a ``model`` the force reaches the surface's
    driving-point modes at ``location`` through the contact spring ``contact_stiffness``
    and the surface gives way under it (:mod:`ugens.driving_point`)."""

    driving_point = True

    def _prepare_surface(self) -> None:
        self.surface = None
        if self.values["model"] is None:
            return
        self.validate_model()
        self.check_param("location", self.values["location"], f"nodes.{self.name}.location")  # gains >= 0
        self.surface = np.zeros((MODE_ROWS, self.model.n_modes))
        self._scratch = np.zeros(self.model.n_modes)
        self._design_surface()

    def _design_surface(self) -> None:
        self._gain_sum = driving_point_modes(
            self.model, self.values["location"], self.sample_rate, self.surface
        )

    def _param_changed(self, key: str, value: Any, jump: bool) -> None:
        if key == "location":
            if self.surface is not None:  # the gains jump; the surface's modes keep their motion
                gains_before = self.surface[2].copy()
                self._design_surface()
                self._contact_moved(*move_contact(self.surface, gains_before))
        else:
            super()._param_changed(key, value, jump)

    def _contact_moved(self, last: float, previous: float) -> None:
        """The contact displacement in the last two samples changed by ``last``,
        ``previous`` (m) as the contact moved (:func:`move_contact`)."""

    def _reset(self) -> None:
        super()._reset()
        if self.surface is not None:
            self.surface[3:] = 0.0

    def state_arrays(self) -> dict[str, np.ndarray]:
        arrays = super().state_arrays()
        if self.surface is not None:
            arrays["surface"] = self.surface
        return arrays


def rotation_specs() -> dict[str, ParamSpec]:
    """The ball's ``radius`` and ``unevenness`` (a per-revolution load variation)."""
    return {
        "radius": ParamSpec(
            "float",
            0.0,
            low=0.0,
            high=10.0,
            unit="m",
            fixed=True,
            doc="ball radius r: the profile is one revolution of the ball, repeating every "
            "2 pi r of travel, and its unevenness varies the load (0: no rotation)",
        ),
        "unevenness": ParamSpec(
            "float",
            0.4,
            low=0.0,
            high=0.8,
            fixed=True,
            doc="relative load variation per revolution (the ball's out-of-roundness)",
        ),
    }


@register
class Roll(GivingSurface, Turning, NeedleContact):
    """Rolling force: a smooth profile read at the rolling speed through a speed-tracking low-pass.

    van den Doel, Kry & Pai, FoleyAutomatic (SIGGRAPH 2001), JASS ``ContactForce`` roll:
    the same needle mechanism as Scrape on a smoother profile (1/k^beta, beta = 2 by
    default; heights in m, RMS ``roughness``), read at ``speed / (dx fs)`` points per
    sample, then a second-order Butterworth low-pass whose cutoff follows the speed,
    fc = fc0 |v| / v0 (clamped to [0.5 Hz, 0.45 fs]). JASS uses a fixed 100 Hz; a cutoff
    proportional to speed is a fixed spatial cutoff fc0 / v0 cycles per m (the ball cannot
    follow details shorter than its contact), so the whole spectrum scales with speed.

    Output force (N): stiffness * s(F, v) * h_lp(x(t)), with the amplitude law s of
    ugens/scrape.py (sqrt(F v / (f_ref v_ref)) by default): RMS = stiffness * roughness
    (times the low-pass's share of the profile's variance) at the reference contact.

    With a ``radius`` r > 0 the ball turns: the profile is the ball's own surface, one
    revolution long (``Turning``), and its unevenness varies the load: the output is
    multiplied by
    1 + ``unevenness`` g(phi), phi the rotation angle (``ball_unevenness``), so the sound's
    envelope is modulated at the rotation rate |v| / (2 pi r).

    The default ``force`` is the weight of a light ball (8 g, 0.08 N): rolled at 0.2 m/s
    over a calibrated ModalBank (jassy.levels) it peaks between -30 and -6 dBFS.

    With a ``model`` (the surface's ModalModel, at ``location``) the output over
    ``stiffness`` (> 0 required), r = s(F, v) h_lp(x) (1 + ``unevenness`` g(phi)) (m): the
    filtered profile height scaled by the amplitude law and the out-of-roundness, so
    ``stiffness`` cancels; r is the roughness under the rolling contact filter
    (:func:`ugens.driving_point.roll_over`): the ball of ``mass`` m rides on its contact
    spring ``contact_stiffness`` k (and dashpot ``contact_damping``) over r, and the surface
    gives way under it, F = r / (1/k - 1/(m w^2) + alpha(w)). The output is then the
    dynamic contact force on the surface, to drive a ModalBank of the same model at the
    same location. Use ``law = "height"`` (s = 1 while loaded and moving) with a model:
    the filter already makes the force grow with speed (F = m w^2 r below the contact
    resonance, w = 2 pi v / wavelength) and with the load (through k), so an amplitude law
    on top would count them twice. The filter is linear: the spring may pull (F < -load)
    where a real ball would leave the surface (the micro-impacts of RathRoll).
    """

    type_name = "Roll"
    param_specs = {
        **contact_specs(
            "rolling speed (signed: the profile is read backwards for v < 0)",
            0.08,
            "normal contact force F (default: the weight of an 8 g ball, a 12.5 mm steel ball)",
        ),
        **profile_specs(beta=2.0, roughness=2e-5, dx=1e-4, length=2**16, k_low=20.0),
        "stiffness": STIFFNESS_SPEC,
        "fc0": ParamSpec(
            "float",
            100.0,
            low=0.0,
            low_open=True,
            high=1e5,
            unit="Hz",
            fixed=True,
            doc="low-pass cutoff at the speed v0 (JASS's 100 Hz)",
        ),
        "v0": ParamSpec(
            "float",
            0.2,
            low=0.0,
            low_open=True,
            high=100.0,
            unit="m/s",
            fixed=True,
            doc="speed at which the cutoff is fc0",
        ),
        **law_specs(v_ref=0.2),
        **rotation_specs(),
        "mass": ParamSpec(
            "float",
            0.008,
            low=0.0,
            low_open=True,
            high=1e4,
            unit="kg",
            fixed=True,
            doc="mass of the ball (with a `model`: its inertia in the contact filter)",
        ),
        **surface_specs(
            1.1e7,
            "with a `model`: the ball's Hertz contact spring (6 E*^2 R W)^(1/3) (Johnson, Contact "
            "Mechanics, ch. 4); 1.1e7 for a 30 mm steel ball on steel under its weight",
        ),
        "contact_damping": ParamSpec(
            "float",
            0.0,
            low=0.0,
            high=1e9,
            unit="N s/m",
            fixed=True,
            doc="with a `model`: a dashpot beside the contact spring (N s/m)",
        ),
    }

    def cutoff_per_speed(self) -> float:
        """kc = fc0 / v0 (Hz per m/s)."""
        return self.values["fc0"] / self.values["v0"]

    def _filters_height(self) -> bool:
        return self.values["model"] is not None

    def _prepare(self) -> None:
        super()._prepare()
        v = self.values
        self.cfg[slot(ProfileConfig, "inv_dxfs")] = 1.0 / (self.loop_dx() * self.sample_rate)
        self.ball = ball_unevenness(v["seed"] + 1)
        self.turn = np.zeros(1)
        self._per_metre = 1.0 / (2.0 * math.pi * v["radius"] * self.sample_rate) if v["radius"] > 0 else 0.0
        self._prepare_surface()
        if self.surface is not None and not v["stiffness"] > 0.0:
            raise PatchError(
                f"nodes.{self.name}.stiffness: expected > 0 with a model (the output over it is the "
                f"roughness), got {v['stiffness']}"
            )
        self._inv_stiffness = 1.0 / v["stiffness"] if self.surface is not None else 0.0
        self._ball_motion = np.zeros(3)  # the ball's rise y[n-1], y[n-2] (m), compression (m)
        self._contact_law = np.array([v["contact_stiffness"], v["contact_damping"], self.sample_rate])

    def _reset(self) -> None:
        super()._reset()
        self.turn[0] = 0.0
        self._ball_motion[:] = 0.0

    def _contact_moved(self, last: float, previous: float) -> None:
        """The ball follows the surface at the new contact (x away from the ball, y its rise):
        y - x and so the compression d = r - y - x are kept."""
        self._ball_motion[0] -= last
        self._ball_motion[1] -= previous

    def process(self, start: int, n: int) -> None:
        super().process(start, n)
        if self._per_metre > 0.0:
            modulate_by_turn(
                self.out, n, self._speeds, self.ball, self.turn, self._per_metre, self.values["unevenness"]
            )
        if self.surface is not None:
            v = self.values
            roll_over(
                self.out,
                self._forces,
                n,
                self.surface,
                self._scratch,
                self._ball_motion,
                self._contact_law,
                self._inv_stiffness,
                1.0 / (v["mass"] * self.sample_rate**2),
                self._gain_sum,
            )

    def state_arrays(self) -> dict[str, np.ndarray]:
        return {**super().state_arrays(), "turn": self.turn, "ball_motion": self._ball_motion}


@nb.njit(fastmath=FASTMATH, cache=True)
def highest(prof, start, span):
    """Highest point of the looped, linearly interpolated profile over fractional indices
    [start, start + span] (span >= 0): an end or a profile point inside."""
    L = prof.shape[0]
    top = max(read_profile(prof, wrap(start, L), False), read_profile(prof, wrap(start + span, L), False))
    i = int(math.floor(start)) + 1
    while i < start + span:
        j = i % L
        if prof[j] > top:
            top = prof[j]
        i += 1
    return top


class RollingConfig(NamedTuple):
    """Settings of :func:`rolling_filter`, stored in this order in the float64 array ``cfg``."""

    inv_dxfs: float  #: 1/(dx fs): profile points per (m/s) per sample
    mass: float  #: mass of the ball (kg)
    grain: float  #: the trace falls 2 grain |v| per sample (at most 2)
    depth: float  #: bump scale (1/m)
    has_input: float  #: 1.0 when an audio-rate surface signal replaces the profile
    cubic: float  #: 1.0 for cubic profile interpolation, 0.0 for linear
    smoothed: float  #: 1.0 when the output is low-passed (coef)
    per_metre: float  #: 1/(2 pi r fs): revolutions per (m/s) per sample (0 = no rotation)
    unevenness: float  #: load factor w = 1 + unevenness g(phase) of the ball's unevenness table


@nb.njit(inline="always", cache=True)
def rolling_config(cfg):
    """The RollingConfig record held in ``cfg``."""
    return RollingConfig(cfg[0], cfg[1], cfg[2], cfg[3], cfg[4], cfg[5], cfg[6], cfg[7], cfg[8])


class RollingState(NamedTuple):
    """State of :func:`rolling_filter`, stored in this order in the float64 array ``state``."""

    pos: float  #: profile position (points)
    trace: float  #: the ground trace
    airborne: float  #: 1.0 while the ball flies
    flight: float  #: flight counter c (N samples)
    bump: float  #: bump force B (N)
    s1: float  #: contact low-pass, first DF2T state
    s2: float  #: contact low-pass, second DF2T state
    phase: float  #: rotation phase (revolutions)
    height: float  #: the flying ball's height above its take-off point (m)
    takeoff: float  #: the surface's displacement at the contact at the take-off (m)


@nb.njit(inline="always", cache=True)
def rolling_state(state):
    """The RollingState record held in ``state``."""
    return RollingState(
        state[0],
        state[1],
        state[2],
        state[3],
        state[4],
        state[5],
        state[6],
        state[7],
        state[8],
        state[9],
    )


class RollingSetup(NamedTuple):
    """The arrays :func:`rolling_filter` reads but does not change: the surface profile
    ``prof`` (heights, m), ``coef`` = [b0, b1, b2, a1, a2] of the optional contact low-pass
    (DF2T, states s1, s2), ``cfg`` holding a RollingConfig and ``ball``, the unevenness
    table (ball_unevenness)."""

    prof: np.ndarray
    coef: np.ndarray
    cfg: np.ndarray
    ball: np.ndarray


class SurfaceLaw(NamedTuple):
    """How :func:`rolling_filter` meets a surface that gives way, stored in this order in
    the float64 array ``law`` (unused without the surface's modes)."""

    stiffness: float  #: the ball's contact spring k (N/m)
    gain_sum: float  #: G, the surface's displacement per newton within a sample (m/N)
    mass_fs2: float  #: m fs^2 (N/m): the ball's momentum per sample over a displacement


@nb.njit(inline="always", cache=True)
def surface_law(law):
    """The SurfaceLaw record held in ``law``."""
    return SurfaceLaw(law[0], law[1], law[2])


@nb.njit(inline="always", cache=True)
def profile_under(prof, pos, v, inv_dxfs, turning, cubic):
    """The surface height (m) under the contact at profile position ``pos`` (points) at speed
    ``v`` (m/s): on a turning ball the highest point of its surface over this sample's travel,
    else the profile read at ``pos``."""
    if turning:
        step = v * inv_dxfs
        return highest(prof, pos if step >= 0.0 else pos + step, abs(step))
    return read_profile(prof, pos, cubic)


@nb.njit(inline="always", cache=True)
def flight_step(c, bump, load, height, mass_fs2, giving, turned, free, takeoff):
    """One sample of a flight: c -= W (``load``); returns (output, still airborne, c, height).

    On a rigid surface the ball lands once c <= 0 (output B - c - W, B = ``bump``), else
    outputs -W. On a surface that gives way it lands on the surface, not at its ballistic
    time: its height above the take-off point, h = sum of its momentum p = c - B (N samples;
    trapezoid rule, exact for a constant W) over m fs^2 (``mass_fs2``), is compared with the
    surface's displacement X at the contact (``free``: this sample's free motion, positive
    away from the ball), and the ball lands in the first sample where the gap
    h + X - X_takeoff <= 0 (on a surface at rest that is c <= 0), with Rath's impulse B - c,
    the ball's own downward momentum (0 if still rising): output max(0, B - c) - W; the
    surface's velocity is not added. A new turn (``turned``) lands it at once."""
    if giving:  # the ball's momentum before and after this sample, p = c - B
        height += (c - bump - 0.5 * load) / mass_fs2
    c -= load
    if not giving and c <= 0.0:
        return bump - c - load, False, c, height
    if giving and (turned or height + free - takeoff <= 0.0):  # the ball meets the surface
        return max(0.0, bump - c) - load, False, c, height
    return -load, True, c, height


class YieldingSurface(NamedTuple):
    """The surface under :func:`rolling_filter`: its driving-point ``modes`` at the contact
    (MODE_ROWS, K; :mod:`ugens.driving_point`; K = 0: a rigid surface), their ``scratch``
    (K) and ``law``, a float64 array holding a SurfaceLaw."""

    modes: np.ndarray
    scratch: np.ndarray
    law: np.ndarray


@nb.njit(fastmath=FASTMATH, cache=True)
def rolling_filter(out, contact, n, forces, speeds, inputs, state, setup, yielding):
    """Rath's rolling filter (SDT ``SDTRolling_dsp``) with exact momentum bookkeeping, on
    a rigid surface or one that gives way.

    Forces (N), speeds (m/s) and the optional surface input per sample; ``state`` holds a
    RollingState; ``setup``: a RollingSetup; ``yielding``: a YieldingSurface (its modes
    without columns: a rigid surface).
    Per sample: w = 1 + unevenness g(phase) (1 without rotation); W = (m g + F) w;
    x = input or profile; decay = clip(2 grain |v|, 0, 2); ground = max(trace - decay, x).
    Airborne: c -= W; the ball lands in this sample once c <= 0 (output B - c - W, and it
    is on the ground for the rest of the sample), else output -W. On the ground (also on
    the landing sample: a flight lasts ceil(2 B / W) samples, the first sample at or after
    the ballistic landing time 2 B / W, as SDT): if ground > trace and decay > 0, launch
    with B = (ground - trace) depth (m v^2 / 2) w / sqrt(decay), c = 2 B (output + B).
    contact = output + W (0 in flight). With smoothing, the output is low-passed first.

    On a surface that gives way the ball lands on the surface (:func:`flight_step`), and
    the (low-passed) output then reaches the surface through the contact spring while
    contact > 0 (:func:`press`); the output and ``contact`` are the force on the moving
    surface. A new turn lands a flight at once in either case.
    """
    prof, coef, cfg, ball = setup
    modes, scratch, law = yielding
    config = rolling_config(cfg)
    inv_dxfs, mass, per_metre = config.inv_dxfs, config.mass, config.per_metre
    has_input = config.has_input != 0.0
    cubic = config.cubic != 0.0
    smoothed = config.smoothed != 0.0
    giving = modes.shape[1] > 0
    stiffness, gain_sum, mass_fs2 = surface_law(law)
    lowpass = biquad_coefficients(coef)
    L = prof.shape[0]
    held = rolling_state(state)
    pos = held.pos
    trace = held.trace
    airborne = held.airborne != 0.0
    c = held.flight
    bump = held.bump
    s1 = held.s1
    s2 = held.s2
    phase = held.phase
    height = held.height
    takeoff = held.takeoff
    weight = mass * GRAVITY
    turning = per_metre > 0.0 and not has_input
    for i in range(n):
        v = speeds[i]
        w = 1.0
        turned = False
        if turning and phase >= 1.0:  # a new turn: the ball's surface from its start
            phase = 0.0
            pos = 0.0
            if airborne:
                c = 0.0  # land in this sample (the flight's momentum still balances)
                turned = True
        if per_metre > 0.0:
            w = turn_weight(ball, phase - math.floor(phase), config.unevenness)
            phase += abs(v) * per_metre
            if not turning:
                phase -= math.floor(phase)
        load = (weight + forces[i]) * w
        x = inputs[i] if has_input else profile_under(prof, pos, v, inv_dxfs, turning, cubic)
        decay = min(2.0 * config.grain * abs(v), 2.0)
        ground = max(trace - decay, x)
        free = free_motion(modes, scratch, 0.0) if giving else 0.0
        y = 0.0
        if airborne:
            y, airborne, c, height = flight_step(
                c, bump, load, height, mass_fs2, giving, turned, free, takeoff
            )
        if not airborne and ground > trace and decay > 0.0:
            b = (ground - trace) * config.depth * 0.5 * mass * v * v * w / math.sqrt(decay)
            if b > 0.0:
                bump = b
                c = 2.0 * b
                airborne = True
                y += b
                height = 0.0
                takeoff = free
        trace = ground
        if smoothed:
            y, s1, s2 = biquad_step(lowpass, y, s1, s2)
        touch = y + load
        if giving:
            f = press(modes, scratch, free, y, stiffness if touch > 0.0 else 0.0, gain_sum)
            touch += f - y
            y = f
        out[i] = y
        contact[i] = touch
        if not has_input:
            pos = wrap(pos + v * inv_dxfs, L)
    store(
        state,
        RollingState(pos, trace, 1.0 if airborne else 0.0, c, bump, s1, s2, phase, height, takeoff),
    )


@register
class RathRoll(GivingSurface, Turning, ProfileContact):
    """Rolling as micro-impacts: Rath's rolling filter (DAFx-03; SDT ``SDTRolling_dsp``).

    A ball of ``mass`` m pressed by its weight and the extra normal ``force`` F (total load
    W = m g + F, N) rolls at ``speed`` v over a surface signal x: its own looped 1/k^beta
    profile (unit RMS, dimensionless) read at v / (dx fs) points per sample, or the
    optional ``input`` (an audio-rate surface signal, e.g. noise; then speed only sets the
    dynamics). A ground trace follows max(trace - decay, x), decay = clip(2 grain |v|, 0, 2)
    per sample; a rise while the ball is on the ground launches it with the bump force
    B = (ground - trace) * depth * (m v^2 / 2) / sqrt(decay) N for one sample (impulse
    B / fs), and it stays airborne until a counter of 2 B, decremented by W every sample,
    reaches zero: the ballistic flight time 2 u / g_eff = 2 B / W samples of a launch speed
    u = B / (m fs) under the load W (SDT: flight = 2 bump, decremented by m g per sample);
    the ball is back on the ground from the landing sample on and may take off again
    there, so a flight lasts ceil(2 B / W) samples, as in SDT.
    B grows about as depth v^2.5, so the take-off rate rises with speed until flights get
    long; faster, the ball skips bumps: fewer, harder hops.

    Defaults: a 30 g steel ball (19 mm) rolling on a wooden table. It rides on the highest
    asperities (``grain`` 0.002: the trace falls slowly, as a ball much larger than the
    roughness bridges its valleys), and each micro-impact lasts about its bounce period on
    the Hertz contact: ``contact_cutoff`` 700 Hz is sqrt(k / m) / 2 pi for the contact
    stiffness k = 3 W / (2 delta) of the ball under its weight on wood (E* about 2-4 GPa;
    Johnson, *Contact Mechanics*, 1985, ch. 4; SDT's impact interactor plays this part).
    With ``depth`` 2000 /m, at 0.2 m/s it hops about 90 times a second, 0.9 ms flights
    (1 um high), at 1 m/s about 50 times, 19 ms flights. The former defaults
    (grain 0.5, depth 50, no low-pass) hop every few samples with sub-sample flights: their
    force is a train of one-sample doublets whose spectrum rises as the frequency up to
    about 12 kHz, so an object whose modes lie below a few kHz hears up to 55 dB less of
    it than one ringing near 10 kHz. With these defaults the force carries the low modes
    too: at 0.2 m/s through every shipped model's calibrated bank (jassy.levels) with unit
    gain it peaks within -30..-6 dBFS (tests/test_source_levels.py).

    Output (N): the force the ball exerts on the surface minus the static load W: +B at a
    take-off, -W while airborne (the surface is unloaded), B + r - W at the landing sample
    (r = -counter in [0, W): the landing stops the ball, and r makes each flight's contact
    impulses equal W times its duration, i.e. momentum balance), 0 while rolling on the
    ground. The output therefore sums to zero over every flight (DC-free; the mean contact
    force is the load W) and can drive a ModalBank directly: the static load would only
    deflect the resonator. Optionally (``contact_cutoff``) the output is low-passed for the
    finite duration of each micro-impact. Extra output ``contact``: the total contact force
    on the surface (N), output + W (0 in flight without the low-pass), e.g. for haptics.

    With a ``radius`` r > 0 the ball turns: its unevenness, periodic per revolution (every
    2 pi r of travel), scales the load W and the bumps B by 1 + ``unevenness`` g(phi)
    (``ball_unevenness``), so the take-offs and their strength follow the rotation rate
    |v| / (2 pi r). Without an ``input`` or given profile, the surface x is then the
    ball's own, one turn long (``Turning``; the track is taken as smooth): each sample
    reads its highest point under the contact over the sample's travel (the ball rides
    on the highest asperity, whatever the sample grid), and every turn starts at the
    same point of the ball in the same state (a flight still in the air lands in that
    sample; the turn's fraction of a sample is dropped, so a turn lasts a whole number
    of samples, at most one sample, 0.04 % at 2 m/s for r = 15 mm, longer than 2 pi r /
    v). At a steady speed the micro-impacts then repeat every turn, as the continuous
    model would: a flight quantised to whole samples otherwise sends the filter, a
    sensitive map of its state, onto another hop sequence each turn, and the plate's
    slow response to that random sequence (decays of a few per second) hides the
    per-turn modulation above about 1 m/s.

    With a ``model`` (the surface's ModalModel, at ``location``) the force reaches the
    surface through the ball's contact spring, ``contact_stiffness`` k, and the surface
    gives way: while the ball touches, the force is f - k x (f: the open-loop force above,
    x: the surface's displacement at the contact, from its driving-point modes, solved per
    sample without delay; :func:`ugens.driving_point.press`). A flight then ends when
    the ball meets the moving surface, not at Rath's ballistic time, which assumes a
    surface at rest (:func:`rolling_filter`): on the shipped steel plate the surface
    moves more than the ball flies above about 1 m/s (1.2e-7 m RMS at the contact against
    flights of 6e-8 m at 1.75 m/s), and a ball still rising when the surface meets it
    lands without an impulse (the model drops the ball's small upward momentum, so the
    force's mean is then slightly above zero). An open-loop force drives a lightly
    damped mode that one of its lines (or a burst of hops) lands on as if the surface were
    rigid, and the mode's response grows with its Q; a real surface moves away under the
    ball instead, which caps the force at resonance where the surface's receptance exceeds
    1 / k (the steel plate at its strong modes' resonances: 1e-6..2e-4 m/N, against 9e-8
    m/N for a 30 mm steel ball): the contact filter of rolling-noise models (Remington,
    JASA 81, 1987; Thompson, *Railway Noise and Vibration*, 2009, ch. 5); SDT couples its
    rolling filter to the resonators through an impact interactor. The output is the
    force on the surface, to drive a ModalBank of the same model at the same location;
    the extra output ``contact`` moves with it.
    """

    type_name = "RathRoll"
    inputs = ("input",)
    optional_inputs = ("input",)
    outputs = ("contact",)
    unit_rms = True
    param_specs = {
        **contact_specs("rolling speed", 0.0, "normal force pressing the ball besides its weight m g"),
        "mass": ParamSpec(
            "float", 0.03, low=0.0, low_open=True, high=1e4, unit="kg", fixed=True, doc="mass of the ball"
        ),
        "grain": ParamSpec(
            "float",
            0.002,
            low=0.0,
            high=1.0,
            fixed=True,
            doc="surface grain: the ground trace falls 2 grain |v| per sample (denser micro-impacts)",
        ),
        "depth": ParamSpec(
            "float",
            2000.0,
            low=0.0,
            high=1e9,
            unit="1/m",
            fixed=True,
            doc="bump depth: B = rise * depth * kinetic energy / sqrt(decay)",
        ),
        "contact_cutoff": ParamSpec(
            "float",
            700.0,
            low=0.0,
            high=1e5,
            unit="Hz",
            fixed=True,
            doc="second-order Butterworth low-pass of the output for the micro-impacts' contact "
            "duration (~1/cutoff s; SDT gets it from its impact interactor); 0: none",
        ),
        **profile_specs(beta=1.0, roughness=None, dx=1e-5, length=2**16, k_low=100.0),
        **rotation_specs(),
        **surface_specs(
            1.1e7,
            "the ball's contact spring with a `model`: Hertz's (6 E*^2 R W)^(1/3) (Johnson, "
            "Contact Mechanics, ch. 4); 1.1e7 for a 30 mm steel ball on steel under its weight",
        ),
    }

    def _prepare(self) -> None:
        super()._prepare()
        v = self.values
        config = RollingConfig(
            inv_dxfs=1.0 / (self.loop_dx() * self.sample_rate),
            mass=v["mass"],
            grain=v["grain"],
            depth=v["depth"],
            has_input=float("input" in self.sources),
            cubic=float(v["interp"] == "cubic"),
            smoothed=float(v["contact_cutoff"] > 0),
            per_metre=1.0 / (2.0 * math.pi * v["radius"] * self.sample_rate) if v["radius"] > 0 else 0.0,
            unevenness=v["unevenness"],
        )
        self.cfg = np.array(config, dtype=np.float64)
        self.ball = ball_unevenness(v["seed"] + 1)
        self.state = np.zeros(len(RollingState._fields))
        self.coef = np.zeros(5)
        if v["contact_cutoff"] > 0:
            fc = min(v["contact_cutoff"], NYQUIST_FRACTION * self.sample_rate)
            design_biquad(0, fc, 1.0 / math.sqrt(2.0), 1.0 / self.sample_rate, self.coef)
        self._setup = RollingSetup(self.prof, self.coef, self.cfg, self.ball)
        self._law = np.zeros(len(SurfaceLaw._fields))
        self._prepare_surface()
        if self.surface is None:  # a rigid surface: no modes
            self._yielding = YieldingSurface(np.zeros((MODE_ROWS, 0)), np.zeros(0), self._law)
        else:
            self._yielding = YieldingSurface(self.surface, self._scratch, self._law)
        self._kernel = specialise(
            rolling_filter,
            self.out,
            self.extra["contact"],
            0,
            self._forces,
            self._speeds,
            self.input_buffer("input"),
            self.state,
            self._setup,
            self._yielding,
        )

    def _design_surface(self) -> None:
        super()._design_surface()
        self._law[:] = SurfaceLaw(
            self.values["contact_stiffness"], self._gain_sum, self.values["mass"] * self.sample_rate**2
        )

    def _contact_moved(self, last: float, previous: float) -> None:
        """A flight's gap is measured from the new contact."""
        self.state[slot(RollingState, "takeoff")] += last

    def _reset(self) -> None:
        super()._reset()
        # start on the ground with the trace at the surface
        trace = self.prof[0] if "input" not in self.sources else 0.0
        self.state[:] = 0.0
        self.state[slot(RollingState, "trace")] = trace

    def process(self, start: int, n: int) -> None:
        forces, speeds = self._controls(start, n)
        self._kernel(
            self.out,
            self.extra["contact"],
            n,
            forces,
            speeds,
            self.input_buffer("input"),
            self.state,
            self._setup,
            self._yielding,
        )

    def state_arrays(self) -> dict[str, np.ndarray]:
        return {**super().state_arrays(), "state": self.state}
