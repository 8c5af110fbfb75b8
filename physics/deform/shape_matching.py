"""Meshless shape matching (Mueller, Heidelberger, Teschner & Gross 2005) with Horn's rotation.

The best rigid fit of a body's rest offsets q_i = x0_i - c0 to its current offsets
p_i = x_i - c is taken from Horn's closed-form absolute orientation (J. Opt. Soc. Am. A
4(4):629, 1987): the unit quaternion is the eigenvector of the largest eigenvalue of a
symmetric 4x4 matrix N built from S_ab = sum_i w_i q_ia p_ib. It is always a proper rotation
(no polar decomposition, no reflection fix) and stays defined for fragments of 1, 2 or 3
particles, where Mueller's A_pq is singular:

* 1 particle (or all offsets zero): N = 0, every rotation is optimal -> the prior rotation;
* 2 or collinear particles: the largest eigenvalue is double (spin about the line is free)
  -> the optimal rotation nearest the prior (geodesic angle), i.e. the prior quaternion
  projected on the top eigenspace and normalised;
* coplanar particles (e.g. 3): the rotation is unique and Horn returns it directly.

The prior is the body's rotation at the previous step (identity initially), so degenerate
fragments neither jump nor spin. Eigenvalues within ``tol * max|lambda|`` of the largest are
treated as one eigenspace.

Dynamics (one step of length h, per particle, Mueller 2005 eq. 3.3): goals
g_i = T q_i + c with T = R (rigid), beta A + (1 - beta) R (linear, A = A_pq A_qq normalised to
det 1), or the 3x9 quadratic analogue; then (after optional rigid-velocity damping)
v_i += alpha (g_i - x_i)/h + h f_i/m_i + h gravity, v_i /= 1 + h viscosity, x_i += h v_i.
Particles are then projected out of the boundaries (planes, inside of a spherical bag),
and contact impulses (restitution, Coulomb friction; sequential impulses) act on each
body's rigid motion, its mass and inertia about its centre: a particle-level velocity fix
would support a body only through the 1/N share of one particle in the goal fit, leaving
resting bodies sagging into the boundary. In rigid mode the
goal term conserves linear and angular momentum exactly. Units: SI.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property
from typing import NamedTuple

import numba
import numpy as np

from jassy.errors import JassyError

MODES = ("rigid", "linear", "quadratic")
BIAS = 0.2  # Baumgarte factor of the contact solve: share of a penetration removed per step
BAG = -1  # boundary id of the spherical bag; plane k has id plane_id(k) = -2 - k


def plane_id(k: int) -> int:
    """Boundary id of plane ``k`` (negative, so it never clashes with a body id >= 0)."""
    return -2 - k


class Model(NamedTuple):
    """The kernels' view of a :class:`ShapeMatching` (static arrays)."""

    masses: np.ndarray  #: (n,) particle masses (kg)
    body: np.ndarray  #: (n,) body index per particle (-1: not simulated)
    order: np.ndarray  #: simulated particles grouped by body
    starts: np.ndarray  #: (K + 1,) body b owns order[starts[b]:starts[b + 1]]
    qrest: np.ndarray  #: (n, 3) rest offsets from the body's rest centre of mass (m)
    q9: np.ndarray  #: (n, 9) quadratic terms of qrest
    aqq: np.ndarray  #: (K, 3, 3) inverse of A_qq per body (linear mode)
    aqq9: np.ndarray  #: (K, 9, 9) pseudo-inverse of the quadratic A~qq per body


class Fit(NamedTuple):
    """Options of the goal fit."""

    mode: int  #: index in MODES
    beta: float  #: share of the linear / quadratic deformation in the goals
    tol: float  #: relative tolerance of a multiple top eigenvalue in Horn's fit


class Motion(NamedTuple):
    """Options of the velocity / position update."""

    gravity: np.ndarray  #: (3,) m/s^2
    alpha: float  #: stiffness in (0, 1]: share of the way to the goals per step
    h: float  #: step (s)
    viscosity: float  #: drag (1/s)
    radius: float  #: particle radius against the boundaries (m)


class Walls(NamedTuple):
    """Boundaries as arrays: planes (P, 4) rows (unit n, d); bag (centre x, y, z, radius)."""

    planes: np.ndarray
    bag: np.ndarray


class ContactRows(NamedTuple):
    """Boundary contacts of a step, grouped by body (capacity: particles x boundaries)."""

    particle: np.ndarray  #: int64 particle index
    boundary: np.ndarray  #: int64 boundary id (< 0)
    normal: np.ndarray  #: (cap, 3) unit normal into the allowed side
    speed: np.ndarray  #: approach speed of the body's motion (m/s, >= 0)
    depth: np.ndarray  #: penetration removed by the projection (m)


