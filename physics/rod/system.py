"""A planar multi-body system: rods (chained or mixed formulations), rigid bodies made of disks,
static disks and planes, pin joints and prescribed velocities, stepped with frictional contact.

One step (velocity level, linearly implicit Euler, impulses in N s):

    A v+ = b + C^T(-lam) + H^T r,   C v+ = c,   u = H v+ + g_stab,   (u, r) solve the DFCP (dfcp.py)

* A, b, C, c: each rod's ``linear_system`` (boundary conditions, gluing), rigid bodies M v + h f;
  joint rows J_a v - J_b v = -rate (p_a - p_b)/h and drive rows v_k = v_target are appended.
* Schur reductions: W = H K^{-1}|_v H^T with K = [[A, C^T], [C, 0]], w = H v_free + g_stab, then
  v+ = v_free + K^{-1}|_v H^T r. Default (``schur=True``): a partitioned Schur complement on the
  dofs touched by H (``_SchurDelassus``: K_II factorised once, banded LU in reverse Cuthill-McKee
  order, columns of K_II^{-1} K_IB shared by colouring, iterative refinement to a componentwise
  backward error < 1e-10); if K_II is singular it falls back to the direct path: K factorised once
  (the rod's banded KKT for a lone rod, else SuperLU) and 2c solves with [H^T; 0].
  H has rows n^T(J_a - J_b), t^T(J_a - J_b) (n from b to a, t = e_z x n).
* Penetration at velocity level: g_stab = g/h on the normal row when the gap g >= 0 (contacts are
  kept from ``margin`` on, and only act if they would close within the step) and beta g/h when
  g < 0 (Baumgarte, beta = ``stabilisation``). Moreau-type: restitution 0.
* Rigid surface points include the rotation (omega x (P - X)), so disks roll; on rods the contact
  velocity is the centre-line velocity (the r theta_dot term of the thickness is neglected).
* Contact reduction: per body pair, a contact within half an element length of a closer one is
  dropped (adjacent elements meeting at a node give duplicate rows).
* Not handled: rod self-contact; crossing centre lines (geometry.py).

Body ids (used in events): rods 0..R-1, rigid bodies R..R+B-1, static obstacles after them.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numba
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.linalg import lapack
from scipy.sparse import csgraph

from jassy.errors import JassyError
from jassy.events import ContactTrack, Impact
from physics.rod import geometry
from physics.rod.dfcp import solve_dfcp


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
    (N s), relative velocities u (c, 2) after and free normal velocity before (m/s), bilateral
    impulses lam, solver sweeps and residual, and times (s) of detection / assembly / Delassus / solve."""

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
        sc = np.array([self.obstacles[i].centre for i in self._static], dtype=np.float64).reshape(-1, 2)
        sr = np.array([self.obstacles[i].radius for i in self._static], dtype=np.float64)
        # disk owners: rigid body ids, then static obstacle ids
        d_owner = np.concatenate(
            [self.nr + self._disk_body, self.nr + self.nb + np.array(self._static, np.int64)]
        )
        d_feat = np.concatenate([np.arange(len(dr)), np.arange(len(sr))]).astype(np.int64)
        centres_d, radii_d = np.concatenate([dc, sc]), np.concatenate([dr, sr])
        ac, ar = geometry.element_bounds(arcs)
        na = len(arcs)
        pairs = geometry.broad_phase(
            np.concatenate([ac, centres_d]), np.concatenate([ar + rr, radii_d]), self.margin
        )
        rows, meta = [], []
        i, j = pairs[:, 0], pairs[:, 1]
        aa = (j < na) & (rod_of[np.minimum(i, na - 1)] != rod_of[np.minimum(j, na - 1)]) if na else j < 0
        if np.any(aa):
            ia, ib = i[aa], j[aa]
            rows.append(geometry.arc_arc(arcs, ia, ib, rr[ia], rr[ib]))
            meta.append(np.column_stack([rod_of[ia], rod_of[ib], elem_of[ia], elem_of[ib]]))
        ad = (i < na) & (j >= na)
        if np.any(ad):
            ia, kd = i[ad], j[ad] - na
            rows.append(geometry.arc_disk(arcs, ia, centres_d[kd], radii_d[kd], rr[ia]))
            meta.append(np.column_stack([rod_of[ia], d_owner[kd], elem_of[ia], d_feat[kd]]))
        dd = i >= na
        if np.any(dd):
            ka, kb = i[dd] - na, j[dd] - na
            dd[dd] = (d_owner[ka] != d_owner[kb]) & ((ka < len(dr)) | (kb < len(dr)))
        if np.any(dd):
            ka, kb = i[dd] - na, j[dd] - na
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
                out[:, 8] -= rr[near]
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
            return {"meta": np.zeros((0, 4), np.int64), "geo": np.zeros((0, 9))}
        geo, meta = np.concatenate(rows), np.concatenate(meta).astype(np.int64)
        keep = geo[:, 8] < self.margin
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
        order = np.lexsort((geo[:, 8], pair))
        start = 0
        while start < len(order):
            stop = start
            while stop < len(order) and pair[order[stop]] == pair[order[start]]:
                stop += 1
            idx = order[start:stop]
            d = 0.5 * min(lmin[meta[idx[0], 0]], lmin[meta[idx[0], 1]])
            d = 0.0 if np.isinf(d) else d  # rigid-only pairs: distinct disks touch at distinct points
            kept = []
            for i in idx:
                if all(np.hypot(*(geo[i, 2:4] - geo[j, 2:4])) >= d for j in kept):
                    kept.append(i)
            keep[kept] = True
            start = stop
        return keep

    # ---- one step ----------------------------------------------------------------------------
    def _side(self, state, body, feat, s, point, n, sign):
        """Global cols and the 2 x k rows (n, t)^T J of the contact point on one side."""
        if body < self.nr:
            _, cols, J = self.rods[body].point_jacobian(state.rods[body].q, int(feat), float(s))
            return np.asarray(cols) + self.offsets[body], np.asarray(J)
        if body >= self.nr + self.nb:
            return None, None
        k = self._disk_body[feat]
        R = self._disk_local[feat, 2]
        _, cols, J = self._rigid_jacobian(k, point - sign * R * n, state.q)
        return cols, J

    def step(self, state: SystemState, h: float, drives=None, forces=None) -> tuple[SystemState, StepInfo]:
        """Advance by h (s). ``drives`` {body id: (vx, vy, omega)} prescribes the velocity of a rigid
        body, or of a rod's start pose (its first three dofs, x0, y0, theta0, in both formulations;
        use with start_bc "free"); their impulses are the last 3 entries per drive of ``lam``, in
        order. ``forces`` {rigid body id: (fx, fy, torque)} adds external loads (N, N m)."""
        if not (np.isfinite(h) and h > 0):
            raise JassyError(f"h: expected a time step > 0 s, got {h!r}")
        t0 = time.perf_counter()
        det = self.detect(state)
        t1 = time.perf_counter()
        # --- bilateral system
        A_blocks, b_parts, C_rows, c_parts = [], [], [], []
        for k, (f, st) in enumerate(zip(self.rods, state.rods, strict=True)):
            A, b, C, c = f.linear_system(st, h)
            A_blocks.append(sp.csr_matrix(A))
            b_parts.append(np.asarray(b, dtype=np.float64))
            C = sp.csr_matrix(C)
            C_rows.append(
                sp.csr_matrix((C.data, C.indices + self.offsets[k], C.indptr), shape=(C.shape[0], self.ndof))
            )
            c_parts.append(np.asarray(c, dtype=np.float64))
        if self.nb:
            A_blocks.append(sp.diags(self._M))
            fb = np.zeros((self.nb, 3))
            fb[:, 1] = -np.array([b.mass * b.gravity for b in self.bodies])
            for k, f in (forces or {}).items():
                if not self.nr <= k < self.nr + self.nb:
                    raise JassyError(
                        f"forces: expected rigid body ids in [{self.nr}, {self.nr + self.nb}), got {k}"
                    )
                fb[k - self.nr] += np.asarray(f, dtype=np.float64)
            b_parts.append(self._M * state.v.reshape(-1) + h * fb.reshape(-1))
        for jt in self.joints:
            pa, ca, Ja = self.anchor_point(state, jt.a)
            if jt.b is None:
                pb, cb, Jb = np.asarray(jt.world, dtype=np.float64), np.zeros(0, np.int64), np.zeros((2, 0))
            else:
                pb, cb, Jb = self.anchor_point(state, jt.b)
            M = sp.csr_matrix(
                (
                    np.concatenate([Ja, -Jb], axis=1).ravel(),
                    (np.repeat([0, 1], len(ca) + len(cb)), np.tile(np.concatenate([ca, cb]), 2)),
                ),
                shape=(2, self.ndof),
            )
            C_rows.append(M)
            c_parts.append(-jt.rate * (pa - pb) / h)
        for k, vel in (drives or {}).items():
            if not 0 <= k < self.nr + self.nb:
                raise JassyError(f"drives: expected body ids in [0, {self.nr + self.nb}), got {k}")
            cols = self.offsets[k] + np.arange(3)
            C_rows.append(sp.csr_matrix((np.ones(3), (np.arange(3), cols)), shape=(3, self.ndof)))
            c_parts.append(np.asarray(vel, dtype=np.float64))
        A = sp.block_diag(A_blocks, format="csr")
        C = sp.vstack(C_rows, format="csr") if C_rows else sp.csr_matrix((0, self.ndof))
        b, c = np.concatenate(b_parts), np.concatenate(c_parts) if c_parts else np.zeros(0)
        # --- contact rows
        meta, geo = det["meta"], det["geo"]
        nc = len(meta)
        Hr, Hc, Hv = [], [], []
        for i in range(nc):
            n = geo[i, 6:8]
            t = np.array([-n[1], n[0]])
            for side, sign in ((0, 1.0), (1, -1.0)):
                cols, J = self._side(
                    state,
                    meta[i, side],
                    meta[i, 2 + side],
                    geo[i, side],
                    geo[i, 2 + 2 * side : 4 + 2 * side],
                    n,
                    sign,
                )
                if cols is None:
                    continue
                Hr.append(np.repeat([2 * i, 2 * i + 1], len(cols)))
                Hc.append(np.tile(cols, 2))
                Hv.append(sign * np.concatenate([n @ J, t @ J]))
        H = (
            sp.csr_matrix(
                (np.concatenate(Hv), (np.concatenate(Hr), np.concatenate(Hc))), shape=(2 * nc, self.ndof)
            )
            if nc
            else sp.csr_matrix((0, self.ndof))
        )
        t2 = time.perf_counter()
        solver = None
        if nc and self.schur:
            try:
                solver = _SchurDelassus(A, C, H, b, c)
            except RuntimeError:  # K_II singular (e.g. several joints on one body): direct path
                solver = None
        if solver is None:
            solver = _DirectDelassus(self._factor(A, C, bool(self.joints or drives)), H, b, c)
        x = solver.x_free
        t3 = time.perf_counter()
        if nc:
            gap = geo[:, 8]
            w = H @ x[: self.ndof]
            u_free = w[0::2].copy()
            w[0::2] += np.where(gap >= 0, gap, self.stab * gap) / h
            mu = np.array([self._mu(a, b) for a, b in meta[:, :2]])
            keys = [tuple(k) for k in meta]
            r0 = np.array([state.cache.get(k, (0.0, 0.0)) for k in keys])
            res = solve_dfcp(solver.W, w, mu, r0=r0, tol=self.tol, max_iter=self.max_iter)
            try:
                x = solver.solution(res.r.reshape(-1))
            except RuntimeError:  # partitioned solve inaccurate: same W, direct KKT solves
                x = _DirectDelassus(self._factor(A, C, bool(self.joints or drives)), H, b, c).solution(
                    res.r.reshape(-1)
                )
            r, u, its, resid = res.r, res.u, res.iterations, res.residual
            cache = {k: tuple(ri) for k, ri in zip(keys, r, strict=True) if ri[0] > 0}
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
        surface = geo[:, 2:4] - self._radius_of(meta[:, 0], meta[:, 2])[:, None] * geo[:, 6:8]
        times = {"detect": t1 - t0, "assemble": t2 - t1, "delassus": t3 - t2, "solve": t4 - t3}
        info = StepInfo(
            state.time + h,
            meta[:, :2].copy(),
            surface,
            geo[:, 6:8].copy(),
            geo[:, 8].copy(),
            r,
            u,
            u_free,
            x[self.ndof :],
            its,
            resid,
            times,
        )
        return new, info

    def _factor(self, A, C, extra_rows: bool):
        """KKT factorisation with ``.solve(b, c) -> (v, lam)``: the rod's own (banded for MixedRod)
        when the system is one rod without extra rows, else SuperLU of the whole KKT matrix."""
        if self.nr == 1 and self.nb == 0 and not extra_rows and hasattr(self.rods[0], "kkt_factor"):
            return self.rods[0].kkt_factor(A, C)
        return _SparseKKT(A, C)

    def _radius_of(self, body, feat):
        out = np.zeros(len(body))
        rod = body < self.nr
        out[rod] = self.radius[body[rod]]
        rig = (body >= self.nr) & (body < self.nr + self.nb)
        out[rig] = self._disk_local[feat[rig], 2]
        return out

    def _mu(self, a, b) -> float:
        return self.mu_pairs.get((int(a), int(b)), self.mu_pairs.get((int(b), int(a)), self.mu))


