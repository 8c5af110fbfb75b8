"""Tearable mass-spring membrane over a triangle mesh (the capsulorhexis model of Agus et al.,
VRIPHYS 2006).

Particles are free, anchored (fixed) or scripted (positions set by a function of time: the
forceps). Forces: gravity, environment viscosity (drag -m gamma v), and springs along the
mesh edges (Hooke k (L - L0) plus dashpot c (dv . u)), optionally bending springs between the
two vertices opposite each interior edge. A structural spring whose strain (L - L0)/L0
exceeds its ``tear_strain`` is removed (with the bending spring across it); the triangles
that used it are no longer rendered. Particles are never created or destroyed, so particle
count and total mass are conserved (vertices are not split: a tear opens once every spring
crossing the tear line is gone).

Integrator: semi-implicit (symplectic) Euler with substeps, v += h_s f/m, v /= 1 + h_s gamma,
x += h_s v, in one numba kernel. The substep h_s <= min(1/omega_max, m/(2 sum c)) with
omega_max^2 <= max_i 2 sum_j k_ij / m_i (Gershgorin bound of M^-1 K; half the explicit
stability limit 2/omega). Chosen over implicit Euler because a step costs O(springs) with no
linear solve, and tearing changes the stiffness matrix at any substep, which would force a
new factorisation; implicit Euler would also add numerical damping to the tearing dynamics.
Scripted positions are evaluated at the start and end of each step and linearly
interpolated over its substeps. Units: SI.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import NamedTuple

import numba
import numpy as np

from jassy.errors import JassyError

FREE, ANCHORED, SCRIPTED = 0, 1, 2


@dataclass(frozen=True)
class Tear:
    """A spring torn at ``time`` (s) at ``position`` (its midpoint, m) with ``strain``."""

    time: float
    spring: int
    position: tuple[float, float, float]
    strain: float


class MembraneModel(NamedTuple):
    """The static arrays the kernel reads: masses (n,) kg, kind (n,) FREE / ANCHORED /
    SCRIPTED, scripted (k,) particle indices, springs (S, 2) particle pairs, rest_length (S,)
    m, stiffness (S,) N/m, damping (S,) N s/m, tear_strain (S,), partner (S,) spring removed
    with a torn one (-1 = none), gravity (3,) m/s^2, viscosity gamma (1/s)."""

    masses: np.ndarray
    kind: np.ndarray
    scripted: np.ndarray
    springs: np.ndarray
    rest_length: np.ndarray
    stiffness: np.ndarray
    damping: np.ndarray
    tear_strain: np.ndarray
    partner: np.ndarray
    gravity: np.ndarray
    viscosity: float


class StepOptions(NamedTuple):
    """One step: substep h_s (s), number of substeps, time at the step's start (s)."""

    substep: float
    substeps: int
    start_time: float


class TearLog(NamedTuple):
    """Springs torn during a step: spring index, time (s), midpoint (m) and strain of each,
    and count[0] of them (capacity: the number of springs)."""

    spring: np.ndarray
    time: np.ndarray
    position: np.ndarray
    strain: np.ndarray
    count: np.ndarray


class MembraneData(NamedTuple):
    """State x, v (n, 3) (m, m/s) and alive (S,) (updated in place); scripted positions
    (k, 3) m at the step's start and end; tears; forceps_force (3,) N,
    the force on the scripted particles averaged over the substeps."""

    x: np.ndarray
    v: np.ndarray
    alive: np.ndarray
    script_start: np.ndarray
    script_end: np.ndarray
    tears: TearLog
    forceps_force: np.ndarray


@numba.njit(cache=True, inline="always")
def _load_gravity(m, f):
    """Reset the forces f (n, 3) N to gravity m_i g."""
    mass, g = m.masses, m.gravity
    for i in range(f.shape[0]):
        for a in range(3):
            f[i, a] = mass[i] * g[a]


@numba.njit(cache=True, inline="always")
def _record_tear(d, e, t, i, j, strain):
    """Log spring e (particles i, j) torn at time t with ``strain``."""
    log = d.tears
    q = log.count[0]
    log.spring[q] = e
    log.time[q] = t
    for a in range(3):
        log.position[q, a] = 0.5 * (d.x[i, a] + d.x[j, a])
    log.strain[q] = strain
    log.count[0] = q + 1