class Impulses(NamedTuple):
    """Options of the contact impulse solve."""

    restitution: float  #: in [0, 1]
    friction: float  #: Coulomb coefficient mu
    iterations: int  #: sequential-impulse sweeps
    bias: float  #: Baumgarte share of a penetration removed per step
    h: float  #: step (s)


@numba.njit(cache=True)
def _quat_matrix(q, out):
    w, x, y, z = q[0], q[1], q[2], q[3]
    out[0, 0] = 1 - 2 * (y * y + z * z)
    out[0, 1] = 2 * (x * y - w * z)
    out[0, 2] = 2 * (x * z + w * y)
    out[1, 0] = 2 * (x * y + w * z)
    out[1, 1] = 1 - 2 * (x * x + z * z)
    out[1, 2] = 2 * (y * z - w * x)
    out[2, 0] = 2 * (x * z - w * y)
    out[2, 1] = 2 * (y * z + w * x)
    out[2, 2] = 1 - 2 * (x * x + y * y)


@numba.njit(cache=True)
def _horn_quat(S, prior, tol, out):
    """Unit quaternion (w, x, y, z) of the rotation maximising sum w_i (R q_i) . p_i, given
    S_ab = sum w_i q_ia p_ib; nearest to ``prior`` when the optimum is not unique."""
    sxx, sxy, sxz = S[0, 0], S[0, 1], S[0, 2]
    syx, syy, syz = S[1, 0], S[1, 1], S[1, 2]
    szx, szy, szz = S[2, 0], S[2, 1], S[2, 2]
    N = np.empty((4, 4))
    N[0, 0] = sxx + syy + szz
    N[0, 1] = syz - szy
    N[0, 2] = szx - sxz
    N[0, 3] = sxy - syx
    N[1, 1] = sxx - syy - szz
    N[1, 2] = sxy + syx
    N[1, 3] = szx + sxz
    N[2, 2] = -sxx + syy - szz
    N[2, 3] = syz + szy
    N[3, 3] = -sxx - syy + szz
    for i in range(4):
        for j in range(i):
            N[i, j] = N[j, i]
    scale = 0.0
    for i in range(4):
        for j in range(4):
            scale = max(scale, abs(N[i, j]))
    if scale == 0.0:
        out[:] = prior
        return
    lam, vec = np.linalg.eigh(N)
    top = lam[3]
    thresh = top - tol * max(abs(lam[0]), abs(top))
    proj = np.zeros(4)
    for k in range(4):
        if lam[k] >= thresh:
            d = vec[0, k] * prior[0] + vec[1, k] * prior[1] + vec[2, k] * prior[2] + vec[3, k] * prior[3]
            for a in range(4):
                proj[a] += d * vec[a, k]
    norm = math.sqrt(proj[0] ** 2 + proj[1] ** 2 + proj[2] ** 2 + proj[3] ** 2)
    if norm < 1e-6:
        for a in range(4):
            proj[a] = vec[a, 3]
        norm = 1.0
    sgn = (
        1.0
        if proj[0] * prior[0] + proj[1] * prior[1] + proj[2] * prior[2] + proj[3] * prior[3] >= 0
        else -1.0
    )
    for a in range(4):
        out[a] = sgn * proj[a] / norm


@numba.njit(cache=True)
def _horn_batch(src, dst, w, starts, prior, tol, quat, rot):
    S = np.empty((3, 3))
    for b in range(starts.size - 1):
        lo, hi = starts[b], starts[b + 1]
        W = 0.0
        cs = np.zeros(3)
        cd = np.zeros(3)
        for i in range(lo, hi):
            W += w[i]
            for a in range(3):
                cs[a] += w[i] * src[i, a]
                cd[a] += w[i] * dst[i, a]
        if W > 0:
            cs /= W
            cd /= W
        S[:, :] = 0.0
        for i in range(lo, hi):
            for a in range(3):
                for c in range(3):
                    S[a, c] += w[i] * (src[i, a] - cs[a]) * (dst[i, c] - cd[c])
        _horn_quat(S, prior[b], tol, quat[b])
        _quat_matrix(quat[b], rot[b])


def _check_points(name, a):
    a = np.asarray(a, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] != 3 or a.shape[0] == 0 or not np.all(np.isfinite(a)):
        raise JassyError(f"{name}: expected a finite (n, 3) array with n >= 1, got shape {a.shape}")
    return np.ascontiguousarray(a)


def _check_weights(w, n):
    w = np.ones(n) if w is None else np.asarray(w, dtype=np.float64)
    if w.shape != (n,) or not np.all(np.isfinite(w)) or np.any(w < 0) or not np.any(w > 0):
        raise JassyError(f"w: expected {n} finite weights >= 0, not all zero")
    return np.ascontiguousarray(w)


