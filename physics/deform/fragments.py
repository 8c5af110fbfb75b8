"""Erodible tetrahedral particle solids that break into quasi-rigid fragments (Agus et al.,
VRIPHYS 2006, pp. 91-100: "particle simplices with connectivity").

A :class:`TetMesh` (model) holds particles and tetrahedra with their face neighbours. A face
of a live tet is *external* when no live tet shares it. A live tet with 1, 2 or 3 external
faces is removable (the paper's three removal primitives); removing it turns the faces it
shared into external faces of its neighbours and deletes the particles no live tet uses
any more (those it alone owned). Interior tets (0 external faces) cannot be removed, so a
tool eats the solid from its surface. Beyond the paper, a tet with 4 external faces (held
only through edges or vertices, or a lone one-tet fragment) is also removable: otherwise
such crumbs left by the tool keep the pieces on both sides of a groove connected.

Fragments are the connected components of the **shared-vertex** graph of the live tets
(scipy.sparse.csgraph.connected_components over the particles): every particle then belongs
to exactly one fragment, which shape matching needs; shared-face connectivity would leave
particles in two bodies (tets meeting at an edge or a vertex) unless vertices were split.
Each fragment is a quasi-rigid :class:`ShapeMatching` body (rest shape = the mesh's rest
positions of its particles). Fragments collide with boundaries (planes, the spherical
capsule bag) and with each other: particle spheres of radius r closer than 2r found with
scipy.spatial.cKDTree are pushed apart (mass-weighted) and get an inelastic normal impulse.
Contacts whose approach speed exceeds ``impact_speed`` become :class:`jassy.events.Impact`
events for sound (fragment ids >= 0; boundaries ``BAG`` = -1 and ``plane_id(k)`` = -2 - k).
Units: SI.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from itertools import permutations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from jassy.errors import JassyError
from jassy.events import Impact
from physics.deform.shape_matching import BodyState, Boundaries, ShapeMatching

_FACES = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]])  # face f is opposite vertex f


@dataclass(frozen=True)
class TetMesh:
    """Particles (n, 3) m and positively oriented tets (T, 4); ``neighbours[t, f]`` is the
    tet across the face opposite vertex f (-1 on the mesh boundary); ``volumes`` (T,) m^3."""

    points: np.ndarray
    tets: np.ndarray
    neighbours: np.ndarray = field(init=False, repr=False)
    volumes: np.ndarray = field(init=False, repr=False)

    def __post_init__(self):
        pts = np.asarray(self.points, dtype=np.float64)
        tets = np.array(self.tets, dtype=np.int64)
        if pts.ndim != 2 or pts.shape[1] != 3 or not np.all(np.isfinite(pts)):
            raise JassyError(f"TetMesh.points: expected a finite (n, 3) array, got shape {pts.shape}")
        if tets.ndim != 2 or tets.shape[1] != 4 or tets.shape[0] == 0:
            raise JassyError(f"TetMesh.tets: expected a (T, 4) integer array, got shape {tets.shape}")
        if tets.min() < 0 or tets.max() >= pts.shape[0]:
            raise JassyError(f"TetMesh.tets: expected indices in 0..{pts.shape[0] - 1}")
        vol = _signed_volumes(pts, tets)
        if np.any(np.abs(vol) <= 1e-14 * np.max(np.abs(vol))):
            raise JassyError("TetMesh.tets: expected non-degenerate tets (zero volume found)")
        neg = vol < 0
        tets[neg, 2], tets[neg, 3] = tets[neg, 3].copy(), tets[neg, 2].copy()
        faces = np.sort(tets[:, _FACES].reshape(-1, 3), axis=1)
        _, inv, cnt = np.unique(faces, axis=0, return_inverse=True, return_counts=True)
        if np.any(cnt > 2):
            raise JassyError("TetMesh.tets: a face is shared by more than two tets")
        order = np.argsort(inv, kind="stable")
        sinv = inv[order]
        pair = np.flatnonzero(sinv[1:] == sinv[:-1])
        nb = np.full(faces.shape[0], -1, dtype=np.int64)
        a, b = order[pair], order[pair + 1]
        nb[a], nb[b] = b // 4, a // 4
        object.__setattr__(self, "points", pts)
        object.__setattr__(self, "tets", tets)
        object.__setattr__(self, "neighbours", nb.reshape(-1, 4))
        object.__setattr__(self, "volumes", np.abs(vol))


def _signed_volumes(pts, tets):
    a, b, c, d = (pts[tets[:, k]] for k in range(4))
    return np.einsum("ij,ij->i", np.cross(b - a, c - a), d - a) / 6.0


def lattice_mesh(inside, lo, hi, spacing: float) -> TetMesh:
    """Tet mesh of the region ``inside(points (m, 3)) -> bool (m,)`` within the box lo..hi (m):
    a cube lattice of the given spacing (m), each cube split into the 6 Kuhn tets along its
    main diagonal (conforming across cubes); tets whose centroid is inside are kept."""
    lo, hi = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
    if (
        not (math.isfinite(spacing) and spacing > 0)
        or lo.shape != (3,)
        or hi.shape != (3,)
        or np.any(hi <= lo)
    ):
        raise JassyError("lattice_mesh: expected spacing > 0 (m) and a box lo < hi (3 coordinates each)")
    n = np.maximum(np.ceil((hi - lo) / spacing).astype(int), 1) + 1
    if np.prod(n) > 5_000_000:
        raise JassyError(f"spacing: {spacing!r} m gives {np.prod(n)} lattice points; expected <= 5e6")
    grid = np.stack(np.meshgrid(*[np.arange(k) for k in n], indexing="ij"), -1).reshape(-1, 3)
    pts = lo + grid * spacing
    idx = np.arange(np.prod(n)).reshape(n)
    corner = idx[:-1, :-1, :-1].ravel()
    strides = np.array([n[1] * n[2], n[2], 1])
    tets = []
    for a, b, _ in permutations(range(3)):
        ea, eb = strides[a], strides[b]
        tets.append(np.stack([corner, corner + ea, corner + ea + eb, corner + strides.sum()], 1))
    tets = np.concatenate(tets)
    keep = np.asarray(inside(pts[tets].mean(1)), dtype=bool)
    if not keep.any():
        raise JassyError("inside: no lattice tet has its centroid inside the region")
    tets = tets[keep]
    used, tets = np.unique(tets, return_inverse=True)
    return TetMesh(pts[used], tets.reshape(-1, 4))


def lens_mesh(radii=(4.5e-3, 4.5e-3, 2.0e-3), spacing: float = 0.6e-3, centre=(0.0, 0.0, 0.0)) -> TetMesh:
    """An ellipsoidal crystalline lens (semi-axes ``radii`` m, default 9 x 9 x 4 mm) as a
    Kuhn lattice tet mesh of the given spacing (m)."""
    r = np.asarray(radii, dtype=np.float64)
    c = np.asarray(centre, dtype=np.float64)
    if r.shape != (3,) or np.any(~(r > 0)):
        raise JassyError(f"radii: expected 3 semi-axes > 0 (m), got {radii!r}")
    return lattice_mesh(lambda p: (((p - c) / r) ** 2).sum(1) <= 1.0, c - r, c + r, spacing)


def external_faces(mesh: TetMesh, alive: np.ndarray) -> np.ndarray:
    """(T, 4) bool: face f of live tet t is external (no live tet across it)."""
    nb = mesh.neighbours
    across = np.where(nb >= 0, alive[np.maximum(nb, 0)], False)
    return alive[:, None] & ~across


def external_count(mesh: TetMesh, alive: np.ndarray) -> np.ndarray:
    """(T,) number of external faces of each live tet (0..4), -1 for removed tets."""
    return np.where(alive, external_faces(mesh, alive).sum(1), -1)


def fragment_labels(mesh: TetMesh, alive: np.ndarray):
    """Fragments of the live tets (shared-vertex connectivity).

    Returns (K, particle label (n,) in 0..K-1 or -1 for particles of no live tet, tet label
    (T,) or -1). Labels are ordered by each fragment's smallest particle index."""
    n = mesh.points.shape[0]
    t = mesh.tets[alive]
    rows = np.repeat(t[:, 0], 3)
    cols = t[:, 1:].ravel()
    graph = coo_matrix((np.ones(rows.size), (rows, cols)), shape=(n, n))
    _, lab = connected_components(graph, directed=False)
    used = np.zeros(n, dtype=bool)
    used[t.ravel()] = True
    first = np.full(lab.max() + 1, n)
    np.minimum.at(first, lab[used], np.flatnonzero(used))
    valid = np.flatnonzero(first < n)
    remap = np.full(lab.max() + 1, -1)
    remap[valid[np.argsort(first[valid])]] = np.arange(valid.size)
    plab = np.where(used, remap[lab], -1)
    tlab = np.full(mesh.tets.shape[0], -1)
    tlab[alive] = plab[t[:, 0]]
    return int(valid.size), plab, tlab