@numba.njit(cache=True, inline="always")
def _spring_forces(m, opt, d, f, s):
    """Add each live spring's Hooke and dashpot force to f; tear (and log) the springs
    strained beyond tear_strain, with their partners, in substep s."""
    x, v, alive = d.x, d.v, d.alive
    springs, L0, k, c, tear, partner = (
        m.springs,
        m.rest_length,
        m.stiffness,
        m.damping,
        m.tear_strain,
        m.partner,
    )
    for e in range(springs.shape[0]):
        if not alive[e]:
            continue
        i, j = springs[e, 0], springs[e, 1]
        d0, d1, d2 = x[j, 0] - x[i, 0], x[j, 1] - x[i, 1], x[j, 2] - x[i, 2]
        L = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        strain = (L - L0[e]) / L0[e]
        if strain > tear[e]:
            alive[e] = False
            if partner[e] >= 0:
                alive[partner[e]] = False
            _record_tear(d, e, opt.start_time + s * opt.substep, i, j, strain)
            continue
        if L == 0.0:
            continue
        u0, u1, u2 = d0 / L, d1 / L, d2 / L
        rv = (v[j, 0] - v[i, 0]) * u0 + (v[j, 1] - v[i, 1]) * u1 + (v[j, 2] - v[i, 2]) * u2
        fs = k[e] * (L - L0[e]) + c[e] * rv
        f[i, 0] += fs * u0
        f[i, 1] += fs * u1
        f[i, 2] += fs * u2
        f[j, 0] -= fs * u0
        f[j, 1] -= fs * u1
        f[j, 2] -= fs * u2


@numba.njit(cache=True, inline="always")
def _forceps_force(m, opt, d, f):
    """Add this substep's share of the non-gravity force on the scripted particles."""
    for q in range(m.scripted.size):
        i = m.scripted[q]
        for a in range(3):
            d.forceps_force[a] += (f[i, a] - m.masses[i] * m.gravity[a]) / opt.substeps


@numba.njit(cache=True, inline="always")
def _integrate(m, opt, d, f, damp):
    """Semi-implicit Euler for the free particles (velocity scaled by ``damp`` for the
    viscosity); anchored particles are held at rest."""
    hs, x, v, kind, mass = opt.substep, d.x, d.v, m.kind, m.masses
    for i in range(x.shape[0]):
        if kind[i] == FREE:
            for a in range(3):
                v[i, a] = (v[i, a] + hs * f[i, a] / mass[i]) * damp
                x[i, a] += hs * v[i, a]
        elif kind[i] == ANCHORED:
            for a in range(3):
                v[i, a] = 0.0


@numba.njit(cache=True, inline="always")
def _move_scripted(m, opt, d, w):
    """Place the scripted particles at fraction w of the way from their start to end
    positions, moving at the step's mean velocity."""
    s0, s1 = d.script_start, d.script_end
    for q in range(m.scripted.size):
        i = m.scripted[q]
        for a in range(3):
            d.x[i, a] = (1.0 - w) * s0[q, a] + w * s1[q, a]
            d.v[i, a] = (s1[q, a] - s0[q, a]) / (opt.substep * opt.substeps)


@numba.njit(cache=True)
def _substeps(m, opt, d):
    """One step of ``opt.substeps`` substeps: the list of stages."""
    f = np.empty((d.x.shape[0], 3))
    damp = 1.0 / (1.0 + opt.substep * m.viscosity)
    d.forceps_force[:] = 0.0
    for s in range(opt.substeps):
        _load_gravity(m, f)
        _spring_forces(m, opt, d, f, s)
        _forceps_force(m, opt, d, f)
        _integrate(m, opt, d, f, damp)
        _move_scripted(m, opt, d, (s + 1.0) / opt.substeps)


