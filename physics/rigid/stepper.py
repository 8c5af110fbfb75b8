"""The rigid-world time step (numba): free motion, contacts, impact times inside the step.

One outer step of h seconds:

1. contacts of the current configuration (gap <= slop) are resolved at the impulse level by
   projected Gauss-Seidel on the bodies' velocities (sequential impulses; mathematically PGS
   on W = J M^-1 J^T without forming W): normal rows with Newton restitution for approaching
   contacts faster than ``bounce_threshold`` (u_N+ >= -e u_N-), else a resting target with
   gravity's velocity increment over the step folded in; tangent rows projected onto the
   Coulomb disk |r_T| <= mu r_N; rolling-resistance rows (a torque impulse bounded by
   rolling * r_N, m). Resting contacts found in the previous solve (same bodies and
   features) start from its force times dt (warm start); sweeps stop when no impulse
   changes by more than ``tolerance`` times the largest normal impulse;
2. every body moves freely to the end of the step (integrate.advance_body_into);
3. a pair that was apart at the start (slop < gap <= how far the two can close in the step,
   from their relative velocity and spins) and penetrates at the end, having closed
   faster than ``bounce_threshold`` on average, has hit inside the step: its time of impact
   is the root of its gap along the free motion (Illinois regula falsi to 1e-12 s), and
   the whole world moves to the earliest such time and goes
   back to 1. At most ``max_events`` such sub-steps per step; later impacts are resolved at
   the step end.

Penalty models replace 1 by forces: linear f = k x + c xdot, Hunt-Crossley f = k x^p + c x^p
xdot (zero at first touch), both clamped at f >= 0, with regularised Coulomb friction.

Each resolved contact appends a record row (columns ``REC_*``): time, step, bodies, world
point, impulse on a (N s, world), approach speed, slip and rolling speed after the solve,
impact flag, features, barycentric weights on b, and the contact point in each body's frame.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from physics.rigid.integrate import advance_body_into
from physics.rigid.narrow import pair_contacts, sweep_and_prune
from physics.rigid.shapes import PLANE
from physics.rigid.spatial import cross, dot3, mtv, mv, quat_exp, quat_log, quat_mul, quat_to_mat

DYNAMIC, STATIC, KINEMATIC = 0, 1, 2
IMPULSE, LINEAR, HUNT_CROSSLEY = 0, 1, 2
REC_TIME, REC_STEP, REC_A, REC_B, REC_POINT, REC_IMPULSE, REC_SPEED, REC_SLIP = 0, 1, 2, 3, 4, 7, 10, 11
REC_ROLL, REC_IMPACT, REC_FEAT_A, REC_FEAT_B, REC_BARY, REC_LOCAL_A, REC_LOCAL_B = 12, 13, 14, 15, 16, 19, 22
REC_NORMAL = 25
REC_WIDTH = 28
# parameter vector layout
P_GX, P_GY, P_GZ, P_SLOP, P_BOUNCE, P_BETA, P_ITER, P_TOL = range(8)
P_METHOD, P_ADAPT_TOL, P_MODEL, P_K, P_C, P_EXP, P_MAX_EVENTS, P_VEPS = range(8, 16)
N_PARAMS = 16
MAX_CONTACTS = 1 << 16


@nb.njit(cache=True)
def _rotations(quat):
    n = quat.shape[0]
    rot = np.empty((n, 3, 3))
    for i in range(n):
        rot[i] = quat_to_mat(quat[i])
    return rot


@nb.njit(cache=True)
def _world_velocities(kind, rot, phi, kin_v, kin_w):
    n = kind.shape[0]
    v = np.zeros((n, 3))
    w = np.zeros((n, 3))
    for i in range(n):
        if kind[i] == DYNAMIC:
            w[i] = mv(rot[i], phi[i, :3])
            v[i] = mv(rot[i], phi[i, 3:])
        elif kind[i] == KINEMATIC:
            v[i] = kin_v[i]
            w[i] = kin_w[i]
    return v, w


@nb.njit(cache=True)
def _inv_inertia_world(kind, rot, inv_inertia):
    n = kind.shape[0]
    out = np.zeros((n, 3, 3))
    for i in range(n):
        if kind[i] == DYNAMIC:
            r = rot[i]
            d = inv_inertia[i]
            for x in range(3):
                for y in range(3):
                    out[i, x, y] = (
                        r[x, 0] * d[0] * r[y, 0] + r[x, 1] * d[1] * r[y, 1] + r[x, 2] * d[2] * r[y, 2]
                    )
    return out


@nb.njit(cache=True)
def _apply(i, imp, r, inv_mass, iw, v, w, sign):
    v[i] += sign * inv_mass[i] * imp
    w[i] += sign * mv(iw[i], cross(r, imp))


@nb.njit(cache=True)
def _rel_velocity(a, b, ra, rb, v, w):
    return v[a] + cross(w[a], ra) - v[b] - cross(w[b], rb)


@nb.njit(cache=True)
def new_warm_start(size):
    """Contact impulses of the last solve for warm starting the next: keys (a, b, feature a,
    feature b), world force (N) and rolling torque (N m), and the count in use."""
    return np.empty((size, 4), np.int64), np.empty((size, 6)), np.zeros(1, np.int64)


@nb.njit(cache=True)
def _contact_frames(buf, idx, pos, iw, inv_mass, frame, ra, rb, ang_a, ang_b, res_a, res_b, kin):
    """Per contact k: frame rows (n, t1, t2), lever arms, Jacobian rows (angular parts; rows
    3, 4 roll about t1, t2), responses M^-1 J^T and effective inverse masses (scalar loops)."""
    pts, nrm, _, pair, _, _, _ = buf
    for k in range(idx.shape[0]):
        c = idx[k]
        a, b = pair[c, 0], pair[c, 1]
        n0, n1, n2 = nrm[c, 0], nrm[c, 1], nrm[c, 2]
        if abs(n0) < 0.57:
            s0, s1, s2 = 0.0, -n2, n1
        else:
            s0, s1, s2 = -n1, n0, 0.0
        inv = 1.0 / math.sqrt(s0 * s0 + s1 * s1 + s2 * s2)
        s0, s1, s2 = s0 * inv, s1 * inv, s2 * inv
        frame[k, 0, 0], frame[k, 0, 1], frame[k, 0, 2] = n0, n1, n2
        frame[k, 1, 0], frame[k, 1, 1], frame[k, 1, 2] = s0, s1, s2
        frame[k, 2, 0], frame[k, 2, 1], frame[k, 2, 2] = (
            n1 * s2 - n2 * s1,
            n2 * s0 - n0 * s2,
            n0 * s1 - n1 * s0,
        )
        for x in range(3):
            ra[k, x] = pts[c, x] - pos[a, x]
            rb[k, x] = pts[c, x] - pos[b, x]
        for j in range(5):
            if j < 3:
                d0, d1, d2 = frame[k, j, 0], frame[k, j, 1], frame[k, j, 2]
                ang_a[k, j, 0] = ra[k, 1] * d2 - ra[k, 2] * d1
                ang_a[k, j, 1] = ra[k, 2] * d0 - ra[k, 0] * d2
                ang_a[k, j, 2] = ra[k, 0] * d1 - ra[k, 1] * d0
                ang_b[k, j, 0] = rb[k, 1] * d2 - rb[k, 2] * d1
                ang_b[k, j, 1] = rb[k, 2] * d0 - rb[k, 0] * d2
                ang_b[k, j, 2] = rb[k, 0] * d1 - rb[k, 1] * d0
                kin[k, j] = inv_mass[a] + inv_mass[b]
            else:
                for x in range(3):
                    ang_a[k, j, x] = ang_b[k, j, x] = frame[k, j - 2, x]
                kin[k, j] = 0.0
            for x in range(3):
                res_a[k, j, x] = (
                    iw[a, x, 0] * ang_a[k, j, 0] + iw[a, x, 1] * ang_a[k, j, 1] + iw[a, x, 2] * ang_a[k, j, 2]
                )
                res_b[k, j, x] = (
                    iw[b, x, 0] * ang_b[k, j, 0] + iw[b, x, 1] * ang_b[k, j, 1] + iw[b, x, 2] * ang_b[k, j, 2]
                )
                kin[k, j] += ang_a[k, j, x] * res_a[k, j, x] + ang_b[k, j, x] * res_b[k, j, x]


@nb.njit(cache=True)
def _row_velocity(k, j, a, b, frame, ang_a, ang_b, v, w, linear):
    """Relative velocity of contact k along Jacobian row j (scalar loops, no allocation)."""
    u = 0.0
    for x in range(3):
        u += ang_a[k, j, x] * w[a, x] - ang_b[k, j, x] * w[b, x]
        if linear:
            u += frame[k, j, x] * (v[a, x] - v[b, x])
    return u


@nb.njit(cache=True)
def _row_apply(k, j, a, b, impulse, frame, res_a, res_b, ima, imb, v, w, linear):
    """Apply ``impulse`` along row j of contact k to both bodies (b gets the reaction)."""
    for x in range(3):
        w[a, x] += impulse * res_a[k, j, x]
        w[b, x] -= impulse * res_b[k, j, x]
        if linear:
            v[a, x] += impulse * ima * frame[k, j, x]
            v[b, x] -= impulse * imb * frame[k, j, x]


@nb.njit(cache=True)
def _disk(x1, x2, limit):
    """(x1, x2) projected onto the disk of radius ``limit``."""
    mag = math.sqrt(x1 * x1 + x2 * x2)
    if mag > limit:
        return x1 * limit / mag, x2 * limit / mag
    return x1, x2


@nb.njit(cache=True)
def _warm_impulses(buf, idx, impact, frame, mu, roll, dt, warm, n_bodies, r):
    """Initial impulses r from the last solve's contacts with the same (a, b, features): its
    force and rolling torque times dt, projected on the new frame and cones."""
    _, _, _, pair, feat, _, _ = buf
    keys, vals, size = warm
    m = size[0]
    head = np.full(n_bodies, -1, np.int64)
    nxt = np.empty(m, np.int64)
    used = np.zeros(m, np.bool_)
    for e in range(m - 1, -1, -1):  # lists keep the last solve's order
        nxt[e] = head[keys[e, 0]]
        head[keys[e, 0]] = e
    for k in range(idx.shape[0]):
        r[k, :] = 0.0
        if impact[k]:
            continue
        c = idx[k]
        e = head[pair[c, 0]]
        while e >= 0:
            if (
                not used[e]
                and keys[e, 1] == pair[c, 1]
                and keys[e, 2] == feat[c, 0]
                and keys[e, 3] == feat[c, 1]
            ):
                break
            e = nxt[e]
        if e < 0:
            continue
        used[e] = True
        for j in range(3):
            r[k, j] = dt * (
                vals[e, 0] * frame[k, j, 0] + vals[e, 1] * frame[k, j, 1] + vals[e, 2] * frame[k, j, 2]
            )
        for j in range(2):
            d = frame[k, 1 + j]
            r[k, 3 + j] = dt * (vals[e, 3] * d[0] + vals[e, 4] * d[1] + vals[e, 5] * d[2])
        r[k, 0] = max(r[k, 0], 0.0)
        r[k, 1], r[k, 2] = _disk(r[k, 1], r[k, 2], mu[k] * r[k, 0])
        r[k, 3], r[k, 4] = _disk(r[k, 3], r[k, 4], roll[k] * r[k, 0])


@nb.njit(cache=True)
def _keep_warm(buf, idx, impact, frame, r, dt, warm):
    """Store the solved contacts pushing (r_N > 0) as the next solve's warm start, as forces
    r / dt. Not after a solve with an impact: the impact's impulse spreads through resting
    contacts, and over a short sub-step it would read as a huge force."""
    _, _, _, pair, feat, _, _ = buf
    keys, vals, size = warm
    m = 0
    for k in range(idx.shape[0]):
        if impact[k]:
            size[0] = 0
            return
    for k in range(idx.shape[0]):
        if r[k, 0] <= 0.0 or m >= keys.shape[0]:
            continue
        c = idx[k]
        keys[m, 0], keys[m, 1], keys[m, 2], keys[m, 3] = pair[c, 0], pair[c, 1], feat[c, 0], feat[c, 1]
        for x in range(3):
            vals[m, x] = (r[k, 0] * frame[k, 0, x] + r[k, 1] * frame[k, 1, x] + r[k, 2] * frame[k, 2, x]) / dt
            vals[m, 3 + x] = (r[k, 3] * frame[k, 1, x] + r[k, 4] * frame[k, 2, x]) / dt
        m += 1
    size[0] = m


@nb.njit(cache=True)
def _resolve(
    buf, count, pos, rot, phi, kind, kin_v, kin_w, body, prm, dt, gscale, time, step, rec, nrec, warm, stats
):
    """Impulse-level contact solve (see module doc), warm-started from ``warm`` (updated);
    updates phi; appends records; adds the contacts and PGS sweeps to stats[2] and stats[4]."""
    pts, nrm, gaps, pair, feat, bar, _ = buf
    inv_mass, inv_inertia, restitution, friction, rolling = body
    slop, thr, beta = prm[P_SLOP], prm[P_BOUNCE], prm[P_BETA]
    nc = 0
    for c in range(count):
        if gaps[c] <= slop:
            nc += 1
    if nc == 0:
        warm[2][0] = 0
        return nrec
    idx = np.empty(nc, np.int64)
    k = 0
    for c in range(count):
        if gaps[c] <= slop:
            idx[k] = c
            k += 1
    v, w = _world_velocities(kind, rot, phi, kin_v, kin_w)
    iw = _inv_inertia_world(kind, rot, inv_inertia)
    ra = np.empty((nc, 3))
    rb = np.empty((nc, 3))
    frame = np.empty((nc, 3, 3))
    ang_a = np.empty((nc, 5, 3))
    ang_b = np.empty((nc, 5, 3))
    res_a = np.empty((nc, 5, 3))
    res_b = np.empty((nc, 5, 3))
    kin = np.empty((nc, 5))
    _contact_frames(buf, idx, pos, iw, inv_mass, frame, ra, rb, ang_a, ang_b, res_a, res_b, kin)
    target = np.zeros((nc, 3))
    mu = np.empty(nc)
    roll = np.empty(nc)
    speed0 = np.empty(nc)
    impact = np.zeros(nc, np.bool_)
    gx, gy, gz = prm[P_GX] * gscale * dt, prm[P_GY] * gscale * dt, prm[P_GZ] * gscale * dt
    for k in range(nc):
        c = idx[k]
        a, b = pair[c, 0], pair[c, 1]
        mu[k] = math.sqrt(friction[a] * friction[b])
        roll[k] = max(rolling[a], rolling[b])
        un = _row_velocity(k, 0, a, b, frame, ang_a, ang_b, v, w, True)
        speed0[k] = -un
        if -un > thr:
            impact[k] = True
            target[k, 0] = -math.sqrt(restitution[a] * restitution[b]) * un
        else:  # resting: gravity's velocity increment over dt is folded into the targets
            dyn = (1.0 if kind[a] == DYNAMIC else 0.0) - (1.0 if kind[b] == DYNAMIC else 0.0)
            pen = max(-gaps[c] - slop, 0.0)
            target[k, 0] = (beta * pen - max(gaps[c], 0.0)) / dt
            for j in range(3):
                target[k, j] -= dyn * (gx * frame[k, j, 0] + gy * frame[k, j, 1] + gz * frame[k, j, 2])
    r = np.empty((nc, 5))
    _warm_impulses(buf, idx, impact, frame, mu, roll, dt, warm, kind.shape[0], r)
    for k in range(nc):
        c = idx[k]
        a, b = pair[c, 0], pair[c, 1]
        for j in range(5):
            if r[k, j] != 0.0:
                _row_apply(k, j, a, b, r[k, j], frame, res_a, res_b, inv_mass[a], inv_mass[b], v, w, j < 3)
    iters = int(prm[P_ITER])
    tol = prm[P_TOL]
    stats[2] += nc
    for _ in range(iters):
        stats[4] += 1
        change = 0.0
        scale = 0.0
        for k in range(nc):
            c = idx[k]
            a, b = pair[c, 0], pair[c, 1]
            ima, imb = inv_mass[a], inv_mass[b]
            # normal row
            u = _row_velocity(k, 0, a, b, frame, ang_a, ang_b, v, w, True)
            rn = max(0.0, r[k, 0] + (target[k, 0] - u) / kin[k, 0])
            dn = rn - r[k, 0]
            if dn != 0.0:
                _row_apply(k, 0, a, b, dn, frame, res_a, res_b, ima, imb, v, w, True)
                r[k, 0] = rn
            biggest = abs(dn)
            if mu[k] > 0.0:
                u1 = _row_velocity(k, 1, a, b, frame, ang_a, ang_b, v, w, True)
                u2 = _row_velocity(k, 2, a, b, frame, ang_a, ang_b, v, w, True)
                x1, x2 = _disk(
                    r[k, 1] + (target[k, 1] - u1) / kin[k, 1],
                    r[k, 2] + (target[k, 2] - u2) / kin[k, 2],
                    mu[k] * rn,
                )
                _row_apply(k, 1, a, b, x1 - r[k, 1], frame, res_a, res_b, ima, imb, v, w, True)
                _row_apply(k, 2, a, b, x2 - r[k, 2], frame, res_a, res_b, ima, imb, v, w, True)
                biggest = max(biggest, abs(x1 - r[k, 1]), abs(x2 - r[k, 2]))
                r[k, 1] = x1
                r[k, 2] = x2
            if roll[k] > 0.0:
                y1, y2 = _disk(
                    r[k, 3] - _row_velocity(k, 3, a, b, frame, ang_a, ang_b, v, w, False) / kin[k, 3],
                    r[k, 4] - _row_velocity(k, 4, a, b, frame, ang_a, ang_b, v, w, False) / kin[k, 4],
                    roll[k] * rn,
                )
                _row_apply(k, 3, a, b, y1 - r[k, 3], frame, res_a, res_b, ima, imb, v, w, False)
                _row_apply(k, 4, a, b, y2 - r[k, 4], frame, res_a, res_b, ima, imb, v, w, False)
                r[k, 3] = y1
                r[k, 4] = y2
            change = max(change, biggest)
            scale = max(scale, abs(r[k, 0]))
        if change <= tol * max(scale, 1e-30):
            break
    _keep_warm(buf, idx, impact, frame, r, dt, warm)
    for i in range(kind.shape[0]):
        if kind[i] == DYNAMIC:
            phi[i, :3] = mtv(rot[i], w[i])
            phi[i, 3:] = mtv(rot[i], v[i])
    for k in range(nc):
        if r[k, 0] <= 0.0 and not impact[k]:
            continue
        if nrec >= rec.shape[0]:
            return -1
        c = idx[k]
        a, b = pair[c, 0], pair[c, 1]
        row = rec[nrec]
        row[REC_TIME] = time
        row[REC_STEP] = step
        row[REC_A] = a
        row[REC_B] = b
        # slip: tangential relative velocity with gravity's increment (target) removed
        s1 = _row_velocity(k, 1, a, b, frame, ang_a, ang_b, v, w, True) - target[k, 1]
        s2 = _row_velocity(k, 2, a, b, frame, ang_a, ang_b, v, w, True) - target[k, 2]
        wn = 0.0
        for x in range(3):
            wn += (w[a, x] - w[b, x]) * frame[k, 0, x]
        wt2 = 0.0
        for x in range(3):
            wt2 += (w[a, x] - w[b, x] - wn * frame[k, 0, x]) ** 2
        for x in range(3):
            row[REC_POINT + x] = pts[c, x]
            row[REC_IMPULSE + x] = (
                r[k, 0] * frame[k, 0, x] + r[k, 1] * frame[k, 1, x] + r[k, 2] * frame[k, 2, x]
            )
            row[REC_BARY + x] = bar[c, x]
            row[REC_NORMAL + x] = frame[k, 0, x]
            row[REC_LOCAL_A + x] = rot[a, 0, x] * ra[k, 0] + rot[a, 1, x] * ra[k, 1] + rot[a, 2, x] * ra[k, 2]
            row[REC_LOCAL_B + x] = rot[b, 0, x] * rb[k, 0] + rot[b, 1, x] * rb[k, 1] + rot[b, 2, x] * rb[k, 2]
        row[REC_SPEED] = speed0[k]
        row[REC_SLIP] = math.sqrt(s1 * s1 + s2 * s2)
        row[REC_ROLL] = math.sqrt(wt2) * math.sqrt(ra[k, 0] ** 2 + ra[k, 1] ** 2 + ra[k, 2] ** 2)
        row[REC_IMPACT] = 1.0 if impact[k] else 0.0
        row[REC_FEAT_A] = feat[c, 0]
        row[REC_FEAT_B] = feat[c, 1]
        nrec += 1
    return nrec


@nb.njit(cache=True)
def _penalty(buf, count, pos, rot, phi, kind, kin_v, kin_w, body, prm, dt, time, step, rec, nrec):
    """Penalty contact forces over dt (symplectic: velocities now, positions after)."""
    pts, nrm, gaps, pair, feat, bar, _ = buf
    inv_mass, inv_inertia, restitution, friction, rolling = body
    v, w = _world_velocities(kind, rot, phi, kin_v, kin_w)
    iw = _inv_inertia_world(kind, rot, inv_inertia)
    model, k_s, c_d, p_exp, veps = int(prm[P_MODEL]), prm[P_K], prm[P_C], prm[P_EXP], prm[P_VEPS]
    for c in range(count):
        x = -gaps[c]
        if x <= 0.0:
            continue
        a, b = pair[c, 0], pair[c, 1]
        n = nrm[c]
        ra = pts[c] - pos[a]
        rb = pts[c] - pos[b]
        u = _rel_velocity(a, b, ra, rb, v, w)
        xdot = -(dot3(u, n))
        if model == LINEAR:
            fn = k_s * x + c_d * xdot
        else:
            xp = x**p_exp
            fn = k_s * xp + c_d * xp * xdot
        fn = max(fn, 0.0)
        ut = u - (dot3(u, n)) * n
        slip = math.sqrt(dot3(ut, ut))
        mu = math.sqrt(friction[a] * friction[b])
        ft = -mu * fn * ut / max(slip, veps)
        imp = (fn * n + ft) * dt
        _apply(a, imp, ra, inv_mass, iw, v, w, 1.0)
        _apply(b, imp, rb, inv_mass, iw, v, w, -1.0)
        if nrec >= rec.shape[0]:
            return -1
        row = rec[nrec]
        row[:] = 0.0
        row[REC_TIME] = time
        row[REC_STEP] = step
        row[REC_A] = a
        row[REC_B] = b
        row[REC_POINT : REC_POINT + 3] = pts[c]
        row[REC_IMPULSE : REC_IMPULSE + 3] = imp
        row[REC_SPEED] = xdot
        row[REC_SLIP] = slip
        row[REC_FEAT_A] = feat[c, 0]
        row[REC_FEAT_B] = feat[c, 1]
        row[REC_BARY : REC_BARY + 3] = bar[c]
        row[REC_LOCAL_A : REC_LOCAL_A + 3] = mtv(rot[a], ra)
        row[REC_LOCAL_B : REC_LOCAL_B + 3] = mtv(rot[b], rb)
        row[REC_NORMAL : REC_NORMAL + 3] = n
        nrec += 1
    for i in range(kind.shape[0]):
        if kind[i] == DYNAMIC:
            phi[i, :3] = mtv(rot[i], w[i])
            phi[i, 3:] = mtv(rot[i], v[i])
    return nrec


@nb.njit(cache=True)
def _move(i, tau, pos, quat, phi, mover, out_p, out_q, out_phi):
    """Pose and twist of body i after tau seconds of free motion, into row i of out_p, out_q,
    out_phi. mover: (kind, kinematic v, kinematic w, mass, inertia, prm, gravity (3,), zero
    wrench (6,))."""
    kind, kin_v, kin_w, mass, inertia, prm, gravity, ext = mover
    if kind[i] == DYNAMIC:
        advance_body_into(
            pos[i],
            quat[i],
            phi[i],
            inertia[i],
            mass[i],
            gravity,
            ext,
            tau,
            int(prm[P_METHOD]),
            prm[P_ADAPT_TOL],
            out_p[i],
            out_q[i],
            out_phi[i],
        )
        return
    out_phi[i] = phi[i]
    if kind[i] == KINEMATIC:
        q = quat_mul(quat_exp(kin_w[i] * tau), quat[i])
        out_p[i] = pos[i] + kin_v[i] * tau
        out_q[i] = q / math.sqrt(np.sum(q * q))
    else:
        out_p[i] = pos[i]
        out_q[i] = quat[i]


@nb.njit(cache=True)
def _pair_gap(a, b, pos, rot, geo, margin, scratch):
    count = pair_contacts(a, b, pos, rot, geo, margin, scratch, 0)
    best = margin
    for c in range(count):
        best = min(best, scratch[2][c])
    return best


@nb.njit(cache=True)
def _gap_at(a, b, tau, pos, quat, phi, rot, mover, geo, margin, scratch, moved):
    """Smallest gap of pair (a, b) after tau seconds of free motion of both (``moved``: pose
    arrays like pos, quat, phi to move them in)."""
    mp, mq, mf = moved
    keep_pa, keep_pb = pos[a].copy(), pos[b].copy()
    keep_ra, keep_rb = rot[a].copy(), rot[b].copy()
    for i in (a, b):
        _move(i, tau, pos, quat, phi, mover, mp, mq, mf)
    for i in (a, b):
        pos[i], rot[i] = mp[i], quat_to_mat(mq[i])
    gap = _pair_gap(a, b, pos, rot, geo, margin, scratch)
    pos[a], pos[b], rot[a], rot[b] = keep_pa, keep_pb, keep_ra, keep_rb
    return gap


@nb.njit(cache=True)
def _time_of_impact(a, b, dt, g0, g1, pos, quat, phi, rot, mover, geo, margin, scratch, moved):
    """Root of the pair's gap on [0, dt] (g0 > 0 > g1), Illinois regula falsi."""
    lo, hi = 0.0, dt
    flo, fhi = g0, g1
    side = 0
    for _ in range(100):
        t = (lo * fhi - hi * flo) / (fhi - flo)
        if hi - lo < 1e-12:
            break
        f = _gap_at(a, b, t, pos, quat, phi, rot, mover, geo, margin, scratch, moved)
        if f > 0.0:
            lo, flo = t, f
            if side == -1:
                fhi *= 0.5
            side = -1
        else:
            hi, fhi = t, f
            if side == 1:
                flo *= 0.5
            side = 1
        if abs(f) < 1e-13:
            return t
    return hi