def _check_prior(prior, k):
    if prior is None:
        out = np.zeros((k, 4))
        out[:, 0] = 1.0
        return out
    out = np.array(prior, dtype=np.float64).reshape(-1, 4)
    nrm = np.linalg.norm(out, axis=1)
    if out.shape[0] != k or not np.all(np.isfinite(out)) or np.any(nrm == 0):
        raise JassyError(f"prior: expected {k} nonzero quaternions (w, x, y, z)")
    return out / nrm[:, None]


def horn_rotations(p, q, w=None, starts=None, prior=None, tol: float = 1e-9):
    """Horn rotations of many point sets at once (numba, one eigen-solve per set).

    Set b is rows ``starts[b]:starts[b+1]`` of p (source) and q (destination), (n, 3) in m;
    each set is centred about its own weighted centroid. Returns (quaternions (K, 4) as
    (w, x, y, z), rotations (K, 3, 3)) with R_b minimising sum_i w_i |R_b p_i - q_i|^2.
    ``prior`` (K, 4): the rotations chosen when a set does not determine one (see module doc).
    """
    p, q = _check_points("p", p), _check_points("q", q)
    if p.shape != q.shape:
        raise JassyError(f"q: expected the shape of p {p.shape}, got {q.shape}")
    w = _check_weights(w, p.shape[0])
    starts = np.array([0, p.shape[0]] if starts is None else starts, dtype=np.int64)
    if (
        starts.ndim != 1
        or starts.size < 2
        or starts[0] != 0
        or starts[-1] != p.shape[0]
        or np.any(np.diff(starts) < 0)
    ):
        raise JassyError(f"starts: expected non-decreasing offsets from 0 to {p.shape[0]}")
    k = starts.size - 1
    pri = _check_prior(prior, k)
    quat = np.empty((k, 4))
    rot = np.empty((k, 3, 3))
    _horn_batch(p, q, w, starts, pri, float(tol), quat, rot)
    return quat, rot


def horn_rotation(p, q, w=None, prior=None, tol: float = 1e-9) -> np.ndarray:
    """Proper rotation R (3, 3) minimising sum_i w_i |R p_i - q_i|^2 (Horn 1987).

    p, q: (n, 3) point sets in m, centred here about their weighted centroids; w: (n,)
    weights >= 0 (default 1). With 1 particle, 2 particles or collinear sets the rotation
    is not unique and the optimal one nearest ``prior`` (a quaternion (w, x, y, z), default
    identity) is returned; coplanar sets give the unique optimum.
    """
    return horn_rotations(p, q, w, None, None if prior is None else [prior], tol)[1][0]


def _quadratic_terms(q):
    x, y, z = q[:, 0], q[:, 1], q[:, 2]
    return np.stack([x, y, z, x * x, y * y, z * z, x * y, y * z, z * x], axis=1)


@numba.njit(cache=True)
def _goals(x, model, fit, prior, goal, quat, rot):
    """Goal positions (goal), Horn rotations (quat, rot matrices) of every body at positions
    x, from the body's rotations ``prior``."""
    m, _, order, starts, qrest, q9, aqq, aqq9 = model
    mode, beta, tol = fit
    S = np.empty((3, 3))
    apq = np.empty((3, 3))
    apq9 = np.empty((3, 9))
    T = np.empty((3, 3))
    T9 = np.empty((3, 9))
    c = np.empty(3)
    for b in range(starts.size - 1):
        lo, hi = starts[b], starts[b + 1]
        M = 0.0
        c[:] = 0.0
        for k in range(lo, hi):
            i = order[k]
            M += m[i]
            for a in range(3):
                c[a] += m[i] * x[i, a]
        c /= M
        S[:, :] = 0.0
        for k in range(lo, hi):
            i = order[k]
            for a in range(3):
                for e in range(3):
                    S[a, e] += m[i] * qrest[i, a] * (x[i, e] - c[e])
        _horn_quat(S, prior[b], tol, quat[b])
        _quat_matrix(quat[b], rot[b])
        R = rot[b]
        if mode == 1:
            for a in range(3):
                for e in range(3):
                    apq[a, e] = S[e, a]
            A = apq @ aqq[b]
            det = np.linalg.det(A)
            if det > 1e-12:
                s = det ** (1.0 / 3.0)
                for a in range(3):
                    for e in range(3):
                        T[a, e] = beta * A[a, e] / s + (1 - beta) * R[a, e]
            else:
                T[:, :] = R
            for k in range(lo, hi):
                i = order[k]
                for a in range(3):
                    goal[i, a] = c[a] + T[a, 0] * qrest[i, 0] + T[a, 1] * qrest[i, 1] + T[a, 2] * qrest[i, 2]
        elif mode == 2:
            apq9[:, :] = 0.0
            for k in range(lo, hi):
                i = order[k]
                for a in range(3):
                    for e in range(9):
                        apq9[a, e] += m[i] * (x[i, a] - c[a]) * q9[i, e]
            A9 = apq9 @ aqq9[b]
            for a in range(3):
                for e in range(9):
                    T9[a, e] = beta * A9[a, e] + (1 - beta) * (R[a, e] if e < 3 else 0.0)
            for k in range(lo, hi):
                i = order[k]
                for a in range(3):
                    s = c[a]
                    for e in range(9):
                        s += T9[a, e] * q9[i, e]
                    goal[i, a] = s
        else:
            for k in range(lo, hi):
                i = order[k]
                for a in range(3):
                    goal[i, a] = c[a] + R[a, 0] * qrest[i, 0] + R[a, 1] * qrest[i, 1] + R[a, 2] * qrest[i, 2]