@numba.njit(cache=True)
def _greedy_colours(ncol, nblock, pj, pk):
    """Greedy colouring of columns: columns sharing a block (pairs (pj, pk), sorted by pj) differ."""
    start = np.zeros(nblock + 1, np.int64)
    for k in pk:
        start[k + 1] += 1
    start = np.cumsum(start)
    members = np.empty(pk.size, np.int64)
    fill = start[:-1].copy()
    for t in range(pk.size):
        members[fill[pk[t]]] = pj[t]
        fill[pk[t]] += 1
    colour = np.full(ncol, -1, np.int64)
    mark = np.full(ncol + 1, -1, np.int64)
    t = 0
    for j in range(ncol):
        t0 = t
        while t < pj.size and pj[t] == j:
            k = pk[t]
            for m in range(start[k], start[k + 1]):
                if colour[members[m]] >= 0:
                    mark[colour[members[m]]] = j
            t += 1
        col = 0
        while mark[col] == j:
            col += 1
        colour[j] = col
        t = max(t, t0)
    return colour


class _BandedLU:
    """LU of a sparse matrix in reverse Cuthill-McKee order (LAPACK dgbtrf / dgbtrs); SuperLU if the
    band is wide. ``solve(rhs)`` for one or several columns; RuntimeError if singular."""

    def __init__(self, M, max_band: int = 64):
        self.perm = csgraph.reverse_cuthill_mckee(sp.csr_matrix(abs(M) + abs(M).T), symmetric_mode=True)
        P = sp.csr_matrix(M)[self.perm][:, self.perm].tocoo()
        self.kl = int(max(0, np.max(P.row - P.col, initial=0)))
        self.ku = int(max(0, np.max(P.col - P.row, initial=0)))
        self.splu = None
        if max(self.kl, self.ku) > max_band:
            self.splu = spla.splu(sp.csc_matrix(M))
            return
        ab = np.zeros((2 * self.kl + self.ku + 1, M.shape[0]))
        ab[self.kl + self.ku + P.row - P.col, P.col] = P.data
        self.lu, self.piv, info = lapack.dgbtrf(ab, self.kl, self.ku, overwrite_ab=1)
        if info != 0:
            raise RuntimeError(f"singular matrix (pivot {info})")

    def solve(self, rhs):
        if self.splu is not None:
            return self.splu.solve(rhs)
        x, info = lapack.dgbtrs(self.lu, self.kl, self.ku, rhs[self.perm], self.piv)
        out = np.empty_like(x)
        out[self.perm] = x
        return out