@nb.njit(cache=True)
def _motion(vel, spin, kind, g, dt):
    """Per body, a bound (m) on how far any of its points moves in dt seconds of free motion,
    from its centre's speed and spin bound (_speeds), plus g dt^2 if it falls."""
    n = vel.shape[0]
    motion = np.zeros(n)
    for i in range(n):
        speed = math.sqrt(vel[i, 0] ** 2 + vel[i, 1] ** 2 + vel[i, 2] ** 2)
        motion[i] = dt * (speed + spin[i]) + (g * dt * dt if kind[i] == DYNAMIC else 0.0)
    return motion


@nb.njit(cache=True)
def _speeds(phi, rot, kind, kin_v, kin_w, geo, inertia):
    """(world velocity (N, 3) of each body's centre, m/s; bound on its points' speed about the
    centre, bounding radius * largest |omega| of the step, m/s). A free body's |omega| can grow
    within a step (Euler's equations keep |L|, not |omega|): |L| / I_min bounds it."""
    bound = geo[3]
    n = phi.shape[0]
    vel = np.zeros((n, 3))
    spin = np.zeros(n)
    for i in range(n):
        if kind[i] == DYNAMIC:
            r = rot[i]
            for x in range(3):
                vel[i, x] = r[x, 0] * phi[i, 3] + r[x, 1] * phi[i, 4] + r[x, 2] * phi[i, 5]
            i0, i1, i2 = inertia[i, 0], inertia[i, 1], inertia[i, 2]
            momentum = math.sqrt((i0 * phi[i, 0]) ** 2 + (i1 * phi[i, 1]) ** 2 + (i2 * phi[i, 2]) ** 2)
            w = momentum / min(i0, i1, i2)
        elif kind[i] == KINEMATIC:
            vel[i] = kin_v[i]
            w = math.sqrt(kin_w[i, 0] ** 2 + kin_w[i, 1] ** 2 + kin_w[i, 2] ** 2)
        else:
            w = 0.0
        spin[i] = bound[i] * w if w > 0.0 else 0.0  # a plane's infinite bound only if it turns
    return vel, spin