@numba.njit(cache=True)
def _body_moments(x, v, m, order, lo, hi, c, vc, L, inertia):
    """Mass (kg) of the particles order[lo:hi]; fills their centre of mass c, mean velocity
    vc, angular momentum L about c and inertia tensor about c."""
    M = 0.0
    c[:] = 0.0
    vc[:] = 0.0
    for j in range(lo, hi):
        i = order[j]
        M += m[i]
        for a in range(3):
            c[a] += m[i] * x[i, a]
            vc[a] += m[i] * v[i, a]
    c /= M
    vc /= M
    L[:] = 0.0
    inertia[:, :] = 0.0
    for j in range(lo, hi):
        i = order[j]
        r0, r1, r2 = x[i, 0] - c[0], x[i, 1] - c[1], x[i, 2] - c[2]
        L[0] += m[i] * (r1 * v[i, 2] - r2 * v[i, 1])
        L[1] += m[i] * (r2 * v[i, 0] - r0 * v[i, 2])
        L[2] += m[i] * (r0 * v[i, 1] - r1 * v[i, 0])
        rr = r0 * r0 + r1 * r1 + r2 * r2
        inertia[0, 0] += m[i] * (rr - r0 * r0)
        inertia[1, 1] += m[i] * (rr - r1 * r1)
        inertia[2, 2] += m[i] * (rr - r2 * r2)
        inertia[0, 1] -= m[i] * r0 * r1
        inertia[0, 2] -= m[i] * r0 * r2
        inertia[1, 2] -= m[i] * r1 * r2
    inertia[1, 0] = inertia[0, 1]
    inertia[2, 0] = inertia[0, 2]
    inertia[2, 1] = inertia[1, 2]
    return M


@numba.njit(cache=True)
def _damp_rigid(x, v, m, order, starts, k):
    """v_i += k (v_rigid,i - v_i) per body, v_rigid = v_cm + w x r_i with w = I^+ L: removes
    the non-rigid part of the velocity, keeping linear and angular momentum."""
    c = np.empty(3)
    vc = np.empty(3)
    L = np.empty(3)
    inertia = np.empty((3, 3))
    for b in range(starts.size - 1):
        lo, hi = starts[b], starts[b + 1]
        _body_moments(x, v, m, order, lo, hi, c, vc, L, inertia)
        w = np.linalg.pinv(inertia) @ L
        for j in range(lo, hi):
            i = order[j]
            r0, r1, r2 = x[i, 0] - c[0], x[i, 1] - c[1], x[i, 2] - c[2]
            v[i, 0] += k * (vc[0] + w[1] * r2 - w[2] * r1 - v[i, 0])
            v[i, 1] += k * (vc[1] + w[2] * r0 - w[0] * r2 - v[i, 1])
            v[i, 2] += k * (vc[2] + w[0] * r1 - w[1] * r0 - v[i, 2])