class _DirectDelassus:
    """W = H X_v with X = K^{-1}[H^T; 0]: 2c solves with the whole KKT factorisation."""

    def __init__(self, kkt, H, b, c):
        self.x_free = np.concatenate(kkt.solve(b, c))
        self.W = np.zeros((0, 0))
        if H.shape[0]:
            self.X = np.concatenate(kkt.solve(H.T.toarray(), np.zeros((len(c), H.shape[0]))))
            W = H @ self.X[: H.shape[1]]
            self.W = 0.5 * (W + W.T)

    def solution(self, r):
        return self.x_free + self.X @ r


class _SchurDelassus:
    """Delassus operator by a partitioned Schur complement: B = the dofs touched by H (plus the
    multipliers of constraints acting only on them), I = the rest. Removing B splits K_II into
    independent blocks (rod segments between contacts, free bodies): K_II is factorised once, and
    K_II^{-1} K_IB costs a few right-hand sides because columns whose blocks are disjoint share one
    (greedy colouring). S = K_BB - K_BI K_II^{-1} K_IB (block-banded, small) gives
    W = H_B S^{-1} H_B^T, and v from x_B and one more K_II solve: O(n) + O(c^2) instead of 2c full
    KKT solves; the velocities are polished by iterative refinement. Raises RuntimeError if K_II or
    S is singular, K_II is empty, or the refinement fails (the caller then solves directly)."""

    def __init__(self, A, C, H, b, c):
        ndof, m = A.shape[0], C.shape[0]
        K = sp.bmat([[A, C.T], [C, None]], format="csc") if m else sp.csc_matrix(A)
        N = K.shape[0]
        is_b = np.zeros(N, dtype=bool)
        is_b[np.unique(H.indices)] = True
        if m:
            Cc = sp.csr_matrix(C)
            outside = np.asarray((abs(Cc) @ (~is_b[:ndof]).astype(float)) == 0).ravel()
            is_b[ndof:] = outside & (np.diff(Cc.indptr) > 0)
        bi, ii = np.nonzero(is_b)[0], np.nonzero(~is_b)[0]
        if len(ii) == 0:
            raise RuntimeError("no interior unknowns to condense")
        Kc = K.tocsc()
        K_II, K_IB = Kc[ii][:, ii].tocsc(), Kc[ii][:, bi].tocsc()
        K_BI, K_BB = Kc[bi][:, ii].tocsr(), Kc[bi][:, bi].tocsc()
        ncomp, comp = csgraph.connected_components(K_II, directed=False)
        self.lu_ii = _BandedLU(K_II)
        # colour the B columns so that columns sharing a block of K_II get different colours
        key = np.unique(np.repeat(np.arange(len(bi)), np.diff(K_IB.indptr)) * ncomp + comp[K_IB.indices])
        pj, pk = key // ncomp, key % ncomp  # (column, block) pairs
        colour = _greedy_colours(len(bi), ncomp, pj, pk)
        coo = K_IB.tocoo()
        R = np.zeros((len(ii), int(colour.max(initial=0)) + 1))
        np.add.at(R, (coo.row, colour[coo.col]), coo.data)
        Zc = self.lu_ii.solve(R)
        order = np.argsort(comp, kind="stable")
        bounds = np.searchsorted(comp[order], np.arange(ncomp + 1))
        size = bounds[pk + 1] - bounds[pk]
        first = np.repeat(bounds[pk] - np.cumsum(size) + size, size)
        rows = order[first + np.arange(size.sum())]
        cols = np.repeat(pj, size)
        Z = sp.csc_matrix((Zc[rows, colour[cols]], (rows, cols)), shape=(len(ii), len(bi)))
        S = (K_BB - K_BI @ Z).tocsr()
        self.lu_s = _BandedLU(S)
        self.K, self.K_BI, self.K_IB, self.bi, self.ii, self.ndof = K, K_BI, K_IB, bi, ii, ndof
        self.rhs = np.concatenate([b, c])
        HB = H.tocsc()[:, bi[bi < ndof]]
        HBt = np.zeros((len(bi), H.shape[0]))
        HBt[: HB.shape[1]] = HB.T.toarray()
        self.XB = self.lu_s.solve(HBt)
        W = HB @ self.XB[: HB.shape[1]]
        self.W = 0.5 * (W + W.T)
        self.H = H
        self.x_free = self._refined(self.rhs)

    def _solve(self, rhs):
        """K^{-1} rhs through the partition (exact up to round-off)."""
        x = np.empty_like(rhs)
        y_i = self.lu_ii.solve(rhs[self.ii])
        x[self.bi] = xb = self.lu_s.solve(rhs[self.bi] - self.K_BI @ y_i)
        x[self.ii] = self.lu_ii.solve(rhs[self.ii] - self.K_IB @ xb)
        return x

    def _refined(self, rhs, x=None):
        """Solve with iterative refinement until the componentwise backward error is < 1e-10 (the
        condensed multipliers lose digits on rods with tiny curvature masses); RuntimeError if not."""
        x = self._solve(rhs) if x is None else x
        absk = abs(self.K)
        for _ in range(4):
            res = rhs - self.K @ x
            omega = np.max(np.abs(res) / (absk @ np.abs(x) + np.abs(rhs) + 1e-300))
            if omega < 1e-10:
                return x
            x = x + self._solve(res)
        raise RuntimeError(f"partitioned solve not accurate (backward error {omega:.1e})")

    def solution(self, r):
        rhs = self.rhs.copy()
        rhs[: self.ndof] += self.H.T @ r
        x = self.x_free.copy()
        x[self.bi] += self.XB @ r
        x[self.ii] = self.lu_ii.solve(rhs[self.ii] - self.K_IB @ x[self.bi])
        return self._refined(rhs, x)