@nb.njit(cache=True)
def _pair_reach(pairs, vel, spin, kind, g, dt, out):
    """out[p]: a bound (m) on how much pair p's gap can shrink in dt seconds of free motion:
    dt (|v_a - v_b| + spin_a + spin_b), plus g dt^2 when only one of them falls."""
    for p in range(pairs.shape[0]):
        a, b = pairs[p, 0], pairs[p, 1]
        dv = math.sqrt(
            (vel[a, 0] - vel[b, 0]) ** 2 + (vel[a, 1] - vel[b, 1]) ** 2 + (vel[a, 2] - vel[b, 2]) ** 2
        )
        reach = dt * (dv + spin[a] + spin[b])
        if (kind[a] == DYNAMIC) != (kind[b] == DYNAMIC):
            reach += g * dt * dt
        out[p] = max(out[p], reach)


@nb.njit(cache=True)
def _boxes(pos, motion, kind, geo, margin):
    """Bounding boxes (lo, hi) grown by margin and motion, and which bodies move (dynamic)."""
    btype, bound = geo[0], geo[3]
    n = pos.shape[0]
    lo = np.empty((n, 3))
    hi = np.empty((n, 3))
    movable = np.zeros(n, np.bool_)
    for i in range(n):
        movable[i] = kind[i] == DYNAMIC
        if btype[i] == PLANE:
            lo[i] = -np.inf
            hi[i] = np.inf
            continue
        reach = bound[i] + margin + motion[i]
        lo[i] = pos[i] - reach
        hi[i] = pos[i] + reach
    return lo, hi, movable