def _edges(triangles):
    """Unique edges (E, 2) of the triangles and each triangle's edge indices (F, 3)."""
    tri = np.asarray(triangles, dtype=np.int64)
    e = np.sort(tri[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    edges, inv = np.unique(e, axis=0, return_inverse=True)
    return edges, inv.reshape(-1, 3)


@dataclass
class MembraneState:
    """Positions x and velocities v (n, 3) (m, m/s), live springs (S,) bool, time (s) and the
    force (N) the membrane exerted on the scripted particles (the forceps) over the last step,
    averaged over its substeps."""

    x: np.ndarray
    v: np.ndarray
    alive: np.ndarray
    time: float = 0.0
    forceps_force: np.ndarray = field(default_factory=lambda: np.zeros(3))


@dataclass(frozen=True)
class Membrane:
    """Mass-spring membrane (model; immutable). rest (n, 3) m; masses (n,) kg; springs (S, 2)
    particle pairs with stiffness (S,) N/m, damping (S,) N s/m and tear_strain (S,) (inf =
    never; rest lengths are taken from ``rest``); kind (n,) FREE / ANCHORED / SCRIPTED;
    triangles (F, 3) (for rendering; may be empty); tri_springs (F, 3) the spring of each
    triangle edge; partner (S,) the bending spring removed with a torn edge (-1 = none);
    gravity (3,) m/s^2; viscosity gamma (1/s). Use :func:`membrane_from_mesh` for meshes."""

    rest: np.ndarray
    masses: np.ndarray
    springs: np.ndarray
    stiffness: np.ndarray
    damping: np.ndarray
    tear_strain: np.ndarray
    kind: np.ndarray
    triangles: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), np.int64))
    tri_springs: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), np.int64))
    partner: np.ndarray | None = None
    gravity: tuple[float, float, float] = (0.0, 0.0, -9.81)
    viscosity: float = 0.0
    rest_length: np.ndarray = field(init=False, repr=False)
    max_substep: float = field(init=False)
    model: MembraneModel = field(init=False, repr=False)

    def __post_init__(self):
        rest = np.asarray(self.rest, dtype=np.float64)
        n = rest.shape[0]
        if rest.ndim != 2 or rest.shape[1] != 3 or n == 0 or not np.all(np.isfinite(rest)):
            raise JassyError(f"Membrane.rest: expected a finite (n, 3) array, got shape {rest.shape}")
        m = np.asarray(self.masses, dtype=np.float64)
        if m.shape != (n,) or not np.all(np.isfinite(m)) or np.any(m <= 0):
            raise JassyError(f"Membrane.masses: expected {n} masses > 0 (kg)")
        sp = np.asarray(self.springs, dtype=np.int64).reshape(-1, 2)
        if sp.size == 0 or sp.min() < 0 or sp.max() >= n or np.any(sp[:, 0] == sp[:, 1]):
            raise JassyError(f"Membrane.springs: expected pairs of distinct particle indices in 0..{n - 1}")
        s = sp.shape[0]
        L0 = np.linalg.norm(rest[sp[:, 1]] - rest[sp[:, 0]], axis=1)
        if np.any(L0 <= 0):
            raise JassyError("Membrane.springs: expected springs of nonzero rest length")
        arrays = {}
        for name, lo in (("stiffness", 0.0), ("damping", 0.0), ("tear_strain", 0.0)):
            a = np.broadcast_to(np.asarray(getattr(self, name), dtype=np.float64), (s,)).copy()
            if (
                np.any(np.isnan(a))
                or np.any(a < lo)
                or (name != "tear_strain" and not np.all(np.isfinite(a)))
            ):
                raise JassyError(f"Membrane.{name}: expected {s} values >= {lo}")
            arrays[name] = a
        kind = np.asarray(self.kind, dtype=np.int64)
        if kind.shape != (n,) or np.any((kind < 0) | (kind > 2)):
            raise JassyError(f"Membrane.kind: expected {n} values in FREE=0, ANCHORED=1, SCRIPTED=2")
        partner = np.full(s, -1, np.int64) if self.partner is None else np.asarray(self.partner, np.int64)
        if partner.shape != (s,) or partner.max(initial=-1) >= s:
            raise JassyError(f"Membrane.partner: expected {s} spring indices or -1")
        g = np.asarray(self.gravity, dtype=np.float64)
        if g.shape != (3,) or not np.all(np.isfinite(g)):
            raise JassyError("Membrane.gravity: expected 3 finite components (m/s^2)")
        if not (math.isfinite(self.viscosity) and self.viscosity >= 0):
            raise JassyError(f"Membrane.viscosity: expected a number >= 0 (1/s), got {self.viscosity!r}")
        ksum = np.bincount(sp.ravel(), weights=np.repeat(arrays["stiffness"], 2), minlength=n)
        csum = np.bincount(sp.ravel(), weights=np.repeat(arrays["damping"], 2), minlength=n)
        omega = math.sqrt(float(np.max(2 * ksum / m)))
        hmax = min(1.0 / omega if omega > 0 else np.inf, float(np.min(m / np.maximum(2 * csum, 1e-300))))
        for name, val in [
            ("rest", rest),
            ("masses", m),
            ("springs", sp),
            ("kind", kind),
            ("partner", partner),
            ("rest_length", L0),
            ("max_substep", hmax),
            ("gravity", g),
            *arrays.items(),
            ("triangles", np.asarray(self.triangles, np.int64).reshape(-1, 3)),
            ("tri_springs", np.asarray(self.tri_springs, np.int64).reshape(-1, 3)),
        ]:
            object.__setattr__(self, name, val)
        model = MembraneModel(
            m, kind, np.flatnonzero(kind == SCRIPTED), sp, L0, arrays["stiffness"], arrays["damping"],
            arrays["tear_strain"], partner, g, float(self.viscosity),
        )  # fmt: skip
        object.__setattr__(self, "model", model)

    @property
    def scripted(self) -> np.ndarray:
        """Indices of the scripted particles (the order a script returns positions in)."""
        return np.flatnonzero(self.kind == SCRIPTED)

    def initial_state(self) -> MembraneState:
        n = self.rest.shape[0]
        return MembraneState(self.rest.copy(), np.zeros((n, 3)), np.ones(self.springs.shape[0], dtype=bool))

    def strain(self, state: MembraneState) -> np.ndarray:
        """(L - L0)/L0 of every spring (torn ones included) in ``state``."""
        sp = self.springs
        return np.linalg.norm(state.x[sp[:, 1]] - state.x[sp[:, 0]], axis=1) / self.rest_length - 1.0

    def live_triangles(self, state: MembraneState) -> np.ndarray:
        """Triangles (rows of ``triangles``) whose three edge springs are all intact."""
        return self.triangles[state.alive[self.tri_springs].all(1)] if self.triangles.size else self.triangles

    def step(
        self, state: MembraneState, h: float, script: Callable[[float], np.ndarray] | None = None
    ) -> list[Tear]:
        """Advance ``state`` by h seconds in ceil(h / max_substep) substeps. ``script(t)`` gives
        the scripted particles' positions (k, 3) m at time t (required if there are any).
        Returns the springs torn during the step."""
        if not (math.isfinite(h) and h > 0):
            raise JassyError(f"h: expected a time step > 0 (s), got {h!r}")
        sidx = self.scripted
        s0 = s1 = np.zeros((0, 3))
        if sidx.size:
            if script is None:
                raise JassyError(
                    "script: expected a function t -> (k, 3) positions for the scripted particles"
                )
            s0 = np.asarray(script(state.time), dtype=np.float64)
            s1 = np.asarray(script(state.time + h), dtype=np.float64)
            for arr in (s0, s1):
                if arr.shape != (sidx.size, 3) or not np.all(np.isfinite(arr)):
                    raise JassyError(f"script: expected finite positions of shape ({sidx.size}, 3)")
        nsub = max(1, math.ceil(h / self.max_substep))
        cap = self.springs.shape[0]
        tears = TearLog(
            np.empty(cap, np.int64), np.empty(cap), np.empty((cap, 3)), np.empty(cap), np.zeros(1, np.int64)
        )
        data = MembraneData(state.x, state.v, state.alive, s0, s1, tears, np.zeros(3))
        _substeps(self.model, StepOptions(h / nsub, nsub, float(state.time)), data)
        state.time += h
        state.forceps_force = data.forceps_force
        if not (np.all(np.isfinite(state.x)) and np.all(np.isfinite(state.v))):
            raise JassyError("h: the membrane went unstable (non-finite state)")
        return [
            Tear(
                float(tears.time[q]),
                int(tears.spring[q]),
                tuple(map(float, tears.position[q])),
                float(tears.strain[q]),
            )  # fmt: skip
            for q in range(int(tears.count[0]))
        ]