@numba.njit(cache=True)
def _advance(x, v, model, goal, f, opt, walls, rows):
    """Mueller's velocity/position update (opt: a Motion), then projection of the particles
    out of the boundaries (walls). Contacts (particle, boundary id, unit normal into the
    allowed side, approach speed m/s, depth) go to ``rows`` grouped by body; returns their
    count. The approach speed is that of the particle's velocity without the shape-restoring
    term (the body's motion), so a body resting on a boundary reports about h |gravity|, not
    its goal corrections."""
    m, order = model.masses, model.order
    gravity, alpha, h, visc, radius = opt
    planes, bag = walls
    cid, cbody, cn, cvn, cdep = rows
    damp = 1.0 / (1.0 + h * visc)
    vphys = np.empty(3)
    nc = 0
    for k in range(order.size):
        i = order[k]
        for a in range(3):
            vphys[a] = (v[i, a] + h * (f[i, a] / m[i] + gravity[a])) * damp
            v[i, a] = vphys[a] + alpha * (goal[i, a] - x[i, a]) / h * damp
            x[i, a] += h * v[i, a]
        for j in range(planes.shape[0] + 1):
            if j < planes.shape[0]:
                n0, n1, n2 = planes[j, 0], planes[j, 1], planes[j, 2]
                gap = n0 * x[i, 0] + n1 * x[i, 1] + n2 * x[i, 2] - planes[j, 3] - radius
                bid = -2 - j
            else:
                if bag[3] <= 0:
                    continue
                d0, d1, d2 = x[i, 0] - bag[0], x[i, 1] - bag[1], x[i, 2] - bag[2]
                r = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
                if r == 0.0:
                    continue
                n0, n1, n2 = -d0 / r, -d1 / r, -d2 / r
                gap = bag[3] - radius - r
                bid = -1
            if gap >= 0:
                continue
            x[i, 0] -= gap * n0
            x[i, 1] -= gap * n1
            x[i, 2] -= gap * n2
            cid[nc] = i
            cbody[nc] = bid
            cn[nc, 0], cn[nc, 1], cn[nc, 2] = n0, n1, n2
            cvn[nc] = max(0.0, -(vphys[0] * n0 + vphys[1] * n1 + vphys[2] * n2))
            cdep[nc] = -gap
            nc += 1
    return nc


@numba.njit(cache=True)
def _cross(a, b, out):
    out[0] = a[1] * b[2] - a[2] * b[1]
    out[1] = a[2] * b[0] - a[0] * b[2]
    out[2] = a[0] * b[1] - a[1] * b[0]


@numba.njit(cache=True)
def _first_contacts(body, cid, nc, nb):
    """first[b]: the first of the nc contact rows (sorted by body) on body b or after it;
    first[nb] = nc, so body b's rows are first[b]:first[b + 1]."""
    first = np.full(nb + 1, nc)
    for k in range(nc - 1, -1, -1):
        first[body[cid[k]]] = k
    for b in range(nb - 1, -1, -1):
        first[b] = min(first[b], first[b + 1])
    return first


@numba.njit(cache=True)
def _slip(vc, w, r, n, vrel, t):
    """The tangential slip speed (m/s) of the contact point at arm ``r`` (from the centre of
    mass; body velocity vc, angular velocity w) over normal ``n``; its unit direction is left
    in ``t`` (vrel: scratch, the point's velocity)."""
    _cross(w, r, t)
    for a in range(3):
        vrel[a] = vc[a] + t[a]
    vn = vrel[0] * n[0] + vrel[1] * n[1] + vrel[2] * n[2]
    for a in range(3):
        t[a] = vrel[a] - vn * n[a]
    st = math.sqrt(t[0] * t[0] + t[1] * t[1] + t[2] * t[2])
    if st != 0:
        for a in range(3):
            t[a] /= st
    return st


@numba.njit(cache=True)
def _add_rigid_motion(x, v, particles, c, dv, dw, arm, turn):
    """Add a rigid velocity change (dv at the centre c, angular dw) to the ``particles``
    (arm, turn: (3,) scratch, a particle's arm from c and dw x arm)."""
    for i in particles:
        for a in range(3):
            arm[a] = x[i, a] - c[a]
        _cross(dw, arm, turn)
        for a in range(3):
            v[i, a] += dv[a] + turn[a]