@nb.njit(cache=True)
def _apart(a, b, pos, geo, margin):
    """Whether the bounding spheres of a and b are more than ``margin`` apart (cheap reject)."""
    bound = geo[3]
    reach = bound[a] + bound[b] + margin  # inf for a plane: never apart
    d0, d1, d2 = pos[a, 0] - pos[b, 0], pos[a, 1] - pos[b, 1], pos[a, 2] - pos[b, 2]
    return d0 * d0 + d1 * d1 + d2 * d2 > reach * reach


@nb.njit(cache=True)
def _detect(pairs, pos, rot, geo, slop, reach, buf, gap, touching):
    """Contacts of all pairs within margin = slop + reach[p] (m, how far the pair can close in
    the step). gap[p]: a lower bound of pair p's gap (its smallest contact gap, polytope face
    planes standing in for the distance; ``margin`` when none is that close); touching[p]: it
    has a contact within slop. The solve skips contacts beyond slop."""
    count = 0
    for p in range(pairs.shape[0]):
        a, b = pairs[p, 0], pairs[p, 1]
        margin = slop + reach[p]
        gap[p] = margin
        touching[p] = False
        if _apart(a, b, pos, geo, margin):
            continue
        before = count
        count = pair_contacts(a, b, pos, rot, geo, margin, buf, count)
        for c in range(before, count):
            gap[p] = min(gap[p], buf[2][c])
        touching[p] = count > before and gap[p] <= slop
    return count


