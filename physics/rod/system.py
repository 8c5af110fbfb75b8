"""A planar multi-body system: rods (chained or mixed formulations), rigid bodies made of disks,
static disks and planes, pin joints and prescribed velocities, stepped with frictional contact.

One step (velocity level, linearly implicit Euler, impulses in N s):

    A v+ = b + C^T(-lam) + H^T r,   C v+ = c,   u = H v+ + g_stab,   (u, r) solve the DFCP (dfcp.py)

* A, b, C, c: each rod's ``linear_system`` (boundary conditions, gluing), rigid bodies M v + h f;
  joint rows J_a v - J_b v = -rate (p_a - p_b)/h and drive rows v_k = v_target are appended.
  K = [[A, C^T], [C, 0]] is kept in band storage (physics.rod.band): for mixed rods only (no
  rigid bodies, joints or drives) each rod's ``kkt_band`` one after the other, assembled per
  element; otherwise from the entries in a reverse Cuthill-McKee order computed once per set of
  driven bodies (SuperLU when that band is wider than 64).
* Schur reductions: W = H K^{-1}|_v H^T, w = H v_free + g_stab, then v+ = v_free + K^{-1}|_v H^T r.
  Default (``schur=True``): the partitioned Schur complement of physics.rod.delassus (O(N) for
  rods with contacts spread along them, iterative refinement of v+); if it is singular (e.g. a
  rigid body held by several joints) the direct path: K factorised once and 2c solves with
  [H^T; 0] (``schur=False`` always). H has rows n^T(J_a - J_b), t^T(J_a - J_b) (n from b to a,
  t = e_z x n), built per body with the formulations' vectorised ``point_jacobians``.
* Penetration at velocity level: g_stab = g/h on the normal row when the gap g >= 0 (contacts are
  kept from ``margin`` on, and only act if they would close within the step) and beta g/h when
  g < 0 (Baumgarte, beta = ``stabilisation``). Moreau-type: restitution 0.
* Contact velocities are those of the surface points: rigid points include the rotation
  (omega x (P - X)), so disks roll; a rod's surface point at radius r turns with its cross-section,
  the tangent angle phi = theta + kappa s of a mixed rod (u_T gets -r phi_dot; formulations without
  ``angle_jacobians``, the chained one, use the centre-line velocity). Rolling speed of a contact:
  |R_a omega_a + R_b omega_b|, the relative tangential velocity of the two surfaces' turning parts
  (R: disk or rod radius, omega: body or cross-section angular velocity, 0 for static obstacles);
  the speed at which a disk rolls along a rod or plane.
* Contact reduction: per body pair, a contact within half an element length of a closer one is
  dropped (adjacent elements meeting at a node give duplicate rows).
* Not handled: rod self-contact; crossing centre lines (geometry.py).

Body ids (used in events): rods 0..R-1, rigid bodies R..R+B-1, static obstacles after them.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from jassy.errors import JassyError
from jassy.events import ContactTrack, Impact
from physics.rod import geometry
from physics.rod.band import BandOrder
from physics.rod.delassus import BandKKT, DirectDelassus, SchurDelassus, SparseKKT
from physics.rod.dfcp import solve_dfcp
from physics.rod.mixed import BAND, MixedRod

#: Contact-row columns (geometry.ContactRow) of the closest points on a and on b and of the normal.
_PA = slice(geometry.PA_X, geometry.PA_Y + 1)
_PB = slice(geometry.PB_X, geometry.PB_Y + 1)
_N = slice(geometry.N_X, geometry.N_Y + 1)


@dataclass(frozen=True)
class RigidBody:
    """Mass (kg), rotational inertia (kg m^2), disks (ox, oy, R) in the body frame (m), gravity (m/s^2)."""

    mass: float
    inertia: float
    disks: tuple[tuple[float, float, float], ...] = ((0.0, 0.0, 0.0),)
    gravity: float = 9.81


@dataclass(frozen=True)
class Plane:
    """A static half-space: a point on its boundary and the unit normal out of the solid."""

    point: tuple[float, float]
    normal: tuple[float, float]


@dataclass(frozen=True)
class Disk:
    """A static disk (m)."""

    centre: tuple[float, float]
    radius: float


@dataclass(frozen=True)
class Anchor:
    """A point of body ``body`` (id): rods at (element, s), rigid bodies at ``offset`` (body frame)."""

    body: int
    element: int = 0
    s: float = 0.0
    offset: tuple[float, float] = (0.0, 0.0)


@dataclass(frozen=True)
class Joint:
    """Pin joint: anchor a coincides with anchor b, or with the fixed point ``world`` if b is None;
    ``rate`` is the fraction of the position mismatch removed per step (1: at once; < 1 to close
    an initial gap gradually)."""

    a: Anchor
    b: Anchor | None = None
    world: tuple[float, float] = (0.0, 0.0)
    rate: float = 1.0


@dataclass
class SystemState:
    """Rod states, rigid poses q (B, 3) = (x, y, phi) and velocities v (B, 3), time (s), and the
    previous step's contact impulses keyed by contact feature (warm start)."""

    rods: list
    q: np.ndarray
    v: np.ndarray
    time: float = 0.0
    cache: dict = field(default_factory=dict)