class _SparseKKT:
    """SuperLU of [[A, C^T], [C, 0]], symmetrically equilibrated (primal columns by 1/sqrt(A_ii),
    multiplier rows by the inverse norm of the scaled C rows): element masses of short mixed-model
    elements span many decades."""

    def __init__(self, A, C):
        self.ndof = A.shape[0]
        d1 = 1.0 / np.sqrt(np.maximum(np.abs(A.diagonal()), 1e-300))
        Cs = sp.csr_matrix(C) @ sp.diags(d1)
        d2 = 1.0 / np.maximum(sp.linalg.norm(Cs, axis=1), 1e-300) if C.shape[0] else np.zeros(0)
        self.d = np.concatenate([d1, d2])
        D = sp.diags(self.d)
        K = sp.bmat([[A, C.T], [C, None]], format="csc") if C.shape[0] else sp.csc_matrix(A)
        self.lu = spla.splu((D @ K @ D).tocsc())

    def solve(self, b, c):
        rhs = np.concatenate([b, c])
        d = self.d if rhs.ndim == 1 else self.d[:, None]
        x = d * self.lu.solve(d * rhs)
        return x[: self.ndof], x[self.ndof :]


def _disk_disk(ca, ra, cb, rb) -> np.ndarray:
    d = ca - cb
    dist = np.linalg.norm(d, axis=1)
    n = d / np.maximum(dist, 1e-300)[:, None]
    return np.column_stack([np.zeros((len(ca), 2)), ca, cb, n, dist - ra - rb])