@dataclass(frozen=True)
class FragmentParams:
    """density (kg/m^3) -> lumped particle masses (each live tet gives rho V / 4 to each
    vertex); alpha (shape-matching stiffness, 0 < alpha <= 1); radius (m): particle collision
    radius (default: set by :class:`FragmentSim` to 0.4 x the mean edge length if None);
    restitution, friction (Coulomb, boundaries), viscosity (1/s); damping (0..1, share of
    the non-rigid velocity removed per step, see ShapeMatching); gravity (m/s^2);
    impact_speed (m/s): contacts approaching faster become Impact events (keep it above
    h |gravity|, the approach speed of a resting contact)."""

    density: float = 1100.0
    alpha: float = 1.0
    radius: float | None = None
    restitution: float = 0.2
    friction: float = 0.5
    viscosity: float = 1.0
    damping: float = 1.0
    gravity: tuple[float, float, float] = (0.0, 0.0, -9.81)
    impact_speed: float = 0.05

    def __post_init__(self):
        for name in ("density", "impact_speed"):
            val = getattr(self, name)
            if not (math.isfinite(val) and val > 0):
                raise JassyError(f"FragmentParams.{name}: expected a number > 0, got {val!r}")
        if self.radius is not None and not (math.isfinite(self.radius) and self.radius > 0):
            raise JassyError(f"FragmentParams.radius: expected a number > 0 (m) or None, got {self.radius!r}")