@nb.njit(cache=True)
def _new_buffers(size, hint):
    """Contact buffers of ``size`` rows (points, normals, gaps, pairs, features, barycentric
    weights) and the shared per-point mesh-triangle hints (narrow.pair_contacts)."""
    return (
        np.empty((size, 3)),
        np.empty((size, 3)),
        np.empty(size),
        np.empty((size, 2), np.int64),
        np.empty((size, 2), np.int64),
        np.empty((size, 3)),
        hint,
    )


@nb.njit(cache=True)
def run_steps(
    first,
    n_steps,
    h,
    pos,
    quat,
    phi,
    kind,
    kin_index,
    kin_pos,
    kin_quat,
    mass,
    inertia,
    body,
    geo,
    prm,
    rec,
    nrec,
    stats,
    traj,
    every,
    origin,
    warm,
):
    """Advance n_steps outer steps from step ``first`` (time first*h). Kinematic body
    kin_index[j] follows kin_pos/kin_quat[s, j] at step s (relative to ``first``). After
    every ``every``-th step counted from step ``origin``, the poses go to traj[k] = (pos,
    quat, phi) (N, 13) if traj has room. Returns (steps done, records); stops before a step when
    ``rec`` may not hold its records (the caller grows it and calls again).
    stats: [sub-steps at impacts, impacts resolved late, contacts solved, solves, PGS sweeps,
    pairs checked for an impact inside the step]; warm: the last solve's contact impulses
    (new_warm_start), read and updated."""
    n = pos.shape[0]
    kin_v = np.zeros((n, 3))
    kin_w = np.zeros((n, 3))
    hint = np.zeros(geo[21][-1], np.int64)
    buf = _new_buffers(MAX_CONTACTS, hint)
    scratch = _new_buffers(256, hint)
    gravity = np.array([prm[P_GX], prm[P_GY], prm[P_GZ]])
    gravity_norm = math.sqrt(dot3(gravity, gravity))
    mover = (kind, kin_v, kin_w, mass, inertia, prm, gravity, np.zeros(6))
    new_pos, new_quat, new_phi = np.empty_like(pos), np.empty_like(quat), np.empty_like(phi)
    moved = (np.empty_like(pos), np.empty_like(quat), np.empty_like(phi))
    slop = prm[P_SLOP]
    model = int(prm[P_MODEL])
    max_events = int(prm[P_MAX_EVENTS]) if model == IMPULSE else 0
    gscale = 1.0 if int(prm[P_METHOD]) == 0 else 0.5
    last_count = 64
    for s in range(n_steps):
        step = first + s
        if rec.shape[0] - nrec < (max_events + 2) * last_count + 64:
            return s, nrec
        for j in range(kin_index.shape[0]):
            i = kin_index[j]
            pos[i] = kin_pos[s, j]
            quat[i] = kin_quat[s, j]
            kin_v[i] = (kin_pos[s + 1, j] - kin_pos[s, j]) / h
            kin_w[i] = (
                quat_log(quat_mul(kin_quat[s + 1, j], np.array([1.0, -1.0, -1.0, -1.0]) * kin_quat[s, j])) / h
            )
        t_local = 0.0
        subs = 0
        while True:
            dt = h - t_local
            if dt <= 1e-15:
                break
            rot = _rotations(quat)
            vel, spin = _speeds(phi, rot, kind, kin_v, kin_w, geo, inertia)
            lo, hi, movable = _boxes(pos, _motion(vel, spin, kind, gravity_norm, dt), kind, geo, slop)
            pairs = sweep_and_prune(lo, hi, movable)
            reach = np.zeros(pairs.shape[0])
            _pair_reach(pairs, vel, spin, kind, gravity_norm, dt, reach)
            gap0 = np.empty(pairs.shape[0])
            touching = np.empty(pairs.shape[0], np.bool_)
            count = _detect(pairs, pos, rot, geo, slop, reach, buf, gap0, touching)
            last_count = max(last_count, count)
            time = (first + s) * h + t_local
            if model == IMPULSE:
                nrec = _resolve(
                    buf,
                    count,
                    pos,
                    rot,
                    phi,
                    kind,
                    kin_v,
                    kin_w,
                    body,
                    prm,
                    dt,
                    gscale,
                    time,
                    step,
                    rec,
                    nrec,
                    warm,
                    stats,
                )
            else:
                stats[2] += count
                nrec = _penalty(
                    buf, count, pos, rot, phi, kind, kin_v, kin_w, body, prm, dt, time, step, rec, nrec
                )
            stats[3] += 1
            if nrec < 0:
                raise RuntimeError("run_steps: contact record buffer overflow")
            for i in range(n):
                _move(i, dt, pos, quat, phi, mover, new_pos, new_quat, new_phi)
            first_hit = dt
            if subs < max_events:
                new_rot = _rotations(new_quat)
                vel, spin = _speeds(phi, rot, kind, kin_v, kin_w, geo, inertia)  # after the solve
                _pair_reach(pairs, vel, spin, kind, gravity_norm, dt, reach)
                for p in range(pairs.shape[0]):
                    a, b = pairs[p, 0], pairs[p, 1]
                    if touching[p] or gap0[p] >= slop + reach[p] or reach[p] < prm[P_BOUNCE] * dt:
                        continue  # touching (the solve handles it), out of reach, or too slow to bounce
                    if _apart(a, b, new_pos, geo, slop):
                        continue
                    stats[5] += 1
                    g1 = _pair_gap(a, b, new_pos, new_rot, geo, slop, scratch)
                    if g1 >= -slop:
                        continue
                    within = reach[p] + 4.0 * slop
                    g0 = _pair_gap(a, b, pos, rot, geo, within, scratch)
                    if g0 <= slop or g0 - g1 < prm[P_BOUNCE] * dt:
                        continue  # touching already, or closing too slowly to bounce
                    t_hit = _time_of_impact(
                        a, b, dt, g0, g1, pos, quat, phi, rot, mover, geo, within, scratch, moved
                    )
                    first_hit = min(first_hit, t_hit)
            if first_hit < dt:
                for i in range(n):
                    _move(i, first_hit, pos, quat, phi, mover, new_pos, new_quat, new_phi)
                pos[:] = new_pos
                quat[:] = new_quat
                phi[:] = new_phi
                t_local += first_hit
                subs += 1
                stats[0] += 1
                continue
            pos[:] = new_pos
            quat[:] = new_quat
            phi[:] = new_phi
            if subs >= max_events and max_events > 0:
                stats[1] += 1
            break
        done = step + 1 - origin
        if done % every == 0 and done // every - 1 < traj.shape[0]:
            k = done // every - 1
            traj[k, :, :3] = pos
            traj[k, :, 3:7] = quat
            traj[k, :, 7:] = phi
    return n_steps, nrec
