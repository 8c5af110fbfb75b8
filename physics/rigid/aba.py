"""Allocation-free articulated-body algorithm on named model and data records.

The same recursion as ``articulated._aba`` (Featherstone, RBDA 2008, table 7.1), written the
way Pinocchio writes it (Carpentier et al., "The Pinocchio C++ library", SII 2019): the joint
transform of link i is kept as a rotation E (3x3, parent -> link coordinates) and the link
origin r (m, parent coordinates) instead of a 6x6 Plucker matrix, every product is unrolled
over 3-vectors, and all scratch lives in an ``AbaData`` record made once per model, so a call
allocates nothing. Spatial vectors are (angular; linear), in each link's own frame.

Transform rules with X = [[E, 0], [-E r^, E]] (parent -> link motion):
  X m        = (E m_w, E (m_v - r x m_w))
  X^T f      = (E^T f_n + r x E^T f_f, E^T f_f)                       (link -> parent force)
  X^T I X    = [[A' - B' r^ + r^ B'^T - r^ C' r^, B' + r^ C'], [sym., C']]
               with [[A', B'], [B'^T, C']] = blkdiag(E^T) I blkdiag(E).
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

REVOLUTE, PRISMATIC = 0, 1


class ChainModel(NamedTuple):
    """Static description of a kinematic tree (see ``articulated.Chain``)."""

    parent: np.ndarray  # (n,) int64, -1 = fixed base
    joint_type: np.ndarray  # (n,) int64, REVOLUTE or PRISMATIC
    axis: np.ndarray  # (n, 3) unit joint axes in the joint frame
    joint_rot: np.ndarray  # (n, 3, 3) joint frame orientation in the parent frame
    joint_pos: np.ndarray  # (n, 3) m, joint frame origin in the parent frame
    inertia: np.ndarray  # (n, 6, 6) spatial inertia about the link origin, link axes
    motion_subspace: np.ndarray  # (n, 6) S_i: (axis; 0) revolute, (0; axis) prismatic
    base_acceleration: np.ndarray  # (6,) (0; -g): gravity as a fictitious base acceleration


class AbaData(NamedTuple):
    """Scratch and results of one ABA evaluation (made by ``new_aba_data``)."""

    rot: np.ndarray  # (n, 3, 3) E_i, parent -> link coordinates at q
    origin: np.ndarray  # (n, 3) m, link origin in parent coordinates at q
    velocity: np.ndarray  # (n, 6) link spatial velocity
    bias_acc: np.ndarray  # (n, 6) velocity-product acceleration c_i = v_i x S_i qd_i
    art_inertia: np.ndarray  # (n, 6, 6) articulated-body inertia I^A_i
    art_bias: np.ndarray  # (n, 6) articulated bias force p^A_i
    u_vec: np.ndarray  # (n, 6) U_i = I^A_i S_i
    d_inv: np.ndarray  # (n,) 1 / (S_i^T U_i)
    u_force: np.ndarray  # (n,) tau_i - S_i^T p^A_i
    acceleration: np.ndarray  # (n, 6) link spatial acceleration
    qdd: np.ndarray  # (n,) joint accelerations (the result)
    work6x6: np.ndarray  # (3, 6, 6) scratch: reduced inertia, its rotated blocks, shift terms
    work6: np.ndarray  # (4, 6) scratch vectors


# Floats per link in each AbaData field, in field order (a flat scratch buffer holds them all)
_DATA_SIZES = (9, 3, 6, 6, 36, 6, 6, 1, 1, 6, 1)
_DATA_FIXED = 3 * 36 + 4 * 6  # work6x6 and work6


def aba_data_size(n: int) -> int:
    """Length of the flat float64 scratch buffer of a model of n links."""
    return n * sum(_DATA_SIZES) + _DATA_FIXED


@numba.njit(cache=True)
def aba_data_views(buffer, n):
    """An ``AbaData`` whose arrays are views into one flat float64 ``buffer``."""
    o = 0
    rot = buffer[o : o + 9 * n].reshape((n, 3, 3))
    o += 9 * n
    origin = buffer[o : o + 3 * n].reshape((n, 3))
    o += 3 * n
    velocity = buffer[o : o + 6 * n].reshape((n, 6))
    o += 6 * n
    bias_acc = buffer[o : o + 6 * n].reshape((n, 6))
    o += 6 * n
    art_inertia = buffer[o : o + 36 * n].reshape((n, 6, 6))
    o += 36 * n
    art_bias = buffer[o : o + 6 * n].reshape((n, 6))
    o += 6 * n
    u_vec = buffer[o : o + 6 * n].reshape((n, 6))
    o += 6 * n
    d_inv = buffer[o : o + n]
    o += n
    u_force = buffer[o : o + n]
    o += n
    acceleration = buffer[o : o + 6 * n].reshape((n, 6))
    o += 6 * n
    qdd = buffer[o : o + n]
    o += n
    work6x6 = buffer[o : o + 108].reshape((3, 6, 6))
    work6 = buffer[o + 108 : o + 132].reshape((4, 6))
    return AbaData(
        rot, origin, velocity, bias_acc, art_inertia, art_bias, u_vec, d_inv, u_force, acceleration, qdd,
        work6x6, work6,
    )  # fmt: skip


def new_aba_data(n: int) -> AbaData:
    """Scratch for a model of n links."""
    return aba_data_views(np.zeros(aba_data_size(n)), n)


@numba.njit(cache=True, fastmath=True, inline="always", _nrt=False)
def _joint_transform(m, d, i, qi):
    """E_i and r_i of link i at joint coordinate qi (Rodrigues for a revolute joint)."""
    J = m.joint_rot[i]
    a0, a1, a2 = m.axis[i, 0], m.axis[i, 1], m.axis[i, 2]
    E = d.rot[i]
    if m.joint_type[i] == REVOLUTE:
        s, c = np.sin(qi), np.cos(qi)
        t = 1.0 - c
        # R_J(q) = c 1 + t a a^T + s a^ ; link rotation in parent = J R_J; E = (J R_J)^T
        r00, r01, r02 = c + t * a0 * a0, t * a0 * a1 - s * a2, t * a0 * a2 + s * a1
        r10, r11, r12 = t * a1 * a0 + s * a2, c + t * a1 * a1, t * a1 * a2 - s * a0
        r20, r21, r22 = t * a2 * a0 - s * a1, t * a2 * a1 + s * a0, c + t * a2 * a2
        for k in range(3):
            jk0, jk1, jk2 = J[k, 0], J[k, 1], J[k, 2]
            E[0, k] = jk0 * r00 + jk1 * r10 + jk2 * r20
            E[1, k] = jk0 * r01 + jk1 * r11 + jk2 * r21
            E[2, k] = jk0 * r02 + jk1 * r12 + jk2 * r22
        for k in range(3):
            d.origin[i, k] = m.joint_pos[i, k]
    else:
        for k in range(3):
            for j in range(3):
                E[j, k] = J[k, j]
            d.origin[i, k] = m.joint_pos[i, k] + qi * (J[k, 0] * a0 + J[k, 1] * a1 + J[k, 2] * a2)


@numba.njit(cache=True, fastmath=True, inline="always", _nrt=False)
def _motion_to_link(E, r, src, dst):
    """dst = X src for X = (E, r): (E w, E (v - r x w))."""
    w0, w1, w2 = src[0], src[1], src[2]
    v0 = src[3] - (r[1] * w2 - r[2] * w1)
    v1 = src[4] - (r[2] * w0 - r[0] * w2)
    v2 = src[5] - (r[0] * w1 - r[1] * w0)
    for k in range(3):
        dst[k] = E[k, 0] * w0 + E[k, 1] * w1 + E[k, 2] * w2
        dst[3 + k] = E[k, 0] * v0 + E[k, 1] * v1 + E[k, 2] * v2


@numba.njit(cache=True, fastmath=True, inline="always", _nrt=False)
def _add_force_to_parent(E, r, f, dst):
    """dst += X^T f: (E^T n + r x E^T f, E^T f)."""
    n0 = E[0, 0] * f[0] + E[1, 0] * f[1] + E[2, 0] * f[2]
    n1 = E[0, 1] * f[0] + E[1, 1] * f[1] + E[2, 1] * f[2]
    n2 = E[0, 2] * f[0] + E[1, 2] * f[1] + E[2, 2] * f[2]
    g0 = E[0, 0] * f[3] + E[1, 0] * f[4] + E[2, 0] * f[5]
    g1 = E[0, 1] * f[3] + E[1, 1] * f[4] + E[2, 1] * f[5]
    g2 = E[0, 2] * f[3] + E[1, 2] * f[4] + E[2, 2] * f[5]
    dst[0] += n0 + r[1] * g2 - r[2] * g1
    dst[1] += n1 + r[2] * g0 - r[0] * g2
    dst[2] += n2 + r[0] * g1 - r[1] * g0
    dst[3] += g0
    dst[4] += g1
    dst[5] += g2


@numba.njit(cache=True, fastmath=True, inline="always", _nrt=False)
def _add_inertia_to_parent(E, r, Ia, rotated, shift, dst):
    """dst += X^T Ia X for symmetric Ia (6x6), X = (E, r); ``rotated`` and ``shift`` are 6x6
    scratch (``shift`` holds r^ C' in its top-left and B' r^ in its bottom-left block)."""
    # rotated = blkdiag(E^T) Ia blkdiag(E): blocks A, B, C as E^T (M E) (the lower-left block
    # is B'^T and is never read); ``shift`` rows 0-2 hold M E meanwhile
    for oi, oj in ((0, 0), (0, 3), (3, 3)):
        for k in range(3):
            for q in range(3):
                shift[k, q] = (
                    Ia[oi + k, oj] * E[0, q] + Ia[oi + k, oj + 1] * E[1, q] + Ia[oi + k, oj + 2] * E[2, q]
                )
        for p in range(3):
            for q in range(3):
                rotated[oi + p, oj + q] = (
                    E[0, p] * shift[0, q] + E[1, p] * shift[1, q] + E[2, p] * shift[2, q]
                )
    # shifts by r^ : A' - B' r^ + r^ B'^T - r^ C' r^ ; B' + r^ C' ; C'
    r0, r1, r2 = r[0], r[1], r[2]
    # rC = r^ C' (3x3), with r^ = [[0,-r2,r1],[r2,0,-r0],[-r1,r0,0]]
    rc = shift[:3, :3]
    for q in range(3):
        c0, c1, c2 = rotated[3, 3 + q], rotated[4, 3 + q], rotated[5, 3 + q]
        rc[0, q] = -r2 * c1 + r1 * c2
        rc[1, q] = r2 * c0 - r0 * c2
        rc[2, q] = -r1 * c0 + r0 * c1
    # Br = B' r^ (3x3)
    br = shift[3:, :3]
    for p in range(3):
        b0, b1, b2 = rotated[p, 3], rotated[p, 4], rotated[p, 5]
        br[p, 0] = b1 * r2 - b2 * r1
        br[p, 1] = -b0 * r2 + b2 * r0
        br[p, 2] = b0 * r1 - b1 * r0
    for p in range(3):
        # (r^ C' r^)[p, q] = sum_k rc[p, k] r^[k, q]
        rcr0 = rc[p, 1] * r2 - rc[p, 2] * r1
        rcr1 = -rc[p, 0] * r2 + rc[p, 2] * r0
        rcr2 = rc[p, 0] * r1 - rc[p, 1] * r0
        rcr = (rcr0, rcr1, rcr2)
        for q in range(3):
            top = rotated[p, q] - br[p, q] - br[q, p] - rcr[q]  # r^ B'^T = -(B' r^)^T
            dst[p, q] += top
            off = rotated[p, 3 + q] + rc[p, q]
            dst[p, 3 + q] += off
            dst[3 + q, p] += off
            dst[3 + p, 3 + q] += rotated[3 + p, 3 + q]


@numba.njit(cache=True, fastmath=True, inline="always", _nrt=False)
def _cross_motion(v, m, out):
    """out = v x m (spatial motion cross product)."""
    out[0] = v[1] * m[2] - v[2] * m[1]
    out[1] = v[2] * m[0] - v[0] * m[2]
    out[2] = v[0] * m[1] - v[1] * m[0]
    out[3] = v[1] * m[5] - v[2] * m[4] + v[4] * m[2] - v[5] * m[1]
    out[4] = v[2] * m[3] - v[0] * m[5] + v[5] * m[0] - v[3] * m[2]
    out[5] = v[0] * m[4] - v[1] * m[3] + v[3] * m[1] - v[4] * m[0]


@numba.njit(cache=True, fastmath=True, _nrt=False)
def aba_into(m, d, q, qd, tau, fext) -> bool:
    """Joint accelerations of the tree ``m`` into ``d.qdd``; False where a joint's articulated
    inertia is not positive (a joint that moves no mass). q (rad | m), qd, tau (N m | N): (n,);
    fext (n, 6): external spatial force per link about its origin, link coordinates."""
    n = q.size
    S = m.motion_subspace
    tmp, iv = d.work6[0], d.work6[1]
    # pass 1, root to leaves: transforms, velocities, velocity-product terms, bias forces
    for i in range(n):
        _joint_transform(m, d, i, q[i])
        p = m.parent[i]
        vi = d.velocity[i]
        if p < 0:
            for k in range(6):
                vi[k] = 0.0
        else:
            _motion_to_link(d.rot[i], d.origin[i], d.velocity[p], vi)
        for k in range(6):
            tmp[k] = S[i, k] * qd[i]
        _cross_motion(vi, tmp, d.bias_acc[i])
        for k in range(6):
            vi[k] += tmp[k]
        inertia = m.inertia[i]
        for r_ in range(6):
            acc = 0.0
            for k in range(6):
                acc += inertia[r_, k] * vi[k]
            iv[r_] = acc
            for k in range(6):
                d.art_inertia[i, r_, k] = inertia[r_, k]
        # p = v x* (I v) - fext: (w x n + v_o x f, w x f)
        pa = d.art_bias[i]
        pa[0] = vi[1] * iv[2] - vi[2] * iv[1] + vi[4] * iv[5] - vi[5] * iv[4] - fext[i, 0]
        pa[1] = vi[2] * iv[0] - vi[0] * iv[2] + vi[5] * iv[3] - vi[3] * iv[5] - fext[i, 1]
        pa[2] = vi[0] * iv[1] - vi[1] * iv[0] + vi[3] * iv[4] - vi[4] * iv[3] - fext[i, 2]
        pa[3] = vi[1] * iv[5] - vi[2] * iv[4] - fext[i, 3]
        pa[4] = vi[2] * iv[3] - vi[0] * iv[5] - fext[i, 4]
        pa[5] = vi[0] * iv[4] - vi[1] * iv[3] - fext[i, 5]
    # pass 2, leaves to root: articulated inertias and bias forces
    Ia, rotated, shift = d.work6x6[0], d.work6x6[1], d.work6x6[2]
    pa_red = d.work6[2]
    for i in range(n - 1, -1, -1):
        IA = d.art_inertia[i]
        U = d.u_vec[i]
        # S_i = axis in rows o..o+2 (o = 0 revolute, 3 prismatic) and zero elsewhere
        o = 0 if m.joint_type[i] == REVOLUTE else 3
        a0, a1, a2 = m.axis[i, 0], m.axis[i, 1], m.axis[i, 2]
        for r_ in range(6):
            U[r_] = IA[r_, o] * a0 + IA[r_, o + 1] * a1 + IA[r_, o + 2] * a2
        dd = a0 * U[o] + a1 * U[o + 1] + a2 * U[o + 2]
        su = a0 * d.art_bias[i, o] + a1 * d.art_bias[i, o + 1] + a2 * d.art_bias[i, o + 2]
        if not dd > 0.0:
            return False
        dinv = 1.0 / dd
        d.d_inv[i] = dinv
        ui = tau[i] - su
        d.u_force[i] = ui
        p = m.parent[i]
        if p >= 0:
            c = d.bias_acc[i]
            for r_ in range(6):
                ur = U[r_] * dinv
                for k in range(r_, 6):
                    Ia[r_, k] = IA[r_, k] - ur * U[k]
                    Ia[k, r_] = Ia[r_, k]
            for r_ in range(6):
                acc = d.art_bias[i, r_] + U[r_] * (ui * dinv)
                for k in range(6):
                    acc += Ia[r_, k] * c[k]
                pa_red[r_] = acc
            _add_inertia_to_parent(d.rot[i], d.origin[i], Ia, rotated, shift, d.art_inertia[p])
            _add_force_to_parent(d.rot[i], d.origin[i], pa_red, d.art_bias[p])
    # pass 3, root to leaves: accelerations
    for i in range(n):
        p = m.parent[i]
        ai = d.acceleration[i]
        src = m.base_acceleration if p < 0 else d.acceleration[p]
        _motion_to_link(d.rot[i], d.origin[i], src, ai)
        ua = 0.0
        for k in range(6):
            ai[k] += d.bias_acc[i, k]
            ua += d.u_vec[i, k] * ai[k]
        qddi = (d.u_force[i] - ua) * d.d_inv[i]
        d.qdd[i] = qddi
        for k in range(6):
            ai[k] += S[i, k] * qddi
    return True


# codes returned by ``aba_checked``
ABA_OK, ABA_BAD_Q, ABA_BAD_QD, ABA_BAD_TAU, ABA_BAD_FEXT, ABA_SINGULAR = 0, 1, 2, 3, 4, 5


@numba.njit(cache=True)
def _all_finite(x) -> bool:
    total = 0.0
    for v in x.ravel():
        total += v * 0.0  # NaN for a NaN or an infinity (this kernel is not fastmath)
    return total == 0.0


@numba.njit(cache=True)
def aba_checked(m, scratch, q, qd, tau, fext, qdd) -> int:
    """``aba_into`` with its scratch in the flat buffer ``scratch`` (see ``aba_data_size``; a
    call passes few arrays, which keeps the call cheap from Python) after checking that every
    input is finite; the result in ``qdd``; returns one of the ABA_* codes."""
    d = aba_data_views(scratch, q.size)
    if not _all_finite(q):
        return ABA_BAD_Q
    if not _all_finite(qd):
        return ABA_BAD_QD
    if not _all_finite(tau):
        return ABA_BAD_TAU
    if not _all_finite(fext):
        return ABA_BAD_FEXT
    if not aba_into(m, d, q, qd, tau, fext):
        return ABA_SINGULAR
    qdd[:] = d.qdd
    if not _all_finite(qdd):
        return ABA_SINGULAR
    return ABA_OK