@dataclass
class FragmentState:
    """Live tets (T,) bool, particle positions x and velocities v (n, 3), particle masses
    (n,) kg (0 once removed), stable fragment ids (K,) per body, tets removed per primitive
    (index = number of external faces - 1, 0..3) and the time (s)."""

    alive: np.ndarray
    body: BodyState
    masses: np.ndarray
    fragment_ids: np.ndarray
    removed_by_kind: np.ndarray
    time: float = 0.0


class FragmentSim:
    """An erodible tet solid whose fragments move as quasi-rigid bodies (state mutated in
    place). ``boundaries``: :class:`Boundaries` (planes, spherical bag)."""

    def __init__(
        self, mesh: TetMesh, params: FragmentParams | None = None, boundaries: Boundaries | None = None
    ):
        self.mesh = mesh
        p = params or FragmentParams()
        if p.radius is None:
            edges = (
                mesh.points[mesh.tets[:, [0, 1, 2, 3, 0, 1]]] - mesh.points[mesh.tets[:, [1, 2, 3, 0, 2, 3]]]
            )
            p = FragmentParams(**{**p.__dict__, "radius": 0.4 * float(np.linalg.norm(edges, axis=2).mean())})
        self.params = p
        self.boundaries = boundaries or Boundaries()
        alive = np.ones(mesh.tets.shape[0], dtype=bool)
        n = mesh.points.shape[0]
        body = BodyState(mesh.points.copy(), np.zeros((n, 3)), np.zeros((0, 4)))
        self.state = FragmentState(alive, body, np.zeros(n), np.zeros(0, np.int64), np.zeros(4, np.int64))
        self._next_id = 0
        self.matcher: ShapeMatching
        self._rebuild()

    @property
    def n_fragments(self) -> int:
        return self.matcher.n_bodies

    def _rebuild(self):
        """Masses, fragments and the shape-matching model after a topology change; new bodies
        inherit their parent's rotation, and the largest child keeps the parent's id."""
        st, mesh = self.state, self.mesh
        m = np.zeros(mesh.points.shape[0])
        np.add.at(
            m, mesh.tets[st.alive].ravel(), np.repeat(self.params.density * mesh.volumes[st.alive] / 4, 4)
        )
        st.masses = m
        k, plab, _ = fragment_labels(mesh, st.alive)
        old = self.matcher.body if hasattr(self, "matcher") else None
        ids = np.empty(k, np.int64)
        quat = np.zeros((k, 4))
        quat[:, 0] = 1.0
        rep = np.full(k, -1)
        rep[plab[plab >= 0]] = np.flatnonzero(plab >= 0)
        sizes = np.bincount(plab[plab >= 0], minlength=k)
        parent = old[rep] if old is not None else np.full(k, -1)
        claimed = np.zeros(st.fragment_ids.size, dtype=bool)
        for b in np.argsort(-sizes, kind="stable"):
            pb = parent[b]
            if pb >= 0:
                quat[b] = st.body.quat[pb]
            if pb >= 0 and not claimed[pb]:
                ids[b] = st.fragment_ids[pb]
                claimed[pb] = True
            else:
                ids[b] = self._next_id
                self._next_id += 1
        st.fragment_ids = ids
        st.body.quat = quat
        st.body.v[plab < 0] = 0.0
        p = self.params
        msafe = np.where(m > 0, m, 1.0)
        self.matcher = ShapeMatching(
            mesh.points,
            msafe,
            plab,
            alpha=p.alpha,
            radius=p.radius,
            viscosity=p.viscosity,
            restitution=p.restitution,
            friction=p.friction,
            damping=p.damping,
        )

    def centroids(self) -> np.ndarray:
        """Current centroids (T, 3) m of all tets (removed ones included)."""
        return self.state.body.x[self.mesh.tets].mean(1)

    def remove(self, tets) -> np.ndarray:
        """Remove the given live tets at once (each must have 1..4 external faces now).
        Returns their number of external faces (the removal primitive used)."""
        st = self.state
        tets = np.unique(np.asarray(tets, dtype=np.int64))
        if tets.size == 0:
            return np.zeros(0, np.int64)
        if tets.min() < 0 or tets.max() >= self.mesh.tets.shape[0]:
            raise JassyError(f"tets: expected indices in 0..{self.mesh.tets.shape[0] - 1}")
        kinds = external_count(self.mesh, st.alive)[tets]
        if np.any(kinds < 1):
            bad = tets[kinds < 1]
            raise JassyError(
                f"tets: {bad.tolist()} are not removable (need a live tet with an external face)"
            )
        st.alive[tets] = False
        st.removed_by_kind += np.bincount(kinds - 1, minlength=4)
        self._rebuild()
        return kinds

    def erode(self, centre, radius: float, budget: int) -> np.ndarray:
        """The tool (a sphere, centre m, radius m) removes up to ``budget`` removable tets
        whose current centroid is inside it, nearest first (one surface layer per call).
        Returns the removed tet indices."""
        c = np.asarray(centre, dtype=np.float64)
        if c.shape != (3,) or not np.all(np.isfinite(c)):
            raise JassyError("centre: expected 3 finite coordinates (m)")
        if not (math.isfinite(radius) and radius > 0) or int(budget) < 0:
            raise JassyError("radius, budget: expected radius > 0 (m) and budget >= 0")
        kinds = external_count(self.mesh, self.state.alive)
        cand = np.flatnonzero(kinds >= 1)
        d = np.linalg.norm(self.centroids()[cand] - c, axis=1)
        inside = d < radius
        cand, d = cand[inside], d[inside]
        chosen = cand[np.argsort(d, kind="stable")[: int(budget)]]
        self.remove(chosen)
        return chosen

    def step(self, h: float, forces=None) -> list[Impact]:
        """Advance by h seconds: shape matching with gravity, boundaries, then fragment-
        fragment contacts. Returns the Impact events of this step."""
        st, p = self.state, self.params
        cont = self.matcher.step(st.body, h, forces, p.gravity, self.boundaries)
        pairs = self._collide()
        st.time += h
        x = st.body.x
        if not (np.all(np.isfinite(x)) and np.all(np.isfinite(st.body.v))):
            raise JassyError(
                "h: the fragment simulation went unstable (non-finite state); use a smaller step"
            )
        lab = self.matcher.body
        ids = st.fragment_ids
        a_ids = ids[lab[cont.particle]]
        impacts = _group(
            st.time,
            a_ids,
            cont.boundary,
            cont.particle,
            np.full_like(cont.particle, -1),
            cont.speed,
            cont.impulse,
            p.impact_speed,
        )
        i, j, speed, imp = pairs
        ai, bj = ids[lab[i]], ids[lab[j]]
        swap = ai > bj
        lo, hi = np.where(swap, bj, ai), np.where(swap, ai, bj)
        pi, pj = np.where(swap, j, i), np.where(swap, i, j)
        impacts += _group(st.time, lo, hi, pi, pj, speed, imp, p.impact_speed)
        return impacts

    def _collide(self):
        """Particle-sphere contacts between different fragments: mass-weighted position
        projection of the particles (averaged per particle) and, where the two bodies' rigid
        motions approach, a normal impulse on the bodies (translational effective mass,
        restitution, split evenly over a pair's contacts) changing each body's v_cm and
        omega. Goal corrections of resting fragments are not approach, so they make no
        impacts.
        Returns (i, j, approach speed m/s, impulse N s) per approaching pair."""
        st, r = self.state, self.params.radius
        live = self.matcher.order
        empty = (np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0), np.zeros(0))
        if self.n_fragments < 2:
            return empty
        x, v, m, lab = st.body.x, st.body.v, st.masses, self.matcher.body
        pr = cKDTree(x[live]).query_pairs(2 * r, output_type="ndarray")
        if pr.size == 0:
            return empty
        i, j = live[pr[:, 0]], live[pr[:, 1]]
        keep = lab[i] != lab[j]
        i, j = i[keep], j[keep]
        if i.size == 0:
            return empty
        d = x[j] - x[i]
        dist = np.linalg.norm(d, axis=1)
        nrm = d / np.maximum(dist, 1e-300)[:, None]
        cnt = np.bincount(np.concatenate([i, j]), minlength=x.shape[0]).astype(np.float64)
        wi, wj = m[j] / (m[i] + m[j]), m[i] / (m[i] + m[j])
        pen = (2 * r - dist)[:, None] * nrm
        dx = np.zeros_like(x)
        np.add.at(dx, i, -pen * wi[:, None])
        np.add.at(dx, j, pen * wj[:, None])
        vr = self.matcher.rigid_velocity(st.body)
        vn = np.einsum("ij,ij->i", vr[j] - vr[i], nrm)
        appr = vn < 0
        x += dx / np.maximum(cnt, 1.0)[:, None]
        i, j, vn, nrm = i[appr], j[appr], vn[appr], nrm[appr]
        if i.size == 0:
            return empty
        # body-level impulses: translational effective mass, averaged over each pair's contacts
        nb = self.n_fragments
        sim_p = self.matcher.order
        bm = np.bincount(lab[sim_p], weights=m[sim_p], minlength=nb)
        bc = np.stack(
            [np.bincount(lab[sim_p], weights=m[sim_p] * x[sim_p, a], minlength=nb) for a in range(3)], 1
        )
        bc /= bm[:, None]
        off = x[sim_p] - bc[lab[sim_p]]
        inertia = np.zeros((nb, 3, 3))
        np.add.at(
            inertia,
            lab[sim_p],
            m[sim_p, None, None]
            * (
                np.einsum("ij,ij->i", off, off)[:, None, None] * np.eye(3) - off[:, :, None] * off[:, None, :]
            ),
        )
        iinv = np.linalg.pinv(inertia)
        la, lb = lab[i], lab[j]
        _, pair, per_pair = np.unique(la * nb + lb, return_inverse=True, return_counts=True)
        jn = -(1 + self.params.restitution) * vn / (1 / bm[la] + 1 / bm[lb]) / per_pair[pair.ravel()]
        imp = jn[:, None] * nrm
        dp = np.zeros((nb, 3))
        dl = np.zeros((nb, 3))
        np.add.at(dp, la, -imp)
        np.add.at(dp, lb, imp)
        np.add.at(dl, la, -np.cross(x[i] - bc[la], imp))
        np.add.at(dl, lb, np.cross(x[j] - bc[lb], imp))
        dw = np.einsum("kab,kb->ka", iinv, dl)
        v[sim_p] += dp[lab[sim_p]] / bm[lab[sim_p], None] + np.cross(dw[lab[sim_p]], off)
        return i, j, -vn, jn