@numba.njit(cache=True)
def _contact_impulses(x, v, model, rows, nc, opt, cimp):
    """Sequential impulses on each body's rigid motion (mass M, inertia about its centre)
    at its first nc contacts (rows): normal impulses >= 0 stop approach (restitution),
    Coulomb friction bounds the tangential ones by mu x normal; the resulting change of v_cm
    and omega is added to every particle of the body. The target separation speed is at
    least bias x depth / h (Baumgarte), which lifts the rigid pose out of a penetration the
    particle projection alone would leave (the goal fit pulls projected particles back).
    opt: an Impulses. Normal impulse per contact -> cimp (N s)."""
    m, body, starts, order = model.masses, model.body, model.starts, model.order
    cid, cn, cdep = rows.particle, rows.normal, rows.depth
    rest, mu, iters, bias, h = opt
    nb = starts.size - 1
    first = _first_contacts(body, cid, nc, nb)
    c = np.empty(3)
    vc = np.empty(3)
    L = np.empty(3)
    inertia = np.zeros((3, 3))
    lam_t = np.zeros((nc, 3))
    target = np.zeros(nc)
    r = np.empty((nc, 3))
    rn = np.empty((nc, 3))
    irn = np.empty((nc, 3))
    kn = np.empty(nc)
    tmp = np.empty(3)
    rt = np.empty(3)
    vrel = np.empty(3)
    old = np.empty(3)
    for k in range(nc):
        cimp[k] = 0.0
    for b in range(nb):
        lo, hi = first[b], first[b + 1]
        if lo >= hi:
            continue
        M = _body_moments(x, v, m, order, starts[b], starts[b + 1], c, vc, L, inertia)
        iinv = np.linalg.pinv(inertia)
        w = iinv @ L
        w0 = w.copy()
        v0 = vc.copy()
        for k in range(lo, hi):
            for a in range(3):
                r[k, a] = x[cid[k], a] - c[a]
            _cross(r[k], cn[k], rn[k])
            for a in range(3):
                irn[k, a] = iinv[a, 0] * rn[k, 0] + iinv[a, 1] * rn[k, 1] + iinv[a, 2] * rn[k, 2]
            kn[k] = 1.0 / M + rn[k, 0] * irn[k, 0] + rn[k, 1] * irn[k, 1] + rn[k, 2] * irn[k, 2]
            _cross(w, r[k], tmp)
            vn = (vc[0] + tmp[0]) * cn[k, 0] + (vc[1] + tmp[1]) * cn[k, 1] + (vc[2] + tmp[2]) * cn[k, 2]
            target[k] = max(-rest * vn if vn < 0 else 0.0, bias * cdep[k] / h)
        for _ in range(iters):
            for k in range(lo, hi):
                _cross(w, r[k], tmp)
                for a in range(3):
                    vrel[a] = vc[a] + tmp[a]
                vn = vrel[0] * cn[k, 0] + vrel[1] * cn[k, 1] + vrel[2] * cn[k, 2]
                new = max(0.0, cimp[k] + (target[k] - vn) / kn[k])
                dl = new - cimp[k]
                cimp[k] = new
                for a in range(3):
                    vc[a] += dl * cn[k, a] / M
                    w[a] += dl * irn[k, a]
                if mu <= 0:
                    continue
                st = _slip(vc, w, r[k], cn[k], vrel, tmp)
                if st == 0:
                    continue
                _cross(r[k], tmp, rt)
                kt = 1.0 / M
                for a in range(3):
                    kt += rt[a] * (iinv[a, 0] * rt[0] + iinv[a, 1] * rt[1] + iinv[a, 2] * rt[2])
                nn = 0.0
                for a in range(3):
                    old[a] = lam_t[k, a]
                    lam_t[k, a] -= st / kt * tmp[a]
                    nn += lam_t[k, a] * lam_t[k, a]
                nn = math.sqrt(nn)
                cap = mu * cimp[k]
                if nn > cap:
                    for a in range(3):
                        lam_t[k, a] *= cap / nn
                for a in range(3):
                    tmp[a] = lam_t[k, a] - old[a]
                    vc[a] += tmp[a] / M
                _cross(r[k], tmp, rt)
                for a in range(3):
                    w[a] += iinv[a, 0] * rt[0] + iinv[a, 1] * rt[1] + iinv[a, 2] * rt[2]
        _add_rigid_motion(x, v, order[starts[b] : starts[b + 1]], c, vc - v0, w - w0, tmp, rt)


@dataclass(frozen=True)
class Boundaries:
    """Static obstacles: planes (P, 4) rows (n, d) with unit n, allowed side n.x >= d; and a
    spherical bag (centre (3,), radius m; radius 0 = none) whose inside is allowed.
    Boundary ids in contacts: the bag is ``BAG`` (-1), plane k is ``plane_id(k)``."""

    planes: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))
    bag_centre: tuple[float, float, float] = (0.0, 0.0, 0.0)
    bag_radius: float = 0.0

    def __post_init__(self):
        pl = np.array(self.planes, dtype=np.float64).reshape(-1, 4)
        nrm = np.linalg.norm(pl[:, :3], axis=1)
        if not np.all(np.isfinite(pl)) or np.any(nrm == 0):
            raise JassyError("Boundaries.planes: expected finite rows (nx, ny, nz, d) with n != 0")
        pl = pl / nrm[:, None]
        object.__setattr__(self, "planes", pl)
        if not (math.isfinite(self.bag_radius) and self.bag_radius >= 0):
            raise JassyError(f"Boundaries.bag_radius: expected a number >= 0 (m), got {self.bag_radius!r}")
        if not np.all(np.isfinite(self.bag_centre)) or len(self.bag_centre) != 3:
            raise JassyError("Boundaries.bag_centre: expected 3 finite coordinates (m)")

    def packed(self) -> np.ndarray:
        return np.array([*self.bag_centre, self.bag_radius], dtype=np.float64)


@dataclass
class BodyState:
    """Positions x (n, 3) m, velocities v (n, 3) m/s, the bodies' rotations ``quat`` (K, 4)
    (w, x, y, z; the priors of the next Horn fit) and the time (s)."""

    x: np.ndarray
    v: np.ndarray
    quat: np.ndarray
    time: float = 0.0