def contact_events(infos: list[StepInfo], min_speed: float = 1e-3, min_impulse: float = 1e-9):
    """(impacts, tracks) from step infos: an Impact when a body pair starts touching (total normal
    impulse > min_impulse after none) approaching faster than min_speed (m/s); one ContactTrack per
    body pair over all steps (normal force = sum r_N / h, slip speed = max |u_T| over the pair's
    active contacts, rolling speed 0). Raises JassyError on NaN/Inf."""
    if not infos:
        return [], []
    times = np.array([inf.time for inf in infos])
    h = np.diff(np.concatenate([[2 * times[0] - times[1] if len(times) > 1 else 0.0], times]))
    pairs = sorted({tuple(sorted(map(int, p))) for inf in infos for p in inf.bodies})
    force = {p: np.zeros(len(infos)) for p in pairs}
    slip = {p: np.zeros(len(infos)) for p in pairs}
    impacts, touching = [], set()
    for k, inf in enumerate(infos):
        now = {}
        for (a, b), r, u, uf in zip(inf.bodies.tolist(), inf.r, inf.u, inf.u_free, strict=True):
            p = (min(a, b), max(a, b))
            if r[0] > min_impulse:
                force[p][k] += r[0] / h[k]
                slip[p][k] = max(slip[p][k], abs(u[1]))
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
        if not (np.all(np.isfinite(force[p])) and np.all(np.isfinite(slip[p]))):
            raise JassyError(f"contact_events: non-finite contact track between bodies {p}")
        tracks.append(ContactTrack(p, times, force[p], slip[p], np.zeros(len(infos))))
    return impacts, tracks
