"""The rigid-world time step (numba): free motion, contacts, impact times inside the step.

One outer step of h seconds:

1. contacts of the current configuration (gap <= slop) are resolved at the impulse level by
   projected Gauss-Seidel on the bodies' velocities (sequential impulses; mathematically PGS
   on W = J M^-1 J^T without forming W): normal rows with Newton restitution for approaching
   contacts faster than ``bounce_threshold`` (u_N+ >= -e u_N-), else a resting target with
   gravity's velocity increment over the step folded in; tangent rows projected onto the
   Coulomb disk |r_T| <= mu r_N; rolling-resistance rows (a torque impulse bounded by
   rolling * r_N, m);
2. every body moves freely to the end of the step (integrate.advance_body);
3. a pair that was apart at the start (gap > slop) and penetrates at the end, having closed
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

from physics.rigid.integrate import advance_body
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
def _tangents(n):
    t1 = np.array([0.0, -n[2], n[1]]) if abs(n[0]) < 0.57 else np.array([-n[1], n[0], 0.0])
    t1 /= math.sqrt(dot3(t1, t1))
    return t1, cross(n, t1)


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
def _k_row(d, ra, rb, ima, imb, ia, ib):
    """Effective inverse mass of a unit impulse along d at offsets ra, rb (a gets +d)."""
    ca = cross(ra, d)
    cb = cross(rb, d)
    return ima + imb + dot3(ca, mv(ia, ca)) + dot3(cb, mv(ib, cb))


@nb.njit(cache=True)
def _apply(i, imp, r, inv_mass, iw, v, w, sign):
    v[i] += sign * inv_mass[i] * imp
    w[i] += sign * mv(iw[i], cross(r, imp))


@nb.njit(cache=True)
def _rel_velocity(a, b, ra, rb, v, w):
    return v[a] + cross(w[a], ra) - v[b] - cross(w[b], rb)


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
def _resolve(buf, count, pos, rot, phi, kind, kin_v, kin_w, body, prm, dt, gscale, time, step, rec, nrec):
    """Impulse-level contact solve (see module doc); updates phi; appends records."""
    pts, nrm, gaps, pair, feat, bar = buf
    inv_mass, inv_inertia, restitution, friction, rolling = body
    v, w = _world_velocities(kind, rot, phi, kin_v, kin_w)
    iw = _inv_inertia_world(kind, rot, inv_inertia)
    g = np.array([prm[P_GX], prm[P_GY], prm[P_GZ]])
    slop, thr, beta = prm[P_SLOP], prm[P_BOUNCE], prm[P_BETA]
    use = np.zeros(count, np.bool_)
    nc = 0
    for c in range(count):
        if gaps[c] <= slop:
            use[c] = True
            nc += 1
    if nc == 0:
        return nrec
    idx = np.empty(nc, np.int64)
    k = 0
    for c in range(count):
        if use[c]:
            idx[k] = c
            k += 1
    ra = np.empty((nc, 3))
    rb = np.empty((nc, 3))
    frame = np.empty((nc, 3, 3))
    kin = np.empty((nc, 5))
    target = np.empty((nc, 3))
    mu = np.empty(nc)
    roll = np.empty(nc)
    speed0 = np.empty(nc)
    impact = np.zeros(nc, np.bool_)
    r = np.zeros((nc, 5))
    for k in range(nc):
        c = idx[k]
        a, b = pair[c, 0], pair[c, 1]
        n = nrm[c]
        t1, t2 = _tangents(n)
        frame[k, 0], frame[k, 1], frame[k, 2] = n, t1, t2
        ra[k] = pts[c] - pos[a]
        rb[k] = pts[c] - pos[b]
        for j in range(3):
            kin[k, j] = _k_row(frame[k, j], ra[k], rb[k], inv_mass[a], inv_mass[b], iw[a], iw[b])
        for j in range(2):  # rolling rows: pure torque impulses about t1, t2
            d = frame[k, 1 + j]
            kin[k, 3 + j] = dot3(d, mv(iw[a] + iw[b], d))
        mu[k] = math.sqrt(friction[a] * friction[b])
        roll[k] = max(rolling[a], rolling[b])
        u = _rel_velocity(a, b, ra[k], rb[k], v, w)
        un = dot3(u, n)
        speed0[k] = -un
        if -un > thr:
            impact[k] = True
            target[k, 0] = -math.sqrt(restitution[a] * restitution[b]) * un
            target[k, 1] = 0.0
            target[k, 2] = 0.0
        else:
            ga = g * gscale * dt if kind[a] == DYNAMIC else np.zeros(3)
            gb = g * gscale * dt if kind[b] == DYNAMIC else np.zeros(3)
            dg = ga - gb
            pen = max(-gaps[c] - slop, 0.0)
            target[k, 0] = (beta * pen - max(gaps[c], 0.0)) / dt - dot3(dg, n)
            target[k, 1] = -(dot3(dg, t1))
            target[k, 2] = -(dot3(dg, t2))
    # Jacobian rows j = n, t1, t2 (linear d, angular ra x d / rb x d) and their responses
    # (M^-1 J^T: linear ima d, angular Iw^-1 (r x d)); rows 3, 4: rolling about t1, t2.
    ang_a = np.zeros((nc, 5, 3))
    ang_b = np.zeros((nc, 5, 3))
    res_a = np.zeros((nc, 5, 3))
    res_b = np.zeros((nc, 5, 3))
    for k in range(nc):
        c = idx[k]
        a, b = pair[c, 0], pair[c, 1]
        for j in range(3):
            ang_a[k, j] = cross(ra[k], frame[k, j])
            ang_b[k, j] = cross(rb[k], frame[k, j])
        for j in range(2):
            ang_a[k, 3 + j] = frame[k, 1 + j]
            ang_b[k, 3 + j] = frame[k, 1 + j]
        for j in range(5):
            res_a[k, j] = mv(iw[a], ang_a[k, j])
            res_b[k, j] = mv(iw[b], ang_b[k, j])
    iters = int(prm[P_ITER])
    tol = prm[P_TOL]
    for _ in range(iters):
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
                x1 = (
                    r[k, 1]
                    + (target[k, 1] - _row_velocity(k, 1, a, b, frame, ang_a, ang_b, v, w, True)) / kin[k, 1]
                )
                x2 = (
                    r[k, 2]
                    + (target[k, 2] - _row_velocity(k, 2, a, b, frame, ang_a, ang_b, v, w, True)) / kin[k, 2]
                )
                lim = mu[k] * rn
                mag = math.sqrt(x1 * x1 + x2 * x2)
                if mag > lim:
                    x1 *= lim / mag
                    x2 *= lim / mag
                _row_apply(k, 1, a, b, x1 - r[k, 1], frame, res_a, res_b, ima, imb, v, w, True)
                _row_apply(k, 2, a, b, x2 - r[k, 2], frame, res_a, res_b, ima, imb, v, w, True)
                biggest = max(biggest, abs(x1 - r[k, 1]), abs(x2 - r[k, 2]))
                r[k, 1] = x1
                r[k, 2] = x2
            if roll[k] > 0.0:
                y1 = r[k, 3] - _row_velocity(k, 3, a, b, frame, ang_a, ang_b, v, w, False) / kin[k, 3]
                y2 = r[k, 4] - _row_velocity(k, 4, a, b, frame, ang_a, ang_b, v, w, False) / kin[k, 4]
                lim = roll[k] * rn
                mag = math.sqrt(y1 * y1 + y2 * y2)
                if mag > lim:
                    y1 *= lim / mag
                    y2 *= lim / mag
                _row_apply(k, 3, a, b, y1 - r[k, 3], frame, res_a, res_b, ima, imb, v, w, False)
                _row_apply(k, 4, a, b, y2 - r[k, 4], frame, res_a, res_b, ima, imb, v, w, False)
                r[k, 3] = y1
                r[k, 4] = y2
            change = max(change, biggest)
            scale = max(scale, abs(r[k, 0]))
        if change <= tol * max(scale, 1e-30):
            break
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
        n, t1, t2 = frame[k, 0], frame[k, 1], frame[k, 2]
        u = _rel_velocity(a, b, ra[k], rb[k], v, w)
        ut = u - (dot3(u, n)) * n - target[k, 1] * t1 - target[k, 2] * t2  # with gravity's increment
        wr = w[a] - w[b]
        wt = wr - (dot3(wr, n)) * n
        row = rec[nrec]
        row[REC_TIME] = time
        row[REC_STEP] = step
        row[REC_A] = a
        row[REC_B] = b
        row[REC_POINT : REC_POINT + 3] = pts[c]
        row[REC_IMPULSE : REC_IMPULSE + 3] = r[k, 0] * n + r[k, 1] * t1 + r[k, 2] * t2
        row[REC_SPEED] = speed0[k]
        row[REC_SLIP] = math.sqrt(dot3(ut, ut))
        row[REC_ROLL] = math.sqrt(dot3(wt, wt)) * math.sqrt(dot3(ra[k], ra[k]))
        row[REC_IMPACT] = 1.0 if impact[k] else 0.0
        row[REC_FEAT_A] = feat[c, 0]
        row[REC_FEAT_B] = feat[c, 1]
        row[REC_BARY : REC_BARY + 3] = bar[c]
        row[REC_LOCAL_A : REC_LOCAL_A + 3] = mtv(rot[a], ra[k])
        row[REC_LOCAL_B : REC_LOCAL_B + 3] = mtv(rot[b], rb[k])
        row[REC_NORMAL : REC_NORMAL + 3] = n
        nrec += 1
    return nrec


@nb.njit(cache=True)
def _penalty(buf, count, pos, rot, phi, kind, kin_v, kin_w, body, prm, dt, time, step, rec, nrec):
    """Penalty contact forces over dt (symplectic: velocities now, positions after)."""
    pts, nrm, gaps, pair, feat, bar = buf
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
def _move(i, tau, pos, quat, phi, kind, kin_v, kin_w, mass, inertia, prm):
    """Pose and twist of body i after tau seconds of free motion."""
    if kind[i] == DYNAMIC:
        g = np.array([prm[P_GX], prm[P_GY], prm[P_GZ]])
        return advance_body(
            pos[i],
            quat[i],
            phi[i],
            inertia[i],
            mass[i],
            g,
            np.zeros(6),
            tau,
            int(prm[P_METHOD]),
            prm[P_ADAPT_TOL],
        )
    if kind[i] == KINEMATIC:
        q = quat_mul(quat_exp(kin_w[i] * tau), quat[i])
        return pos[i] + kin_v[i] * tau, q / math.sqrt(dot3(q, q)), phi[i].copy()
    return pos[i].copy(), quat[i].copy(), phi[i].copy()


@nb.njit(cache=True)
def _pair_gap(a, b, pos, rot, geo, margin, scratch):
    count = pair_contacts(a, b, pos, rot, geo, margin, scratch, 0)
    best = margin
    for c in range(count):
        best = min(best, scratch[2][c])
    return best


@nb.njit(cache=True)
def _gap_at(a, b, tau, pos, quat, phi, rot, kind, kin_v, kin_w, mass, inertia, prm, geo, margin, scratch):
    """Smallest gap of pair (a, b) after tau seconds of free motion of both."""
    keep_pa, keep_pb = pos[a].copy(), pos[b].copy()
    keep_ra, keep_rb = rot[a].copy(), rot[b].copy()
    pa, qa, _ = _move(a, tau, pos, quat, phi, kind, kin_v, kin_w, mass, inertia, prm)
    pb, qb, _ = _move(b, tau, pos, quat, phi, kind, kin_v, kin_w, mass, inertia, prm)
    pos[a], rot[a] = pa, quat_to_mat(qa)
    pos[b], rot[b] = pb, quat_to_mat(qb)
    gap = _pair_gap(a, b, pos, rot, geo, margin, scratch)
    pos[a], pos[b], rot[a], rot[b] = keep_pa, keep_pb, keep_ra, keep_rb
    return gap


@nb.njit(cache=True)
def _time_of_impact(
    a, b, dt, g0, g1, pos, quat, phi, rot, kind, kin_v, kin_w, mass, inertia, prm, geo, margin, scratch
):
    """Root of the pair's gap on [0, dt] (g0 > 0 > g1), Illinois regula falsi."""
    lo, hi = 0.0, dt
    flo, fhi = g0, g1
    side = 0
    for _ in range(100):
        t = (lo * fhi - hi * flo) / (fhi - flo)
        if hi - lo < 1e-12:
            break
        f = _gap_at(
            a, b, t, pos, quat, phi, rot, kind, kin_v, kin_w, mass, inertia, prm, geo, margin, scratch
        )
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
def _boxes(pos, rot, phi, kind, kin_v, kin_w, geo, prm, margin, dt):
    btype, bound = geo[0], geo[3]
    n = pos.shape[0]
    lo = np.empty((n, 3))
    hi = np.empty((n, 3))
    movable = np.zeros(n, np.bool_)
    motion = np.zeros(n)
    g = math.sqrt(prm[P_GX] ** 2 + prm[P_GY] ** 2 + prm[P_GZ] ** 2)
    for i in range(n):
        if btype[i] == PLANE:
            lo[i] = -np.inf
            hi[i] = np.inf
            continue
        if kind[i] == DYNAMIC:
            movable[i] = True
            speed = math.sqrt(dot3(phi[i, 3:], phi[i, 3:])) + bound[i] * math.sqrt(
                dot3(phi[i, :3], phi[i, :3])
            )
            motion[i] = dt * speed + dt * dt * g
        elif kind[i] == KINEMATIC:
            motion[i] = dt * (
                math.sqrt(dot3(kin_v[i], kin_v[i])) + bound[i] * math.sqrt(dot3(kin_w[i], kin_w[i]))
            )
        reach = bound[i] + margin + motion[i]
        lo[i] = pos[i] - reach
        hi[i] = pos[i] + reach
    return lo, hi, movable, motion