@dataclass(frozen=True)
class StepInfo:
    """One step: contact bodies (c, 2), points on a (c, 2), normals (c, 2), gaps (m), impulses r (c, 2)
    (N s), relative velocities u (c, 2) of the surface points after and free normal velocity before
    (m/s), bilateral impulses lam, solver sweeps and residual, times (s) of detection / assembly /
    Delassus / solve, and rolling speeds (c,) after the step (m/s, see the module docstring)."""

    time: float
    bodies: np.ndarray
    points: np.ndarray
    normals: np.ndarray
    gaps: np.ndarray
    r: np.ndarray
    u: np.ndarray
    u_free: np.ndarray
    lam: np.ndarray
    iterations: int
    residual: float
    timings: dict
    rolling: np.ndarray


class RodSystem:
    """Rods (formulations with ``linear_system``, ``point_jacobian``, ``arcs``, ``advance``), rigid
    bodies, static obstacles (Plane, Disk) and joints; ``mu`` friction coefficient (or ``mu_pairs``
    {(id_a, id_b): mu}); contacts kept below gap ``margin`` (m); ``ignore`` body-id pairs never
    collide (e.g. a string and the limbs it is pinned to); DFCP ``tol`` and ``max_iter``; ``schur``:
    Delassus operator by the partitioned Schur complement (else 2c full KKT solves)."""

    def __init__(
        self,
        rods=(),
        bodies=(),
        obstacles=(),
        joints=(),
        mu: float = 0.3,
        mu_pairs=None,
        margin: float = 1e-3,
        stabilisation: float = 0.2,
        tol: float = 1e-10,
        max_iter: int = 5000,
        ignore=(),
        schur: bool = True,
    ):
        self.rods, self.bodies = list(rods), list(bodies)
        self.obstacles, self.joints = list(obstacles), list(joints)
        if not (mu >= 0 and margin >= 0 and 0 <= stabilisation <= 1):
            raise JassyError(
                "mu, margin, stabilisation: expected mu >= 0, margin >= 0, 0 <= stabilisation <= 1"
            )
        for ob in self.obstacles:
            if not isinstance(ob, (Plane, Disk)):
                raise JassyError(f"obstacles: expected Plane or Disk, got {ob!r}")
        self.mu, self.mu_pairs = float(mu), dict(mu_pairs or {})
        self.ignore = {tuple(sorted(map(int, p))) for p in ignore}
        self.schur = bool(schur)
        self.margin, self.stab, self.tol, self.max_iter = float(margin), float(stabilisation), tol, max_iter
        self.nr, self.nb = len(self.rods), len(self.bodies)
        self.offsets = np.cumsum([0] + [f.ndof for f in self.rods] + [3] * self.nb)
        self.ndof = int(self.offsets[-1])
        self.radius = np.array([f.model.radius for f in self.rods])
        mass = [np.array([b.mass, b.mass, b.inertia]) for b in self.bodies]
        self._M = np.concatenate(mass) if mass else np.zeros(0)
        self._disk_body = np.array([i for i, b in enumerate(self.bodies) for _ in b.disks], dtype=np.int64)
        self._disk_local = np.array([d for b in self.bodies for d in b.disks], dtype=np.float64).reshape(
            -1, 3
        )
        self._static = [i for i, ob in enumerate(self.obstacles) if isinstance(ob, Disk)]
        self._planes = [i for i, ob in enumerate(self.obstacles) if isinstance(ob, Plane)]
        self._static_disks = (
            np.array([self.obstacles[i].centre for i in self._static], dtype=np.float64).reshape(-1, 2),
            np.array([self.obstacles[i].radius for i in self._static], dtype=np.float64),
        )
        self._disk_owner = np.concatenate(
            [self.nr + self._disk_body, self.nr + self.nb + np.array(self._static, np.int64)]
        )
        self._disk_feature = np.concatenate([np.arange(len(self._disk_body)), np.arange(len(self._static))])
        nid = self.nr + self.nb + len(self.obstacles)
        self._mu_table = np.full((nid, nid), self.mu)
        for (a, b), m in self.mu_pairs.items():  # (a, b) wins over (b, a)
            if 0 <= a < nid and 0 <= b < nid:
                self._mu_table[a, b] = m
                if (b, a) not in self.mu_pairs:
                    self._mu_table[b, a] = m
        self._band, self._orders = None, {}
        if self.nr and not self.nb and all(isinstance(f, MixedRod) for f in self.rods):
            # rods only: K is the rods' band KKT matrices one after the other (no coupling rows)
            sizes = [f.perm.size for f in self.rods]
            start = np.cumsum([0] + sizes)
            m_off = self.ndof + np.cumsum([0] + [f.n_constraints for f in self.rods])
            pos = np.empty(start[-1], dtype=np.int64)
            for k, f in enumerate(self.rods):
                pos[self.offsets[k] : self.offsets[k + 1]] = start[k] + f.perm[: f.ndof]
                pos[m_off[k] : m_off[k + 1]] = start[k] + f.perm[f.ndof :]
            self._band = (start, m_off, pos)

    # ---- state -------------------------------------------------------------------------------
    def initial_state(self, rod_states=None, poses=None, velocities=None) -> SystemState:
        """Rod states (default each formulation's initial_state()), rigid poses (B, 3), velocities."""
        rods = list(rod_states) if rod_states is not None else [f.initial_state() for f in self.rods]
        q = np.zeros((self.nb, 3)) if poses is None else np.array(poses, dtype=np.float64).reshape(self.nb, 3)
        v = (
            np.zeros((self.nb, 3))
            if velocities is None
            else np.array(velocities, dtype=np.float64).reshape(self.nb, 3)
        )
        return SystemState(rods, q, v)

    def world_disks(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Centres (D, 2) and radii (D,) of the rigid bodies' disks at poses q."""
        qb = q[self._disk_body]
        c, s = np.cos(qb[:, 2]), np.sin(qb[:, 2])
        ox, oy = self._disk_local[:, 0], self._disk_local[:, 1]
        return np.column_stack([qb[:, 0] + c * ox - s * oy, qb[:, 1] + s * ox + c * oy]), self._disk_local[
            :, 2
        ]

    def anchor_point(self, state: SystemState, a: Anchor):
        """(point (2,), global dof indices, J (2, k)) of an anchor."""
        if a.body < self.nr:
            p, cols, J = self.rods[a.body].point_jacobian(state.rods[a.body].q, a.element, a.s)
            return np.asarray(p, dtype=np.float64), np.asarray(cols) + self.offsets[a.body], np.asarray(J)
        k = a.body - self.nr
        x, y, phi = state.q[k]
        c, s = np.cos(phi), np.sin(phi)
        d = np.array([c * a.offset[0] - s * a.offset[1], s * a.offset[0] + c * a.offset[1]])
        return self._rigid_jacobian(k, np.array([x, y]) + d, state.q)

    def _rigid_jacobian(self, k, point, q):
        d = point - q[k, :2]
        J = np.array([[1.0, 0.0, -d[1]], [0.0, 1.0, d[0]]])
        return point, self.offsets[self.nr + k] + np.arange(3), J

    # ---- detection ---------------------------------------------------------------------------
    def detect(self, state: SystemState) -> dict:
        """Contacts with gap < margin: dict of arrays kind/ida/idb/fa/fb (feature: element or disk),
        sa/sb, pa/pb (centre-line or centre points), n (from b to a), gap."""
        arcs_list, rod_of, elem_of = [], [], []
        for i, (f, st) in enumerate(zip(self.rods, state.rods, strict=True)):
            a = f.arcs(st.q)
            arcs_list.append(np.column_stack([a.x, a.y, a.theta, a.kappa, a.l]))
            rod_of.append(np.full(len(a.x), i))
            elem_of.append(np.arange(len(a.x)))
        arcs = np.concatenate(arcs_list) if arcs_list else np.zeros((0, 5))
        rod_of = np.concatenate(rod_of).astype(np.int64) if rod_of else np.zeros(0, np.int64)
        elem_of = np.concatenate(elem_of).astype(np.int64) if elem_of else np.zeros(0, np.int64)
        rr = self.radius[rod_of] if rod_of.size else np.zeros(0)
        dc, dr = self.world_disks(state.q)
        sc, sr = self._static_disks
        # disk owners: rigid body ids, then static obstacle ids
        d_owner, d_feat = self._disk_owner, self._disk_feature
        centres_d, radii_d = np.concatenate([dc, sc]), np.concatenate([dr, sr])
        ac, ar = geometry.element_bounds(arcs)
        na = len(arcs)
        rows, meta = [], []
        if self.nr > 1:  # elements of different rods
            pairs = geometry.broad_phase(ac, ar + rr, self.margin)
            pairs = pairs[rod_of[pairs[:, 0]] != rod_of[pairs[:, 1]]]
            if len(pairs):
                ia, ib = pairs[:, 0], pairs[:, 1]
                rows.append(geometry.arc_arc(arcs, ia, ib, rr[ia], rr[ib]))
                meta.append(np.column_stack([rod_of[ia], rod_of[ib], elem_of[ia], elem_of[ib]]))
        pairs = geometry.cross_pairs(ac, ar + rr, centres_d, radii_d, self.margin)
        if len(pairs):
            ia, kd = pairs[:, 0], pairs[:, 1]
            rows.append(geometry.arc_disk(arcs, ia, centres_d[kd], radii_d[kd], rr[ia]))
            meta.append(np.column_stack([rod_of[ia], d_owner[kd], elem_of[ia], d_feat[kd]]))
        if len(dr):  # rigid disks against other bodies' disks
            pairs = geometry.broad_phase(centres_d, radii_d, self.margin)
            ka, kb = pairs[:, 0], pairs[:, 1]
            dd = (d_owner[ka] != d_owner[kb]) & ((ka < len(dr)) | (kb < len(dr)))
            if np.any(dd):
                ka, kb = ka[dd], kb[dd]
                rows.append(_disk_disk(centres_d[ka], radii_d[ka], centres_d[kb], radii_d[kb]))
                meta.append(np.column_stack([d_owner[ka], d_owner[kb], d_feat[ka], d_feat[kb]]))
        for p in self._planes:
            ob = self.obstacles[p]
            nrm = np.asarray(ob.normal, dtype=np.float64)
            pt = np.asarray(ob.point, dtype=np.float64)
            pid = self.nr + self.nb + p
            near = np.nonzero((ac - pt) @ nrm - ar - rr < self.margin)[0] if na else np.zeros(0, np.int64)
            if near.size:
                out = geometry.arc_plane(arcs, near, pt, nrm, 0.0)
                out[:, geometry.GAP] -= rr[near]
                rows.append(out)
                meta.append(
                    np.column_stack(
                        [rod_of[near], np.full(near.size, pid), elem_of[near], np.zeros_like(near)]
                    )
                )
            nd = np.nonzero((dc - pt) @ nrm - dr < self.margin)[0]
            if nd.size:
                dist = (dc[nd] - pt) @ nrm
                out = np.column_stack(
                    [
                        np.zeros((nd.size, 2)),
                        dc[nd],
                        dc[nd] - dist[:, None] * nrm,
                        np.tile(nrm, (nd.size, 1)),
                        dist - dr[nd],
                    ]
                )
                rows.append(out)
                meta.append(
                    np.column_stack(
                        [self.nr + self._disk_body[nd], np.full(nd.size, pid), nd, np.zeros_like(nd)]
                    )
                )
        if not rows:
            return {
                "meta": np.zeros((0, 4), np.int64),
                "geo": np.zeros((0, len(geometry.ContactRow._fields))),
            }
        geo, meta = np.concatenate(rows), np.concatenate(meta).astype(np.int64)
        keep = geo[:, geometry.GAP] < self.margin
        if self.ignore:
            keep &= np.array([tuple(sorted(p)) not in self.ignore for p in meta[:, :2].tolist()], dtype=bool)
        meta, geo = meta[keep], geo[keep]
        keep = self._cluster(meta, geo)
        meta, geo = meta[keep], geo[keep]
        return {"meta": meta, "geo": geo}

    def _cluster(self, meta, geo) -> np.ndarray:
        """Mask keeping, per body pair, contacts in increasing gap order unless one already kept lies
        within half the shortest element length of the pair (adjacent elements meeting at a node, or
        a conformal patch, give (near-)duplicate rows that make W singular and PGS crawl)."""
        keep = np.zeros(len(meta), dtype=bool)
        if len(meta) == 0:
            return keep
        n_other = self.nb + len(self.obstacles)
        lmin = np.array([f.model.length / f.model.n for f in self.rods] + [np.inf] * n_other)
        pair = meta[:, 0] * (self.nr + self.nb + len(self.obstacles)) + meta[:, 1]
        order = np.lexsort((geo[:, geometry.GAP], pair))
        ps = pair[order]
        starts = np.flatnonzero(np.r_[True, ps[1:] != ps[:-1]])
        stops = np.r_[starts[1:], len(order)]
        single = stops - starts == 1
        keep[order[starts[single]]] = True
        for start, stop in zip(starts[~single], stops[~single], strict=True):
            idx = order[start:stop]
            d = 0.5 * min(lmin[meta[idx[0], 0]], lmin[meta[idx[0], 1]])
            d = 0.0 if np.isinf(d) else d  # rigid-only pairs: distinct disks touch at distinct points
            kept = []
            for i in idx:
                if all(np.hypot(*(geo[i, _PA] - geo[j, _PA])) >= d for j in kept):
                    kept.append(i)
            keep[kept] = True
        return keep

    # ---- one step ----------------------------------------------------------------------------
    def step(self, state: SystemState, h: float, drives=None, forces=None) -> tuple[SystemState, StepInfo]:
        """Advance by h (s). ``drives`` {body id: (vx, vy, omega)} prescribes the velocity of a rigid
        body, or of a rod's start pose (its first three dofs, x0, y0, theta0, in both formulations;
        use with start_bc "free"); their impulses are the last 3 entries per drive of ``lam``, in
        order. ``forces`` {rigid body id: (fx, fy, torque)} adds external loads (N, N m)."""
        if not (np.isfinite(h) and h > 0):
            raise JassyError(f"h: expected a time step > 0 s, got {h!r}")
        drives, forces = dict(drives or {}), dict(forces or {})
        for k in forces:
            if not self.nr <= k < self.nr + self.nb:
                raise JassyError(
                    f"forces: expected rigid body ids in [{self.nr}, {self.nr + self.nb}), got {k}"
                )
        for k in drives:
            if not 0 <= k < self.nr + self.nb:
                raise JassyError(f"drives: expected body ids in [0, {self.nr + self.nb}), got {k}")
        t0 = time.perf_counter()
        det = self.detect(state)
        t1 = time.perf_counter()
        band, K, rhs = self._bilateral(state, h, drives, forces)
        meta, geo = det["meta"], det["geo"]
        nc = len(meta)
        H, G = self._contact_rows(state, meta, geo)
        t2 = time.perf_counter()
        solver = None
        if nc and self.schur and band is not None:
            try:
                solver = SchurDelassus(*band, self.ndof, H, rhs)
            except RuntimeError:  # K_II or S singular (e.g. several joints on one body): direct path
                solver = None
        if solver is None:
            solver = DirectDelassus(self._kkt(band, K), self.ndof, H, rhs)
        x = solver.x_free
        t3 = time.perf_counter()
        if nc:
            gap = geo[:, geometry.GAP]
            w = H @ x[: self.ndof]
            u_free = w[0::2].copy()
            w[0::2] += np.where(gap >= 0, gap, self.stab * gap) / h
            mu = self._mu_table[meta[:, 0], meta[:, 1]]
            keys = [tuple(k) for k in meta.tolist()]
            r0 = np.array([state.cache.get(k, (0.0, 0.0)) for k in keys])
            res = solve_dfcp(solver.W, w, mu, r0=r0, tol=self.tol, max_iter=self.max_iter)
            try:
                x = solver.solution(res.r.reshape(-1))
            except RuntimeError:  # partitioned solve inaccurate: one direct KKT solve
                full = rhs.copy()
                full[: self.ndof] += H.T @ res.r.reshape(-1)
                x = self._kkt(band, K).solve(full)
            r, u, its, resid = res.r, res.u, res.iterations, res.residual
            cache = {k: tuple(ri) for k, ri in zip(keys, r.tolist(), strict=True) if ri[0] > 0}
        else:
            r, u, u_free, its, resid, cache = np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0), 0, 0.0, {}
        t4 = time.perf_counter()
        v = x[: self.ndof]
        if not np.all(np.isfinite(v)):
            raise JassyError(
                "step: the velocity solve produced NaN/Inf (time step too large or singular constraints)"
            )
        rods = [
            f.advance(st, v[self.offsets[k] : self.offsets[k + 1]], h)
            for k, (f, st) in enumerate(zip(self.rods, state.rods, strict=True))
        ]
        vb = v[self.offsets[self.nr] :].reshape(self.nb, 3)
        new = SystemState(rods, state.q + h * vb, vb.copy(), state.time + h, cache)
        surface = geo[:, _PA] - self._radius_of(meta[:, 0], meta[:, 2])[:, None] * geo[:, _N]
        rolling = np.abs(G @ v)
        times = {"detect": t1 - t0, "assemble": t2 - t1, "delassus": t3 - t2, "solve": t4 - t3}
        info = StepInfo(
            state.time + h,
            meta[:, :2].copy(),
            surface,
            geo[:, _N].copy(),
            geo[:, geometry.GAP].copy(),
            r,
            u,
            u_free,
            x[self.ndof :],
            its,
            resid,
            times,
            rolling,
        )
        return new, info

    def _bilateral(self, state, h, drives, forces):
        """(band, K, rhs): K = [[A, C^T], [C, 0]] in band storage (ab, kl, ku, pos) or None if it is
        not banded, K sparse (None on the rods-only path), rhs = (b, c). Rods only: the rods' own band
        matrices one after the other, assembled directly. Else the entries of the rods'
        linear_system, rigid bodies, joint and drive rows, in a reverse Cuthill-McKee order computed
        once per set of driven bodies (the sparsity pattern does not change between steps)."""
        if self._band is not None and not drives:
            start, m_off, pos = self._band
            ab = np.zeros((start[-1], 3 * BAND + 1))
            rhs = np.empty(start[-1])
            for k, (f, st) in enumerate(zip(self.rods, state.rods, strict=True)):
                _, rk = f.kkt_band(st, h, out=ab[start[k] : start[k + 1]])
                rhs[self.offsets[k] : self.offsets[k + 1]] = rk[: f.ndof]
                rhs[m_off[k] : m_off[k + 1]] = rk[f.ndof :]
            return (ab, BAND, BAND, pos), None, rhs
        ent, b_parts, c_parts = [], [], []  # K entries (rows, cols, vals) in natural numbering
        m = self.ndof  # next multiplier
        for k, (f, st) in enumerate(zip(self.rods, state.rods, strict=True)):
            A, b, C, c = f.linear_system(st, h)
            A, C = sp.coo_matrix(A), sp.coo_matrix(C)
            ent.append((A.row + self.offsets[k], A.col + self.offsets[k], A.data))
            ent += [
                (C.row + m, C.col + self.offsets[k], C.data),
                (C.col + self.offsets[k], C.row + m, C.data),
            ]
            m += C.shape[0]
            b_parts.append(np.asarray(b, dtype=np.float64))
            c_parts.append(np.asarray(c, dtype=np.float64))
        if self.nb:
            dofs = np.arange(self.offsets[self.nr], self.ndof)
            ent.append((dofs, dofs, self._M))
            fb = np.zeros((self.nb, 3))
            fb[:, 1] = -np.array([b.mass * b.gravity for b in self.bodies])
            for k, f in forces.items():
                fb[k - self.nr] += np.asarray(f, dtype=np.float64)
            b_parts.append(self._M * state.v.reshape(-1) + h * fb.reshape(-1))
        for jt in self.joints:
            pa, ca, Ja = self.anchor_point(state, jt.a)
            if jt.b is None:
                pb, cb, Jb = np.asarray(jt.world, dtype=np.float64), np.zeros(0, np.int64), np.zeros((2, 0))
            else:
                pb, cb, Jb = self.anchor_point(state, jt.b)
            rows = m + np.repeat([0, 1], len(ca) + len(cb))
            cols = np.tile(np.concatenate([ca, cb]), 2)
            vals = np.concatenate([Ja, -Jb], axis=1).ravel()
            ent += [(rows, cols, vals), (cols, rows, vals)]
            m += 2
            c_parts.append(-jt.rate * (pa - pb) / h)
        for k, vel in drives.items():
            rows, cols = m + np.arange(3), self.offsets[k] + np.arange(3)
            ent += [(rows, cols, np.ones(3)), (cols, rows, np.ones(3))]
            m += 3
            c_parts.append(np.asarray(vel, dtype=np.float64))
        rows, cols, vals = (np.concatenate([e[i] for e in ent]) for i in range(3))
        rhs = np.concatenate(b_parts + c_parts)
        key = tuple(drives)
        if key not in self._orders or not self._orders[key].fits(rows, cols):
            self._orders[key] = BandOrder(rows, cols, m)
        band = self._orders[key].band(rows, cols, vals)
        K = sp.csc_matrix((vals, (rows, cols)), shape=(m, m)) if band is None else None
        return band, K, rhs

    def _kkt(self, band, K):
        """One factorisation of K with ``.solve(rhs)``: band LU, else equilibrated SuperLU."""
        if band is not None:
            return BandKKT(*band)
        return SparseKKT(K, self.ndof)

    def _contact_rows(self, state, meta, geo):
        """(H, G) sparse (2c, ndof) and (c, ndof): H rows n^T (J_a - J_b), t^T (J_a - J_b) of each
        contact's surface points (t = e_z x n), G the rolling rows R_a omega_a + R_b omega_b."""
        nc = len(meta)
        if nc == 0:
            return sp.csr_matrix((0, self.ndof)), sp.csr_matrix((0, self.ndof))
        nrm = geo[:, _N]
        tng = np.column_stack([-nrm[:, 1], nrm[:, 0]])
        rows, cols, vals, grows, gcols, gvals = [], [], [], [], [], []
        for side, sign in ((0, 1.0), (1, -1.0)):
            body, feat, s = meta[:, side], meta[:, 2 + side], geo[:, geometry.S_A + side]
            for k in np.unique(body[body < self.nr]):
                f, sel = self.rods[k], np.nonzero(body == k)[0]
                q = state.rods[k].q
                _, c, J = f.point_jacobians(q, feat[sel], s[sel])
                jn = sign * np.einsum("mi,miw->mw", nrm[sel], J)
                jt = sign * np.einsum("mi,miw->mw", tng[sel], J)
                if hasattr(f, "angle_jacobians"):  # surface point: u_T gets -r phi_dot
                    ca, dphi = f.angle_jacobians(q, feat[sel], s[sel])
                    ca = ca + self.offsets[k]
                    rows.append(np.repeat(2 * sel + 1, ca.shape[1]))
                    cols.append(ca.ravel())
                    vals.append((-f.model.radius * dphi).ravel())
                    grows.append(np.repeat(sel, ca.shape[1]))
                    gcols.append(ca.ravel())
                    gvals.append((f.model.radius * dphi).ravel())
                for row, jac in ((2 * sel, jn), (2 * sel + 1, jt)):
                    rows.append(np.repeat(row, c.shape[1]))
                    cols.append((c + self.offsets[k]).ravel())
                    vals.append(jac.ravel())
            sel = np.nonzero((body >= self.nr) & (body < self.nr + self.nb))[0]
            if sel.size:
                disk = feat[sel]
                kb = self._disk_body[disk]
                radius = self._disk_local[disk, 2]
                arm = geo[sel, _PB if side else _PA] - sign * radius[:, None] * nrm[sel]
                arm -= state.q[kb, :2]
                dofs = self.offsets[self.nr + kb]
                for row, d in ((2 * sel, nrm[sel]), (2 * sel + 1, tng[sel])):
                    rows.append(np.repeat(row, 3))
                    cols.append((dofs[:, None] + np.arange(3)).ravel())
                    moment = d[:, 1] * arm[:, 0] - d[:, 0] * arm[:, 1]
                    vals.append(sign * np.column_stack([d, moment]).ravel())
                grows.append(sel)
                gcols.append(dofs + 2)
                gvals.append(radius)
        H = sp.csr_matrix(
            (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(2 * nc, self.ndof)
        )
        if not grows:
            return H, sp.csr_matrix((nc, self.ndof))
        G = sp.csr_matrix(
            (np.concatenate(gvals), (np.concatenate(grows), np.concatenate(gcols))), shape=(nc, self.ndof)
        )
        return H, G

    def _radius_of(self, body, feat):
        out = np.zeros(len(body))
        rod = body < self.nr
        out[rod] = self.radius[body[rod]]
        rig = (body >= self.nr) & (body < self.nr + self.nb)
        out[rig] = self._disk_local[feat[rig], 2]
        return out


def _disk_disk(ca, ra, cb, rb) -> np.ndarray:
    d = ca - cb
    dist = np.linalg.norm(d, axis=1)
    n = d / np.maximum(dist, 1e-300)[:, None]
    return np.column_stack([np.zeros((len(ca), 2)), ca, cb, n, dist - ra - rb])


def contact_events(infos: list[StepInfo], min_speed: float = 1e-3, min_impulse: float = 1e-9):
    """(impacts, tracks) from step infos: an Impact when a body pair starts touching (total normal
    impulse > min_impulse after none) approaching faster than min_speed (m/s); one ContactTrack per
    body pair over all steps (normal force = sum r_N / h, slip speed = max |u_T| and rolling speed =
    max rolling over the pair's active contacts). Raises JassyError on NaN/Inf."""
    if not infos:
        return [], []
    times = np.array([inf.time for inf in infos])
    h = np.diff(np.concatenate([[2 * times[0] - times[1] if len(times) > 1 else 0.0], times]))
    pairs = sorted({tuple(sorted(map(int, p))) for inf in infos for p in inf.bodies})
    force = {p: np.zeros(len(infos)) for p in pairs}
    slip = {p: np.zeros(len(infos)) for p in pairs}
    roll = {p: np.zeros(len(infos)) for p in pairs}
    impacts, touching = [], set()
    for k, inf in enumerate(infos):
        now = {}
        for (a, b), r, u, uf, w in zip(
            inf.bodies.tolist(), inf.r, inf.u, inf.u_free, inf.rolling, strict=True
        ):
            p = (min(a, b), max(a, b))
            if r[0] > min_impulse:
                force[p][k] += r[0] / h[k]
                slip[p][k] = max(slip[p][k], abs(u[1]))
                roll[p][k] = max(roll[p][k], w)
                imp, spd = now.get(p, (0.0, 0.0))
                now[p] = (imp + r[0], max(spd, -uf))
        for p, (imp, spd) in now.items():
            if p not in touching and spd > min_speed:
                if not (np.isfinite(imp) and np.isfinite(spd)):
                    raise JassyError(f"contact_events: non-finite impact between bodies {p}")
                impacts.append(Impact(float(inf.time), p, float(imp), float(spd)))
        touching = set(now)
    tracks = []
    for p in pairs:
        if not all(np.all(np.isfinite(x[p])) for x in (force, slip, roll)):
            raise JassyError(f"contact_events: non-finite contact track between bodies {p}")
        tracks.append(ContactTrack(p, times, force[p], slip[p], roll[p]))
    return impacts, tracks
