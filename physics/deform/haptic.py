"""The 1 kHz haptic loop: a spherical probe poking and sliding on a linear elastic body.

One :meth:`PokeSim.step` at probe centre c (m), probe radius r:

1. contact set: the free vertices whose rest position lies inside the probe sphere (the
   body's deformation is linear, so contact is decided on the rest shape);
2. constraint displacements: each contact vertex is moved radially onto the probe
   surface, u_bar = c + r (x - c)/|x - c| - x (bilateral, sticking contact);
3. the capacitance solver (physics.deform.capacitance) returns the constraint forces F_m
   on the body (optionally spread by vertex masks); it refactors only when the contact set
   changes;
4. unilateral contact: while some constraints pull the probe (F_m . n_m > 0, n_m the
   outward vertex normal), they are all released and the rest re-solved (released vertices
   are not re-checked for penetration: a one-way active set); the released set is kept
   while the set of vertices inside the probe does not change;
5. force on the probe = -sum_m F_m (N).

``run_poke`` runs it at ``rate`` Hz along a scripted path and returns HapticFrames and a
ContactTrack (normal force = |force|, slip speed = probe speed perpendicular to the force,
rolling speed 0, location = the contact vertex nearest the probe centre or -1).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import numba as nb
import numpy as np

from jassy.errors import JassyError
from jassy.events import ContactTrack, HapticFrame
from physics.deform.capacitance import CapacitanceSolver
from physics.deform.greens import GreensFunctions


def soft_ball(radius: float = 0.05, subdivisions: int = 3, base: float = 0.8):
    """(vertices m, faces, fixed mask) of an icosphere of ``radius`` centred at the origin
    resting on a rigid base: vertices below z = -base * radius are fixed."""
    import trimesh

    if not (math.isfinite(radius) and radius > 0):
        raise JassyError(f"radius: expected a length > 0 m, got {radius!r}")
    if not (0.0 < base < 1.0):
        raise JassyError(f"base: expected a fraction in (0, 1), got {base!r}")
    mesh = trimesh.creation.icosphere(int(subdivisions), radius=radius)
    V = np.asarray(mesh.vertices, dtype=np.float64)
    return V, np.asarray(mesh.faces, dtype=np.int64), V[:, 2] < -base * radius


@nb.njit(cache=True)
def probe_contacts(X, ids, centre, radius, idx, disp):
    """Vertices ids[i] with rest position X[i] inside the probe (centre, radius): writes up
    to len(idx) of them to idx and their radial projections onto the probe surface minus
    the rest positions to disp; returns how many there are (may exceed len(idx))."""
    count = 0
    r2 = radius * radius
    for i in range(X.shape[0]):
        d0 = X[i, 0] - centre[0]
        d1 = X[i, 1] - centre[1]
        d2 = X[i, 2] - centre[2]
        dd = d0 * d0 + d1 * d1 + d2 * d2
        if dd < r2:
            if count < idx.shape[0]:
                scale = radius / math.sqrt(dd) - 1.0 if dd > 0.0 else 0.0
                idx[count] = ids[i]
                disp[count, 0] = d0 * scale
                disp[count, 1] = d1 * scale
                disp[count, 2] = d2 * scale
            count += 1
    return count


@dataclass
class PokeState:
    """One haptic step: force (3,) on the probe (N), contact vertices (s,), constraint
    forces (s, 3) on the body (N), and whether the capacitance matrix was refactored."""

    force: np.ndarray
    contacts: np.ndarray
    contact_forces: np.ndarray
    refactored: bool


class PokeSim:
    """A probe sphere of ``probe_radius`` (m) against the body of ``greens``, with vertex
    masks of radius ``mask_radius`` (m; 0 = single vertices, the default: the probe's own
    area spreads the contact; masks wider than half the vertex spacing overlap between
    neighbouring contact vertices and make their constraints nearly dependent)."""

    def __init__(self, greens: GreensFunctions, probe_radius: float = 0.01, mask_radius: float = 0.0,
                 max_contacts: int = 64):  # fmt: skip
        if not (math.isfinite(probe_radius) and probe_radius > 0):
            raise JassyError(f"probe_radius: expected a length > 0 m, got {probe_radius!r}")
        self.greens = greens
        self.probe_radius = float(probe_radius)
        self.solver = CapacitanceSolver(greens, mask_radius, max_contacts)
        self._X = np.ascontiguousarray(greens.vertices[greens.free])
        self._ids = greens.free.astype(np.int64)
        self._idx = np.zeros(self.solver.max_contacts, dtype=np.int64)
        self._disp = np.zeros((self.solver.max_contacts, 3))
        self._centre = np.zeros(3)
        self._candidates = np.zeros(0, dtype=np.int64)
        self._keep = np.zeros(0, dtype=bool)
        V, F = greens.vertices, greens.faces
        cross = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
        normals = np.zeros_like(V)
        for k in range(3):
            np.add.at(normals, F[:, k], cross)
        self.normals = normals / np.linalg.norm(normals, axis=1)[:, None]

    def step(self, centre) -> PokeState:
        """One haptic update at probe centre ``centre`` (m)."""
        c = self._centre
        c[0], c[1], c[2] = centre
        if not (math.isfinite(c[0]) and math.isfinite(c[1]) and math.isfinite(c[2])):
            raise JassyError(f"centre: expected a finite position in m, got {centre!r}")
        s = probe_contacts(self._X, self._ids, c, self.probe_radius, self._idx, self._disp)
        if s > self.solver.max_contacts:
            raise JassyError(f"centre: {s} vertices inside the probe, more than max_contacts="
                             f"{self.solver.max_contacts} (probe too deep or too large)")  # fmt: skip
        cand = self._idx[:s]
        if s != self._candidates.size or (s and not np.array_equal(cand, self._candidates)):
            self._candidates, self._keep = cand.copy(), np.ones(s, dtype=bool)
        if s == 0:
            return PokeState(np.zeros(3), self._candidates, np.zeros((0, 3)), self.solver.set_contacts(cand))
        keep, changed = self._keep, False
        while True:
            active = self._candidates[keep]
            changed |= self.solver.set_contacts(active)
            if not active.size:
                forces = np.zeros((0, 3))
                break
            forces = self.solver.solve(self._disp[:s][keep])
            pull = np.einsum("ij,ij->i", forces, self.normals[active])
            if pull.max() <= 0.0:
                break
            keep[np.flatnonzero(keep)[pull > 0.0]] = False
        total = -forces.sum(axis=0)
        if not (math.isfinite(total[0]) and math.isfinite(total[1]) and math.isfinite(total[2])):
            raise JassyError("centre: the contact force is not finite")
        return PokeState(total, active, forces, changed)


@dataclass
class PokeResult:
    """A haptic run: frames, the ContactTrack, and per-step time (s), probe centre (m),
    force on the probe (N), contact count, refactor flag and wall time of each step (s)."""

    frames: list[HapticFrame]
    track: ContactTrack
    times: np.ndarray
    centres: np.ndarray
    forces: np.ndarray
    counts: np.ndarray
    refactored: np.ndarray
    step_seconds: np.ndarray


def run_poke(
    sim: PokeSim, path: Callable[[float], np.ndarray], duration: float, rate: float = 1000.0
) -> PokeResult:
    """Run the haptic loop at ``rate`` Hz for ``duration`` s with the probe at ``path(t)``."""
    if not (rate > 0 and duration > 0 and math.isfinite(rate) and math.isfinite(duration)):
        raise JassyError(f"run_poke: rate and duration must be finite and > 0, got {rate!r}, {duration!r}")
    steps = max(2, int(round(duration * rate)))
    times = np.arange(steps) / rate
    centres = np.array([np.asarray(path(float(t)), dtype=np.float64) for t in times])
    if centres.shape != (steps, 3):
        raise JassyError(f"path: expected path(t) to return a 3-vector, got shape {centres.shape[1:]}")
    forces = np.zeros((steps, 3))
    counts = np.zeros(steps, dtype=np.int64)
    refac = np.zeros(steps, dtype=bool)
    wall = np.zeros(steps)
    nearest = np.full(steps, -1, dtype=np.int64)
    V = sim.greens.vertices
    for i in range(steps):
        t0 = time.perf_counter()
        st = sim.step(centres[i])
        wall[i] = time.perf_counter() - t0
        forces[i], counts[i], refac[i] = st.force, st.contacts.size, st.refactored
        if st.contacts.size:
            nearest[i] = st.contacts[np.argmin(np.linalg.norm(V[st.contacts] - centres[i], axis=1))]
    velocity = np.gradient(centres, times, axis=0)
    magnitude = np.linalg.norm(forces, axis=1)
    unit = forces / np.maximum(magnitude, 1e-300)[:, None]
    tangential = velocity - np.sum(velocity * unit, axis=1)[:, None] * unit
    slip = np.where(counts > 0, np.linalg.norm(tangential, axis=1), 0.0)
    frames = [HapticFrame(float(t), f.copy()) for t, f in zip(times, forces, strict=True)]
    track = ContactTrack((0, 1), times, magnitude, slip, np.zeros(steps), [int(k) for k in nearest])
    return PokeResult(frames, track, times, centres, forces, counts, refac, wall)


@dataclass(frozen=True)
class PokePath:
    """Scripted probe path over a ball of ``radius`` (m) centred at ``centre``: keyframes
    (time s, indentation m (negative = gap), polar angle rad about the y axis from the top),
    joined by smoothstep; the probe (radius ``probe_radius``) stays on the ball's normal."""

    radius: float
    probe_radius: float
    keys: tuple[tuple[float, float, float], ...]
    centre: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self):
        k = np.asarray(self.keys, dtype=np.float64)
        if k.ndim != 2 or k.shape[0] < 2 or k.shape[1] != 3 or np.any(np.diff(k[:, 0]) <= 0):
            raise JassyError("keys: expected >= 2 rows (time s, depth m, angle rad) with increasing times")

    def __call__(self, t: float) -> np.ndarray:
        keys = self.keys
        j = 0
        while j < len(keys) - 2 and t >= keys[j + 1][0]:
            j += 1
        (t0, d0, a0), (t1, d1, a1) = keys[j], keys[j + 1]
        s = min(max((t - t0) / (t1 - t0), 0.0), 1.0)
        s = s * s * (3.0 - 2.0 * s)
        depth, angle = d0 + s * (d1 - d0), a0 + s * (a1 - a0)
        dist = self.radius + self.probe_radius - depth
        c = self.centre
        return np.array([c[0] + dist * math.sin(angle), c[1], c[2] + dist * math.cos(angle)])


def poke_path(radius: float, probe_radius: float, depth: float, gap: float = 0.004) -> PokePath:
    """The demo gesture (4 s): approach, a soft poke (press to ``depth`` m and release),
    then press again, slide 35 degrees each way over the top, and lift off."""
    a = math.radians(35.0)
    keys = ((0.0, -gap, 0.0), (0.3, -gap, 0.0), (0.8, depth, 0.0), (1.0, depth, 0.0), (1.3, -gap, 0.0),
            (1.5, -gap, -a), (1.9, depth, -a), (2.9, depth, a), (3.3, depth, 0.2 * a), (3.7, -gap, 0.0),
            (4.0, -gap, 0.0))  # fmt: skip
    return PokePath(float(radius), float(probe_radius), keys)