def _group(time, a, b, pa, pb, speed, impulse, threshold) -> list[Impact]:
    """One Impact per body pair (a, b) among contacts faster than ``threshold``: summed
    impulse, the largest speed and the particles of that fastest contact as locations. A
    pair whose impulses sum to zero (a boundary contact whose sequential-impulse solve left
    the work to the body's other contacts) transferred nothing and makes no Impact."""
    fast = speed > threshold
    if not fast.any():
        return []
    a, b, pa, pb, speed, impulse = a[fast], b[fast], pa[fast], pb[fast], speed[fast], impulse[fast]
    keys, inv = np.unique(np.stack([a, b], 1), axis=0, return_inverse=True)
    inv = inv.ravel()
    tot = np.bincount(inv, weights=impulse, minlength=keys.shape[0])
    order = np.lexsort((-speed, inv))
    first = order[np.r_[0, np.flatnonzero(np.diff(inv[order])) + 1]]
    out = []
    for g, k in enumerate(first):
        if tot[g] == 0.0:
            continue
        vals = (time, tot[g], speed[k])
        if not all(math.isfinite(float(val)) for val in vals):
            raise JassyError("impact: non-finite time, impulse or speed")
        loc_b = int(pb[k]) if pb[k] >= 0 else None
        out.append(
            Impact(
                float(time),
                (int(keys[g, 0]), int(keys[g, 1])),
                float(tot[g]),
                float(speed[k]),
                None,
                (int(pa[k]), loc_b),
            )
        )
    return out