@nb.njit(cache=True)
def _apart(a, b, pos, geo, margin):
    """Whether the bounding spheres of a and b are more than ``margin`` apart (cheap reject)."""
    bound = geo[3]
    reach = bound[a] + bound[b] + margin  # inf for a plane: never apart
    d0, d1, d2 = pos[a, 0] - pos[b, 0], pos[a, 1] - pos[b, 1], pos[a, 2] - pos[b, 2]
    return d0 * d0 + d1 * d1 + d2 * d2 > reach * reach


@nb.njit(cache=True)
def _detect(pairs, pos, rot, geo, margin, buf, touching):
    """Contacts of all pairs; touching[p] tells whether pair p has one within margin."""
    count = 0
    for p in range(pairs.shape[0]):
        touching[p] = False
        if _apart(pairs[p, 0], pairs[p, 1], pos, geo, margin):
            continue
        before = count
        count = pair_contacts(pairs[p, 0], pairs[p, 1], pos, rot, geo, margin, buf, count)
        touching[p] = count > before
    return count


@nb.njit(cache=True)
def _new_buffers(size):
    return (
        np.empty((size, 3)),
        np.empty((size, 3)),
        np.empty(size),
        np.empty((size, 2), np.int64),
        np.empty((size, 2), np.int64),
        np.empty((size, 3)),
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
):
    """Advance n_steps outer steps from step ``first`` (time first*h). Kinematic body
    kin_index[j] follows kin_pos/kin_quat[s, j] at step s (relative to ``first``). After
    every ``every``-th step counted from step ``origin``, the poses go to traj[k] = (pos,
    quat, phi) (N, 13) if traj has room. Returns (steps done, records); stops before a step when
    ``rec`` may not hold its records (the caller grows it and calls again).
    stats: [sub-steps at impacts, impacts resolved late, contacts, solves]."""
    n = pos.shape[0]
    kin_v = np.zeros((n, 3))
    kin_w = np.zeros((n, 3))
    buf = _new_buffers(MAX_CONTACTS)
    scratch = _new_buffers(256)
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
            lo, hi, movable, motion = _boxes(pos, rot, phi, kind, kin_v, kin_w, geo, prm, slop, dt)
            pairs = sweep_and_prune(lo, hi, movable)
            touching = np.empty(pairs.shape[0], np.bool_)
            count = _detect(pairs, pos, rot, geo, slop, buf, touching)
            stats[2] += count
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
                )
            else:
                nrec = _penalty(
                    buf, count, pos, rot, phi, kind, kin_v, kin_w, body, prm, dt, time, step, rec, nrec
                )
            stats[3] += 1
            if nrec < 0:
                raise RuntimeError("run_steps: contact record buffer overflow")
            new_pos = np.empty_like(pos)
            new_quat = np.empty_like(quat)
            new_phi = np.empty_like(phi)
            for i in range(n):
                new_pos[i], new_quat[i], new_phi[i] = _move(
                    i, dt, pos, quat, phi, kind, kin_v, kin_w, mass, inertia, prm
                )
            first_hit = dt
            if subs < max_events:
                new_rot = _rotations(new_quat)
                for p in range(pairs.shape[0]):
                    if touching[p]:
                        continue  # in contact already: the solve handles it
                    a, b = pairs[p, 0], pairs[p, 1]
                    if _apart(a, b, new_pos, geo, slop):
                        continue
                    g1 = _pair_gap(a, b, new_pos, new_rot, geo, slop, scratch)
                    if g1 >= -slop:
                        continue
                    reach = motion[a] + motion[b] + 4.0 * slop
                    g0 = _pair_gap(a, b, pos, rot, geo, reach, scratch)
                    if g0 <= slop or g0 - g1 < prm[P_BOUNCE] * dt:
                        continue  # touching already, or closing too slowly to bounce
                    t_hit = _time_of_impact(
                        a,
                        b,
                        dt,
                        g0,
                        g1,
                        pos,
                        quat,
                        phi,
                        rot,
                        kind,
                        kin_v,
                        kin_w,
                        mass,
                        inertia,
                        prm,
                        geo,
                        reach,
                        scratch,
                    )
                    first_hit = min(first_hit, t_hit)
            if first_hit < dt:
                for i in range(n):
                    pos[i], quat[i], phi[i] = _move(
                        i, first_hit, pos, quat, phi, kind, kin_v, kin_w, mass, inertia, prm
                    )
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
