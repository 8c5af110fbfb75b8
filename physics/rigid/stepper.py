"""The rigid-world time step (numba): free motion, contacts, impact times inside the step.

One outer step of h seconds:

1. contacts of the current configuration (gap <= slop) are resolved at the impulse level
   (impulses.resolve: projected Gauss-Seidel with Newton restitution, Coulomb friction,
   rolling resistance, penetration recovery and a warm start);
2. every body moves freely to the end of the step (integrate.advance_body_into). With the
   default integrator a body in flight follows the exact ballistic path (so impact times and
   speeds of a bouncing body are those of the closed form); a body held by a resting contact
   of the solve (a recorded non-impact contact) drifts with its new velocity instead, the
   solve having folded the step's gravity increment into it, and so stays put at rest;
3. a pair that was apart at the start (slop < gap <= how far the two can close in the step,
   from their relative velocity and spins) and penetrates at the end, having closed
   faster than ``bounce_threshold`` on average, has hit inside the step: its time of impact
   is the root of its gap along the free motion (Illinois regula falsi to 1e-12 s), and
   the whole world moves to the earliest such time and goes
   back to 1. At most ``max_events`` such sub-steps per step; later impacts are resolved at
   the step end.

Penalty models replace 1 by forces: linear f = k x + c xdot, Hunt-Crossley f = k x^p + c x^p
xdot (zero at first touch), both clamped at f >= 0, with regularised Coulomb friction.

Each resolved contact appends a record row (columns ``codes.REC_*``): time, step, bodies, world
point, impulse on a (N s, world), approach speed, slip and rolling speed after the solve,
impact flag, features, barycentric weights on b, and the contact point in each body's frame.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from physics.rigid.broad import new_sweep, sweep_pairs
from physics.rigid.codes import (
    DYNAMIC,
    IMPULSE,
    KINEMATIC,
    LINEAR,
    P_ADAPT_TOL,
    P_BOUNCE,
    P_C,
    P_EXP,
    P_GX,
    P_GY,
    P_GZ,
    P_K,
    P_MAX_EVENTS,
    P_METHOD,
    P_MODEL,
    P_SLOP,
    P_VEPS,
    REC_A,
    REC_B,
    REC_BARY,
    REC_FEAT_A,
    REC_FEAT_B,
    REC_IMPACT,
    REC_IMPULSE,
    REC_LOCAL_A,
    REC_LOCAL_B,
    REC_NORMAL,
    REC_POINT,
    REC_SLIP,
    REC_SPEED,
    REC_STEP,
    REC_TIME,
)
from physics.rigid.impulses import (
    inv_inertia_world,
    new_solver,
    resolve,
    store_twists,
    world_velocities,
)
from physics.rigid.integrate import SEMI_IMPLICIT, advance_body_into, semi_implicit_into
from physics.rigid.narrow import new_mesh_memory, pair_contacts
from physics.rigid.shapes import PLANE, SPHERE
from physics.rigid.spatial import cross, dot3, mtv, mv, quat_log, quat_mul, quat_to_mat

MAX_CONTACTS = 1 << 16


@nb.njit(cache=True)
def _rotations(quat, rot):
    """rot[i]: rotation matrix of the unit quaternion quat[i] (spatial.quat_to_mat, in place)."""
    for i in range(quat.shape[0]):
        w, x, y, z = quat[i, 0], quat[i, 1], quat[i, 2], quat[i, 3]
        rot[i, 0, 0], rot[i, 0, 1], rot[i, 0, 2] = (
            1 - 2 * (y * y + z * z),
            2 * (x * y - w * z),
            2 * (x * z + w * y),
        )
        rot[i, 1, 0], rot[i, 1, 1], rot[i, 1, 2] = (
            2 * (x * y + w * z),
            1 - 2 * (x * x + z * z),
            2 * (y * z - w * x),
        )
        rot[i, 2, 0], rot[i, 2, 1], rot[i, 2, 2] = (
            2 * (x * z - w * y),
            2 * (y * z + w * x),
            1 - 2 * (x * x + y * y),
        )


@nb.njit(cache=True)
def _apply(i, imp, r, inv_mass, iw, v, w, sign):
    v[i] += sign * inv_mass[i] * imp
    w[i] += sign * mv(iw[i], cross(r, imp))


@nb.njit(cache=True)
def _rel_velocity(a, b, ra, rb, v, w):
    return v[a] + cross(w[a], ra) - v[b] - cross(w[b], rb)


@nb.njit(cache=True)
def _penalty(buf, count, pos, rot, phi, kind, kin_v, kin_w, body, prm, dt, time, step, rec, nrec):
    """Penalty contact forces over dt (symplectic: velocities now, positions after)."""
    pts, nrm, gaps, pair, feat, bar, _ = buf
    inv_mass, inv_inertia, restitution, friction, rolling = body
    n = kind.shape[0]
    v, w, iw = np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 3, 3))
    world_velocities(kind, rot, phi, kin_v, kin_w, v, w)
    inv_inertia_world(kind, rot, inv_inertia, iw)
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
    store_twists(kind, rot, v, w, phi)
    return nrec


@nb.njit(cache=True)
def _mark_resting(rec, first, last, kind, resting):
    """resting[i]: dynamic body i has a non-impact contact among the records first..last-1
    (those of the solve just done)."""
    resting[:] = False
    for r in range(first, last):
        if rec[r, REC_IMPACT] == 0.0:
            for col in (REC_A, REC_B):
                i = int(rec[r, col])
                resting[i] = kind[i] == DYNAMIC


@nb.njit(cache=True)
def _move(i, tau, pos, quat, phi, mover, out_p, out_q, out_phi):
    """Pose and twist of body i after tau seconds of free motion, into row i of out_p, out_q,
    out_phi. mover: (kind, kinematic v, kinematic w, mass, inertia, prm, gravity (3,), zero
    wrench (6,), resting (N,): held by a resting contact of the last solve)."""
    kind, kin_v, kin_w, mass, inertia, prm, gravity, ext, resting = mover
    method = int(prm[P_METHOD])
    if kind[i] == DYNAMIC and method == SEMI_IMPLICIT and tau > 0.0:
        semi_implicit_into(
            pos[i],
            quat[i],
            phi[i],
            inertia[i],
            mass[i],
            gravity,
            ext,
            tau,
            out_p[i],
            out_q[i],
            out_phi[i],
            not resting[i],
        )
    elif kind[i] == DYNAMIC:
        advance_body_into(
            pos[i],
            quat[i],
            phi[i],
            inertia[i],
            mass[i],
            gravity,
            ext,
            tau,
            method,
            prm[P_ADAPT_TOL],
            out_p[i],
            out_q[i],
            out_phi[i],
        )
    else:
        for x in range(6):
            out_phi[i, x] = phi[i, x]
        for x in range(3):
            out_p[i, x] = pos[i, x] + kin_v[i, x] * tau if kind[i] == KINEMATIC else pos[i, x]
        if kind[i] == KINEMATIC:
            _turn(i, tau, quat, kin_w, out_q)
        else:
            for x in range(4):
                out_q[i, x] = quat[i, x]


@nb.njit(cache=True, inline="always")
def _turn(i, tau, quat, kin_w, out_q):
    """out_q[i]: quat[i] turned by the angular velocity kin_w[i] (rad/s) for tau seconds,
    exp(tau w) q normalised (spatial.quat_exp, quat_mul in scalars)."""
    r0, r1, r2 = kin_w[i, 0] * tau, kin_w[i, 1] * tau, kin_w[i, 2] * tau
    angle = math.sqrt(r0**2 + r1**2 + r2**2)
    half = 0.5 * angle
    s = math.sin(half) / angle if angle > 1e-4 else 0.5 - angle * angle / 48.0
    a0, a1, a2, a3 = math.cos(half), s * r0, s * r1, s * r2
    b0, b1, b2, b3 = quat[i, 0], quat[i, 1], quat[i, 2], quat[i, 3]
    q0 = a0 * b0 - a1 * b1 - a2 * b2 - a3 * b3
    q1 = a0 * b1 + a1 * b0 + a2 * b3 - a3 * b2
    q2 = a0 * b2 - a1 * b3 + a2 * b0 + a3 * b1
    q3 = a0 * b3 + a1 * b2 - a2 * b1 + a3 * b0
    norm = math.sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
    out_q[i, 0], out_q[i, 1], out_q[i, 2], out_q[i, 3] = q0 / norm, q1 / norm, q2 / norm, q3 / norm


@nb.njit(cache=True, _nrt=False)
def _pair_gap(a, b, pos, rot, geo, margin, scratch):
    """Smallest gap (m) of pair (a, b), at most margin (no reference counting, like
    narrow.pair_contacts)."""
    count = pair_contacts(a, b, pos, rot, geo, margin, scratch, np.int64(0))  # not a literal 0: one compile
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
def _gap_spin(spin, geo):
    """The part of each body's spin bound (_speeds) that can change a gap: none for a sphere
    (turning about its centre moves no point of it nearer to anything), all of it otherwise.
    In place."""
    btype = geo[0]
    for i in range(spin.shape[0]):
        if btype[i] == SPHERE:
            spin[i] = 0.0


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


@nb.njit(cache=True, inline="always")
def _beyond_plane(a, b, pos, rot, geo, margin):
    """Whether body a lies wholly more than ``margin`` (m) beyond plane b: its centre's height
    over the plane less its bounding radius (every one of its contact points lies within that
    radius of its centre, narrow._against_plane), with a relative guard of 1e-9 against
    rounding. A plane pair that passes gives no contact, so the narrow phase is not called."""
    param, bound = geo[2], geo[3]
    nx = rot[b, 0, 0] * param[b, 0] + rot[b, 0, 1] * param[b, 1] + rot[b, 0, 2] * param[b, 2]
    ny = rot[b, 1, 0] * param[b, 0] + rot[b, 1, 1] * param[b, 1] + rot[b, 1, 2] * param[b, 2]
    nz = rot[b, 2, 0] * param[b, 0] + rot[b, 2, 1] * param[b, 1] + rot[b, 2, 2] * param[b, 2]
    height = nx * (pos[a, 0] - pos[b, 0]) + ny * (pos[a, 1] - pos[b, 1]) + nz * (pos[a, 2] - pos[b, 2])
    height -= param[b, 3]
    clear = height - bound[a]
    return clear > margin + 1e-9 * (1.0 + bound[a] + abs(height))


@nb.njit(cache=True, inline="always")
def _cannot_touch(a, b, pos, rot, geo, margin):
    """Cheap rejects before the narrow phase: bounding spheres apart, or a body wholly beyond
    a plane (both exact: such a pair has no contact within margin)."""
    btype = geo[0]
    if btype[b] == PLANE and btype[a] != PLANE:
        return _beyond_plane(a, b, pos, rot, geo, margin)
    if btype[a] == PLANE and btype[b] != PLANE:
        return _beyond_plane(b, a, pos, rot, geo, margin)
    return _apart(a, b, pos, geo, margin)


@nb.njit(cache=True, _nrt=False)
def _detect(pairs, pos, rot, geo, slop, reach, buf, gap, touching):
    """Contacts of all pairs within margin = slop + reach[p] (m, how far the pair can close in
    the step). gap[p]: a lower bound of pair p's gap (its smallest contact gap, polytope face
    planes standing in for the distance; ``margin`` when none is that close); touching[p]: it
    has a contact within slop. The solve skips contacts beyond slop."""
    count = np.int64(0)  # a literal 0 would compile the narrow phase a second time
    for p in range(pairs.shape[0]):
        a, b = pairs[p, 0], pairs[p, 1]
        margin = slop + reach[p]
        gap[p] = margin
        touching[p] = False
        if _cannot_touch(a, b, pos, rot, geo, margin):
            continue
        before = count
        count = pair_contacts(a, b, pos, rot, geo, margin, buf, count)
        for c in range(before, count):
            gap[p] = min(gap[p], buf[2][c])
        touching[p] = count > before and gap[p] <= slop
    return count


@nb.njit(cache=True)
def _new_buffers(size, near):
    """Contact buffers of ``size`` rows (points, normals, gaps, pairs, features, barycentric
    weights) and the shared memory of the body points near meshes (narrow._mesh_closest)."""
    return (
        np.empty((size, 3)),
        np.empty((size, 3)),
        np.empty(size),
        np.empty((size, 2), np.int64),
        np.empty((size, 2), np.int64),
        np.empty((size, 3)),
        near,
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
    near = new_mesh_memory(geo[21][-1])
    # sizes as np.int64: literal sizes would compile the function once per value
    buf = _new_buffers(np.int64(MAX_CONTACTS), near)
    scratch = _new_buffers(np.int64(256), near)
    gravity = np.array([prm[P_GX], prm[P_GY], prm[P_GZ]])
    gravity_norm = math.sqrt(dot3(gravity, gravity))
    resting = np.zeros(n, np.bool_)
    mover = (kind, kin_v, kin_w, mass, inertia, prm, gravity, np.zeros(6), resting)
    new_pos, new_quat, new_phi = np.empty_like(pos), np.empty_like(quat), np.empty_like(phi)
    rot, new_rot = np.empty((n, 3, 3)), np.empty((n, 3, 3))
    solver = new_solver(np.int64(256), n, warm[0].shape[0])
    moved = (np.empty_like(pos), np.empty_like(quat), np.empty_like(phi))
    sweep = new_sweep(n)
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
            _rotations(quat, rot)
            vel, spin = _speeds(phi, rot, kind, kin_v, kin_w, geo, inertia)
            lo, hi, movable = _boxes(pos, _motion(vel, spin, kind, gravity_norm, dt), kind, geo, slop)
            pairs, sweep = sweep_pairs(lo, hi, movable, sweep)
            _gap_spin(spin, geo)  # after the boxes, whose order on x sets the contacts' order
            reach = np.zeros(pairs.shape[0])
            _pair_reach(pairs, vel, spin, kind, gravity_norm, dt, reach)
            gap0 = np.empty(pairs.shape[0])
            touching = np.empty(pairs.shape[0], np.bool_)
            count = _detect(pairs, pos, rot, geo, slop, reach, buf, gap0, touching)
            last_count = max(last_count, count)
            if count > solver.idx.shape[0]:
                solver = new_solver(2 * count, n, warm[0].shape[0])
            time = (first + s) * h + t_local
            solved = nrec
            if model == IMPULSE:
                nrec = resolve(
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
                    h,
                    dt,
                    gscale,
                    time,
                    step,
                    rec,
                    nrec,
                    warm,
                    stats,
                    solver,
                )
            else:
                stats[2] += count
                nrec = _penalty(
                    buf, count, pos, rot, phi, kind, kin_v, kin_w, body, prm, dt, time, step, rec, nrec
                )
            stats[3] += 1
            if nrec < 0:
                raise RuntimeError("run_steps: contact record buffer overflow")
            _mark_resting(rec, solved, nrec, kind, resting)
            for i in range(n):
                _move(i, dt, pos, quat, phi, mover, new_pos, new_quat, new_phi)
            first_hit = dt
            if subs < max_events:
                _rotations(new_quat, new_rot)
                vel, spin = _speeds(phi, rot, kind, kin_v, kin_w, geo, inertia)  # after the solve
                _gap_spin(spin, geo)
                _pair_reach(pairs, vel, spin, kind, gravity_norm, dt, reach)
                for p in range(pairs.shape[0]):
                    a, b = pairs[p, 0], pairs[p, 1]
                    if touching[p] or gap0[p] - reach[p] >= -slop or reach[p] < prm[P_BOUNCE] * dt:
                        continue  # touching (the solve handles it), cannot close past -slop, or too slow
                    if _cannot_touch(a, b, new_pos, new_rot, geo, slop):
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