def membrane_from_mesh(
    points,
    triangles,
    *,
    thickness: float = 20e-6,
    density: float = 1000.0,
    stiffness: float = 10.0,
    damping: float = 0.0,
    tear_strain: float = np.inf,
    bending: float = 0.0,
    anchored=(),
    scripted=(),
    gravity=(0.0, 0.0, -9.81),
    viscosity: float = 0.0,
) -> Membrane:
    """Membrane over a triangle mesh: a spring per edge (stiffness N/m, damping N s/m,
    tear_strain), masses lumped from triangle areas (thickness m, density kg/m^3, a third of
    each triangle per vertex), and if ``bending`` > 0 (N/m) a spring between the two
    vertices opposite each interior edge (never torn by strain; removed with its edge).
    ``anchored``, ``scripted``: particle indices."""
    pts = np.asarray(points, dtype=np.float64)
    tri = np.asarray(triangles, dtype=np.int64)
    if tri.ndim != 2 or tri.shape[1] != 3 or tri.shape[0] == 0 or tri.min() < 0 or tri.max() >= len(pts):
        raise JassyError(f"triangles: expected a (F, 3) array of indices into {len(pts)} points")
    if not (thickness > 0 and density > 0):
        raise JassyError("thickness, density: expected numbers > 0 (m, kg/m^3)")
    edges, tri_edges = _edges(tri)
    area = 0.5 * np.linalg.norm(
        np.cross(pts[tri[:, 1]] - pts[tri[:, 0]], pts[tri[:, 2]] - pts[tri[:, 0]]), axis=1
    )
    masses = np.bincount(
        tri.ravel(), weights=np.repeat(area * thickness * density / 3, 3), minlength=len(pts)
    )
    if np.any(masses <= 0):
        raise JassyError("points: every point must belong to a triangle of nonzero area")
    ne = edges.shape[0]
    springs, k, tear = [edges], [np.full(ne, float(stiffness))], [np.full(ne, float(tear_strain))]
    partner = np.full(ne, -1, np.int64)
    if bending > 0:
        flat = tri_edges.ravel()
        order = np.argsort(flat, kind="stable")
        fs = flat[order]
        pair = np.flatnonzero(fs[1:] == fs[:-1])
        ta, tb = order[pair] // 3, order[pair + 1] // 3
        e = fs[pair]
        esum = edges[e].sum(1)
        opp = [tri[tt].sum(1) - esum for tt in (ta, tb)]
        partner[e] = ne + np.arange(e.size)
        springs.append(np.stack(opp, 1))
        k.append(np.full(e.size, float(bending)))
        tear.append(np.full(e.size, np.inf))
        partner = np.concatenate([partner, np.full(e.size, -1, np.int64)])
    springs = np.concatenate(springs)
    kind = np.zeros(len(pts), np.int64)
    kind[np.asarray(anchored, dtype=np.int64)] = ANCHORED
    kind[np.asarray(scripted, dtype=np.int64)] = SCRIPTED
    return Membrane(
        pts,
        masses,
        springs,
        np.concatenate(k),
        np.full(springs.shape[0], float(damping)),
        np.concatenate(tear),
        kind,
        tri,
        tri_edges,
        partner,
        tuple(gravity),
        viscosity,
    )