@dataclass(frozen=True)
class Contacts:
    """Boundary contacts of one step: particle index, boundary id (<0), approach speed (m/s,
    >= 0, the body's motion at the particle) and the normal impulse solved there (N s)."""

    particle: np.ndarray
    boundary: np.ndarray
    speed: np.ndarray
    impulse: np.ndarray


@dataclass(frozen=True)
class ShapeMatching:
    """Quasi-rigid bodies sharing one particle array (model; immutable).

    rest (n, 3) m; masses (n,) kg; body (n,) body index per particle (0..K-1, or -1 for a
    particle that is not simulated); alpha in (0, 1] (1 = snap to the goals each step);
    mode "rigid" | "linear" | "quadratic" with beta in [0, 1]; radius (m) of the particles
    against boundaries; viscosity (1/s) drag; restitution in [0, 1]; friction >= 0;
    damping in [0, 1]: fraction of each body's non-rigid velocity removed per step before the
    goal term (Mueller et al. 2007, PBD sec. 3.5; momentum-conserving). Without it (0) the
    non-rigid velocity left by collisions oscillates undamped (alpha = 1 is stable, not
    dissipative); quasi-rigid fragments use 1. iterations: sequential-impulse sweeps over
    each body's contacts per step.
    Linear mode falls back to the rotation for a body whose A has det <= 0 (fewer than 4
    non-coplanar particles); quadratic mode uses the pseudo-inverse of the 9x9 A~qq.
    """

    rest: np.ndarray
    masses: np.ndarray
    body: np.ndarray
    alpha: float = 1.0
    mode: str = "rigid"
    beta: float = 0.0
    radius: float = 0.0
    viscosity: float = 0.0
    restitution: float = 0.0
    friction: float = 0.5
    damping: float = 0.0
    iterations: int = 8
    order: np.ndarray = field(init=False, repr=False)
    starts: np.ndarray = field(init=False, repr=False)
    qrest: np.ndarray = field(init=False, repr=False)
    q9: np.ndarray = field(init=False, repr=False)
    aqq: np.ndarray = field(init=False, repr=False)
    aqq9: np.ndarray = field(init=False, repr=False)

    def __post_init__(self):
        rest = _check_points("ShapeMatching.rest", self.rest)
        n = rest.shape[0]
        m = np.asarray(self.masses, dtype=np.float64)
        if m.shape != (n,) or not np.all(np.isfinite(m)) or np.any(m <= 0):
            raise JassyError(f"ShapeMatching.masses: expected {n} masses > 0 (kg)")
        body = np.asarray(self.body)
        if body.shape != (n,) or not np.issubdtype(body.dtype, np.integer) or np.any(body < -1):
            raise JassyError(f"ShapeMatching.body: expected {n} integer body indices >= -1")
        body = body.astype(np.int64)
        nb = int(body.max()) + 1 if n else 0
        counts = np.bincount(body[body >= 0], minlength=nb)
        if np.any(counts == 0):
            raise JassyError("ShapeMatching.body: expected body indices 0..K-1 each used at least once")
        if not (0 < self.alpha <= 1):
            raise JassyError(f"ShapeMatching.alpha: expected 0 < alpha <= 1, got {self.alpha!r}")
        if self.mode not in MODES:
            raise JassyError(f"ShapeMatching.mode: expected one of {MODES}, got {self.mode!r}")
        if not (0 <= self.beta <= 1):
            raise JassyError(f"ShapeMatching.beta: expected 0 <= beta <= 1, got {self.beta!r}")
        for name in ("radius", "viscosity", "friction"):
            val = getattr(self, name)
            if not (math.isfinite(val) and val >= 0):
                raise JassyError(f"ShapeMatching.{name}: expected a number >= 0, got {val!r}")
        if not (0 <= self.damping <= 1):
            raise JassyError(f"ShapeMatching.damping: expected 0..1, got {self.damping!r}")
        if int(self.iterations) < 1:
            raise JassyError(f"ShapeMatching.iterations: expected an integer >= 1, got {self.iterations!r}")
        if not (0 <= self.restitution <= 1):
            raise JassyError(f"ShapeMatching.restitution: expected 0..1, got {self.restitution!r}")
        sim = np.flatnonzero(body >= 0)
        order = sim[np.argsort(body[sim], kind="stable")]
        starts = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        seg = body[order]
        mo = m[order]
        mass = np.bincount(seg, weights=mo, minlength=nb)
        c0 = np.stack([np.bincount(seg, weights=mo * rest[order, a], minlength=nb) for a in range(3)], 1)
        c0 /= mass[:, None]
        qrest = np.zeros_like(rest)
        qrest[order] = rest[order] - c0[seg]
        q9 = _quadratic_terms(qrest)
        aqq = np.zeros((nb, 3, 3))
        aqq9 = np.zeros((nb, 9, 9))
        if self.mode == "linear":
            np.add.at(aqq, seg, mo[:, None, None] * qrest[order, :, None] * qrest[order, None, :])
            aqq = np.linalg.pinv(aqq)
        elif self.mode == "quadratic":
            np.add.at(aqq9, seg, mo[:, None, None] * q9[order, :, None] * q9[order, None, :])
            aqq9 = np.linalg.pinv(aqq9)
        for name, val in [
            ("rest", rest),
            ("masses", m),
            ("body", body),
            ("order", order),
            ("starts", starts),
            ("qrest", qrest),
            ("q9", q9),
            ("aqq", aqq),
            ("aqq9", aqq9),
        ]:
            object.__setattr__(self, name, val)

    @property
    def n_bodies(self) -> int:
        return self.starts.size - 1

    @cached_property
    def model(self) -> Model:
        """The arrays the kernels read (built once)."""
        return Model(
            self.masses, self.body, self.order, self.starts, self.qrest, self.q9, self.aqq, self.aqq9
        )

    def initial_state(self, x=None, v=None, quat=None) -> BodyState:
        """State at rest positions (or ``x``), zero (or ``v``) velocity, identity rotations."""
        n = self.rest.shape[0]
        x = self.rest.copy() if x is None else _check_points("x", x).copy()
        v = np.zeros((n, 3)) if v is None else _check_points("v", v).copy()
        if x.shape != (n, 3) or v.shape != (n, 3):
            raise JassyError(f"x, v: expected shape ({n}, 3)")
        return BodyState(x, v, _check_prior(quat, self.n_bodies))

    def goals(self, state: BodyState, tol: float = 1e-9):
        """Goal positions (n, 3) m (rows of non-simulated particles are their positions) and
        the bodies' rotations (K, 3, 3); updates ``state.quat``."""
        goal = state.x.copy()
        quat = np.empty_like(state.quat)
        rot = np.empty((self.n_bodies, 3, 3))
        fit = Fit(MODES.index(self.mode), float(self.beta), float(tol))
        _goals(state.x, self.model, fit, state.quat, goal, quat, rot)
        state.quat[:] = quat
        return goal, rot

    def step(
        self, state: BodyState, h: float, forces=None, gravity=(0.0, 0.0, 0.0), boundaries=None
    ) -> Contacts:
        """Advance ``state`` by h seconds (in place). forces: (n, 3) N external forces or None;
        gravity: acceleration (3,) m/s^2; boundaries: :class:`Boundaries` or None. Returns the
        boundary contacts made during the step."""
        if not (math.isfinite(h) and h > 0):
            raise JassyError(f"h: expected a time step > 0 (s), got {h!r}")
        n = self.rest.shape[0]
        f = np.zeros((n, 3)) if forces is None else np.asarray(forces, dtype=np.float64)
        if f.shape != (n, 3) or not np.all(np.isfinite(f)):
            raise JassyError(f"forces: expected a finite ({n}, 3) array (N)")
        g = np.asarray(gravity, dtype=np.float64)
        if g.shape != (3,) or not np.all(np.isfinite(g)):
            raise JassyError("gravity: expected 3 finite components (m/s^2)")
        bnd = boundaries or Boundaries()
        goal, _ = self.goals(state)
        if self.damping > 0:
            _damp_rigid(state.x, state.v, self.masses, self.order, self.starts, float(self.damping))
        cap = self.order.size * (bnd.planes.shape[0] + 1)
        ids = np.empty(cap, np.int64)
        rows = ContactRows(ids, np.empty_like(ids), np.empty((cap, 3)), np.empty(cap), np.empty(cap))
        motion = Motion(g, float(self.alpha), float(h), float(self.viscosity), float(self.radius))
        nc = _advance(state.x, state.v, self.model, goal, f, motion, Walls(bnd.planes, bnd.packed()), rows)
        cimp = np.empty(nc)
        impulses = Impulses(
            float(self.restitution), float(self.friction), int(self.iterations), BIAS, float(h)
        )
        _contact_impulses(state.x, state.v, self.model, rows, nc, impulses, cimp)
        state.time += h
        return Contacts(rows.particle[:nc], rows.boundary[:nc], rows.speed[:nc], cimp[:nc])

    def rigid_velocity(self, state: BodyState) -> np.ndarray:
        """(n, 3) m/s: each body's rigid motion v_cm + omega x r (same momenta as ``state.v``)."""
        vr = state.v.copy()
        _damp_rigid(state.x, vr, self.masses, self.order, self.starts, 1.0)
        return vr

    def momentum(self, state: BodyState):
        """Total linear momentum (kg m/s) and angular momentum about the origin (kg m^2/s)
        of the simulated particles."""
        i = self.order
        mv = self.masses[i, None] * state.v[i]
        return mv.sum(0), np.cross(state.x[i], mv).sum(0)
