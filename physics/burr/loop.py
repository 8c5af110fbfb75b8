"""The haptic-rate burr simulation: pose in, force out; and the constant-force descent.

One :meth:`BurrSim.step` (Agus et al., IEEE VR 2002/2003), one compiled call
(:func:`physics.burr.update.haptic_update`):

1. moments m0, m1 of the density in the burr ball (octree or brute-force voxel sum);
2. n = -m1/|m1| (out of the bone), h from m0 = pi rho0 R^3 (h/R)^2 (1 - h/(3R)) and the
   elastic force F_e = c_e R^2 (h/R)^(3/2) n (zero when n is undefined: burr fully immersed
   or density symmetric about the centre, |m1| <= 1e-9 m0 R);
3. the Hertz pressure P(xi) = P0 sqrt(1 - xi^2/a^2), a = sqrt(R h), P0 = 3|F_e|/(2 pi a^2)
   (normalised on the voxels), friction mu P dsigma against the sliding velocity of each
   voxel's burr-surface point (spin omega x p plus tool velocity) and the frictional power;
4. erosion: each voxel loses K_er * power_i * dt kg (8-bit counter, Russian roulette), its
   decrement is subtracted from its octree brick as it is eroded, and the levels above are
   rebuilt over the changed box.

Units: SI (m, N, rad/s, kg); the volume's counters are density fractions of ``rho_full``.
The force returned is the force of the bone on the burr (what the haptic device renders).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from jassy.errors import JassyError
from jassy.events import ContactTrack, HapticFrame
from jassy.jit import specialise
from physics.burr.contact import (
    CONTACT_TALLY,
    CONTACT_VOXEL,
    NO_BRICKS,
    BurrModel,
    ContactData,
    brute_moments,
)
from physics.burr.octree import BLOCK_COLUMNS, Octree, Pyramid
from physics.burr.update import STEP_RESULT, Burr, haptic_update
from physics.burr.volume import Volume

_FLOAT64 = np.dtype(np.float64)


@dataclass(frozen=True)
class BurrParams:
    """Burr and material constants (tunable per simulation, fixed once it is built; the
    papers' fitted values are not reproduced).

    radius (m); c_e (N/m^2): elastic constant of F_e = c_e R^2 (h/R)^(3/2), a haptic-scale
    stiffness rather than bone's (4/3) E*; mu: burr-bone friction coefficient; rho0 (counter
    units): the reference density of the h inversion (255 = ``rho_full``); erosion (kg/J):
    bone mass removed per joule of frictional work; method: "octree" or "brute"; leaf
    (voxels): partial-volume threshold of the octree (1 = exact voxel sum).
    """

    radius: float = 1.5e-3
    c_e: float = 5.0e6
    mu: float = 0.3
    rho0: float = 255.0
    erosion: float = 5.0e-6
    method: str = "octree"
    leaf: int = 1

    def check(self) -> None:
        for name in ("radius", "c_e", "rho0"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise JassyError(f"BurrParams.{name}: expected a number > 0, got {v!r}")
        for name in ("mu", "erosion"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise JassyError(f"BurrParams.{name}: expected a number >= 0, got {v!r}")
        if self.method not in ("octree", "brute"):
            raise JassyError(f"BurrParams.method: expected 'octree' or 'brute', got {self.method!r}")
        if int(self.leaf) < 1:
            raise JassyError(f"BurrParams.leaf: expected an integer >= 1, got {self.leaf!r}")


@dataclass
class ContactState:
    """Result of one haptic step (SI units)."""

    force: np.ndarray  # total force of the bone on the burr, N
    elastic: np.ndarray  # F_e, N
    friction: np.ndarray  # F_mu, N
    torque: np.ndarray  # friction torque about the burr centre, N m
    normal: np.ndarray  # unit normal (zeros if undefined)
    depth: float  # h, m
    m0: float  # counter * m^3 (mass = m0 * rho_full / 255)
    m1: np.ndarray  # counter * m^4, about the burr centre
    power: float  # frictional power, W
    removed: float  # mass removed this step, kg (actual counter decrements)
    expected: float  # mass the continuous erosion law asks for this step, kg
    contact_area: float  # sum of the contact voxels' surface shares, m^2
    slip_speed: float  # load-weighted mean sliding speed, m/s


@dataclass(frozen=True)
class DrillTrack(ContactTrack):
    """A ContactTrack plus the drill's removal rate (mm^3/s of full-density bone) and rotation
    speed (rev/min) per sample, for :func:`jassy.events.track_events`."""

    removal_rate: np.ndarray = field(default_factory=lambda: np.zeros(0))
    rotation_speed: np.ndarray = field(default_factory=lambda: np.zeros(0))


class BurrSim:
    """A spherical burr against an eroding voxel volume (the volume's array is modified).

    The params (frozen) and the volume's voxel size, origin (copied) and mass per counter
    unit are read once, here: changing the Volume's fields afterwards does not move or
    rescale the burr's grid; build a new BurrSim for that."""

    def __init__(self, volume: Volume, params: BurrParams | None = None, seed: int = 0):
        self.volume = volume
        self.params = p = params or BurrParams()
        p.check()
        self.octree = Octree(volume.density) if p.method == "octree" else None
        self._mom = np.zeros(4)
        side = 2 * int(math.ceil(p.radius / volume.voxel + 1.0)) + 3
        cap = side**3
        rng = np.array([seed], dtype=np.uint64)
        bricks = self.octree.bricks() if self.octree is not None else NO_BRICKS
        self._mass_per_count = volume.mass_per_count
        data = ContactData(
            volume.density, rng, np.zeros(cap, CONTACT_VOXEL), np.zeros(1, CONTACT_TALLY), bricks
        )
        self.removed_total = 0.0
        self.work_total = 0.0
        v = volume
        leaf = int(p.leaf) if self.octree is not None else 0
        burr = Burr(float(p.radius), p.radius / v.voxel, float(p.c_e), float(p.rho0), float(v.voxel),
                    v.voxel**3, v.voxel**4, v.origin.copy(), leaf)  # fmt: skip
        model = BurrModel(p.radius / v.voxel, float(v.voxel), float(p.mu), self.kmass)
        if self.octree is not None:
            moments = (tuple(self.octree.pyramid), self.octree.stack, np.zeros(4))
        else:  # an empty pyramid of the right types; brute force reads the density
            empty = Pyramid(v.density, 0, 0, np.zeros(4), np.zeros(2, np.int64), np.zeros((1, 3), np.int64))
            moments = (tuple(empty), np.zeros((8, BLOCK_COLUMNS), np.int64), np.zeros(4))
        self._result = np.zeros(1, STEP_RESULT)
        self._fixed = (tuple(burr), tuple(model), moments)
        self._burr = burr
        self._data_fields = (*data[:4], tuple(bricks))  # a plain tuple, as haptic_update takes it
        self._update = None  # haptic_update's typed entry point, found at the first step

    @property
    def kmass(self) -> float:
        """Counter units removed per joule."""
        return self.params.erosion / self._mass_per_count

    def moments(self, centre) -> tuple[float, np.ndarray]:
        """(m0 in counter m^3, m1 about the centre in counter m^4) at world ``centre``."""
        b = self._burr
        g = (np.asarray(centre, dtype=np.float64) - b.origin) / b.voxel
        if self.octree is not None:
            mom, _ = self.octree.moments(g, b.radius_grid, self.params.leaf)
        else:
            brute_moments(self.volume.density, g[0], g[1], g[2], b.radius_grid, self._mom)
            mom = self._mom
        return float(mom[0]) * b.voxel3, mom[1:4] * b.voxel4

    def step(self, centre, omega=(0.0, 0.0, 0.0), velocity=(0.0, 0.0, 0.0), dt: float = 1e-3, erode=True):
        """One haptic update at burr centre ``centre`` (m), spin ``omega`` (rad/s vector),
        tool velocity (m/s); erodes for ``dt`` seconds if ``erode``. Returns a ContactState."""
        pose = (_vector(centre, "centre"), _vector(omega, "omega"), _vector(velocity, "velocity"), float(dt),
                bool(erode))  # fmt: skip
        burr, model, moments = self._fixed
        args = (burr, model, moments, pose, self._data_fields, self._result)
        if self._update is None:  # the same types at every step: one typed entry point
            self._update = specialise(haptic_update, *args)
        self._update(*args)
        r = self._result.copy()  # the state's arrays are views of this copy
        power, load, mu = float(r["power"][0]), float(r["load"][0]), self.params.mu
        removed = float(r["removed"][0]) * self._mass_per_count
        self.removed_total += removed
        self.work_total += power * dt if erode else 0.0
        return ContactState(
            force=r["force"][0],
            elastic=r["elastic"][0],
            friction=r["friction"][0],
            torque=r["torque"][0],
            normal=r["normal"][0],
            depth=float(r["depth"][0]),
            m0=float(r["m0"][0]),
            m1=r["m1"][0],
            power=power,
            removed=removed,
            expected=float(r["expected"][0]) * self._mass_per_count,
            contact_area=float(r["area"][0]),
            slip_speed=power / (mu * load) if mu > 0 and load > 0 else 0.0,
        )


def _vector(x, name: str) -> np.ndarray:
    """``x`` as a writeable C-contiguous float64 array of shape (3,) (the update's types)."""
    if type(x) is np.ndarray and x.dtype is _FLOAT64 and x.shape == (3,) and x.flags.c_contiguous \
            and x.flags.writeable:  # fmt: skip
        return x
    v = np.array(x, dtype=np.float64)
    if v.shape != (3,):
        raise JassyError(f"BurrSim.step: {name}: expected 3 numbers, got shape {v.shape}")
    return v


Controller = Callable[[float, "ContactState | None"], tuple]


@dataclass
class LoopResult:
    """Output of a haptic loop run: frames for the device, a DrillTrack for sound, and
    per-step arrays (time s, centre m, force N, depth m, removed mass kg cumulative)."""

    frames: list[HapticFrame]
    track: DrillTrack
    times: np.ndarray
    centres: np.ndarray
    forces: np.ndarray
    depths: np.ndarray
    removed: np.ndarray
    step_seconds: np.ndarray


def run_loop(sim: BurrSim, controller: Controller, duration: float, rate: float = 1000.0) -> LoopResult:
    """Run the haptic loop at ``rate`` Hz for ``duration`` s.

    ``controller(t, last_state)`` returns (centre m, omega rad/s vector, velocity m/s); each
    tick steps the simulation and records a HapticFrame (force, torque) and the track
    (normal force |F_e|, slip speed, removal rate, rotation speed). ``step_seconds`` holds
    the wall time of each update.
    """
    import time

    if not (rate > 0 and duration > 0):
        raise JassyError("run_loop: rate and duration must be > 0")
    dt = 1.0 / rate
    steps = max(2, int(round(duration * rate)))
    times = np.arange(steps) * dt
    centres = np.zeros((steps, 3))
    forces = np.zeros((steps, 3))
    normal_force = np.zeros(steps)
    slip = np.zeros(steps)
    depths = np.zeros(steps)
    removal = np.zeros(steps)
    rpm = np.zeros(steps)
    removed = np.zeros(steps)
    wall = np.zeros(steps)
    frames = []
    state = None
    total = 0.0
    mm3 = 1e9 / sim.volume.rho_full  # kg -> mm^3 of full-density bone
    for i, t in enumerate(times):
        centre, omega, velocity = controller(float(t), state)
        t0 = time.perf_counter()
        state = sim.step(centre, omega, velocity, dt)
        wall[i] = time.perf_counter() - t0
        total += state.removed
        centres[i] = centre
        forces[i] = state.force
        normal_force[i] = float(np.linalg.norm(state.elastic))
        slip[i] = state.slip_speed
        depths[i] = state.depth
        removal[i] = state.removed * mm3 / dt
        rpm[i] = float(np.linalg.norm(omega)) * 60.0 / (2.0 * math.pi)
        removed[i] = total
        frames.append(HapticFrame(float(t), state.force.copy(), state.torque.copy()))
    track = DrillTrack(
        (0, 1), times, normal_force, slip, np.zeros(steps), [], removal_rate=removal, rotation_speed=rpm
    )
    return LoopResult(frames, track, times, centres, forces, depths, removed, wall)


def smooth_rate(x: np.ndarray, width: int) -> np.ndarray:
    """Moving average over ``width`` samples (the roulette makes per-step removal spiky)."""
    if width <= 1:
        return x.copy()
    k = np.ones(width) / width
    return np.convolve(x, k, mode="same")


class Descent:
    """The reference experiment of Agus et al.: vertical descent at constant force.

    A force-controlled arm (admittance): the commanded vertical velocity is
    v = (F_z - F_push) / b, clipped to +-v_max, where F_z is the vertical contact force on
    the burr; F_push pushes down. The burr spins at ``rpm`` about ``axis`` (unit vector;
    default tilted 45 degrees from vertical, as a burr is held in use: about the vertical
    axis the tip of a ball burr does not slide). Lateral position is held.
    """

    def __init__(self, start, push: float = 2.0, rpm: float = 30000.0, axis=(1.0, 0.0, 1.0),
                 damping: float = 200.0, v_max: float = 0.02, rpm_profile=None):  # fmt: skip
        self.pos = np.asarray(start, dtype=np.float64).copy()
        self.push = float(push)
        self.axis = np.asarray(axis, dtype=np.float64) / np.linalg.norm(axis)
        self.rpm = float(rpm)
        self.damping = float(damping)
        self.v_max = float(v_max)
        self.rpm_profile = rpm_profile
        self.vz = 0.0
        self._t = None

    def __call__(self, t: float, state: ContactState | None):
        if self._t is not None:
            fz = 0.0 if state is None else float(state.force[2])
            self.vz = float(np.clip((fz - self.push) / self.damping, -self.v_max, self.v_max))
            self.pos[2] += self.vz * (t - self._t)
        self._t = t
        rpm = self.rpm if self.rpm_profile is None else float(self.rpm_profile(t))
        omega = self.axis * rpm * 2.0 * math.pi / 60.0
        return self.pos.copy(), omega, np.array([0.0, 0.0, self.vz])


def descent_experiment(volume, duration: float = 6.0, push: float = 2.0, rpm: float = 30000.0,
                       rate: float = 1000.0, seed: int = 0, start_gap: float = 2e-4,
                       params: BurrParams | None = None):  # fmt: skip
    """The constant-force descent into ``volume`` at its centre column, starting
    ``start_gap`` m above the highest occupied voxel there. Returns (LoopResult, surface
    height m, BurrSim)."""
    d = volume.density
    nx, ny, nz = d.shape
    occupied = np.nonzero(d[nx // 2, ny // 2, :])[0]
    top = int(occupied.max()) if occupied.size else 0
    surface = volume.origin[2] + (top + 0.5) * volume.voxel
    sim = BurrSim(volume, params or BurrParams(), seed=seed)
    centre = volume.to_world([(nx - 1) / 2, (ny - 1) / 2, 0.0])
    centre[2] = surface + sim.params.radius + start_gap
    return run_loop(sim, Descent(centre, push=push, rpm=rpm), duration, rate), surface, sim