def grid_mesh(nx: int, ny: int, width: float, height: float):
    """A flat nx x ny grid of points in the x-y plane (width x height m, corner at the origin)
    split into 2 (nx-1)(ny-1) triangles. Returns (points (nx ny, 3), triangles)."""
    if nx < 2 or ny < 2:
        raise JassyError(f"nx, ny: expected >= 2, got {nx}, {ny}")
    xs, ys = np.meshgrid(np.linspace(0, width, nx), np.linspace(0, height, ny), indexing="ij")
    pts = np.stack([xs.ravel(), ys.ravel(), np.zeros(nx * ny)], 1)
    i, j = np.meshgrid(np.arange(nx - 1), np.arange(ny - 1), indexing="ij")
    a = (i * ny + j).ravel()
    b, c, d = a + ny, a + 1, a + ny + 1
    return pts, np.concatenate([np.stack([a, b, d], 1), np.stack([a, d, c], 1)])


def disc_mesh(radius: float, rings: int):
    """A flat disc (radius m, in the x-y plane) of concentric rings (ring r has 6 r points)
    triangulated with scipy.spatial.Delaunay. Returns (points, triangles); the last 6*rings
    points are the rim."""
    from scipy.spatial import Delaunay

    if not (radius > 0 and rings >= 1):
        raise JassyError("radius, rings: expected radius > 0 (m) and rings >= 1")
    pts = [np.zeros((1, 2))]
    for r in range(1, rings + 1):
        ang = np.arange(6 * r) * 2 * np.pi / (6 * r)
        pts.append(radius * r / rings * np.stack([np.cos(ang), np.sin(ang)], 1))
    p2 = np.concatenate(pts)
    tri = Delaunay(p2).simplices
    return np.column_stack([p2, np.zeros(len(p2))]), tri
