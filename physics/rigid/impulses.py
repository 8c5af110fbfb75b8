"""The impulse-level contact solve of one (sub-)step (numba; stepper module doc, step 1).

Contacts touching (gap <= slop) are resolved by projected Gauss-Seidel on the bodies'
velocities (sequential impulses; mathematically PGS on W = J M^-1 J^T without forming W):
normal rows with Newton restitution for approaching contacts faster than ``bounce_threshold``
(u_N+ >= -e u_N-), else a resting target (penetration beyond slop recovered at beta * depth / h,
gravity's velocity increment over the sub-step folded in); tangent rows projected onto the
Coulomb disk |r_T| <= mu r_N; rolling-resistance rows (a torque impulse bounded by
rolling * r_N, m). Resting contacts found in the previous solve (same bodies and features)
start from its force times dt (warm start); sweeps stop when no body's momentum changes over
a sweep by more than ``tolerance`` times the largest normal impulse, and a contact whose
bodies have settled is skipped meanwhile (_sweeps). The solve allocates nothing: its scratch
(new_solver) lives for the whole run.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba as nb
import numpy as np

from jassy.jit import drop_stale_cache
from physics.rigid import codes, integrate
from physics.rigid.codes import (
    DYNAMIC,
    KINEMATIC,
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
    REC_ROLL,
    REC_SLIP,
    REC_SPEED,
    REC_STEP,
    REC_TIME,
)
from physics.rigid.integrate import SEMI_IMPLICIT

drop_stale_cache(__file__, [codes, integrate])  # its cache holds copies of their kernels and constants


@nb.njit(cache=True, _nrt=False)
def world_velocities(kind, rot, phi, kin_v, kin_w, v, w):
    """World linear and angular velocities (m/s, rad/s) of every body's centre into v, w."""
    for i in range(kind.shape[0]):
        for x in range(3):
            if kind[i] == DYNAMIC:
                w[i, x] = rot[i, x, 0] * phi[i, 0] + rot[i, x, 1] * phi[i, 1] + rot[i, x, 2] * phi[i, 2]
                v[i, x] = rot[i, x, 0] * phi[i, 3] + rot[i, x, 1] * phi[i, 4] + rot[i, x, 2] * phi[i, 5]
            elif kind[i] == KINEMATIC:
                v[i, x], w[i, x] = kin_v[i, x], kin_w[i, x]
            else:
                v[i, x] = w[i, x] = 0.0


@nb.njit(cache=True, _nrt=False)
def store_twists(kind, rot, v, w, phi):
    """The dynamic bodies' twists phi (body frame) from their world velocities v, w."""
    for i in range(kind.shape[0]):
        if kind[i] == DYNAMIC:
            for x in range(3):
                phi[i, x] = rot[i, 0, x] * w[i, 0] + rot[i, 1, x] * w[i, 1] + rot[i, 2, x] * w[i, 2]
                phi[i, 3 + x] = rot[i, 0, x] * v[i, 0] + rot[i, 1, x] * v[i, 1] + rot[i, 2, x] * v[i, 2]


@nb.njit(cache=True, _nrt=False)
def inv_inertia_world(kind, rot, inv_inertia, out):
    """World inverse inertia tensors (1/(kg m^2)) into out; zero for static and kinematic bodies."""
    for i in range(kind.shape[0]):
        dynamic = kind[i] == DYNAMIC
        for x in range(3):
            for y in range(3):
                out[i, x, y] = (
                    rot[i, x, 0] * inv_inertia[i, 0] * rot[i, y, 0]
                    + rot[i, x, 1] * inv_inertia[i, 1] * rot[i, y, 1]
                    + rot[i, x, 2] * inv_inertia[i, 2] * rot[i, y, 2]
                    if dynamic
                    else 0.0
                )


class WarmStart(NamedTuple):
    """Contact forces of the last solve for warm starting the next (new_warm_start)."""

    keys: np.ndarray  # (W, 4) body a, body b, feature of a, feature of b
    forces: np.ndarray  # (W, 6) world force (N) and rolling torque (N m)
    size: np.ndarray  # (1,) rows in use


def new_warm_start(size: int) -> WarmStart:
    """An empty WarmStart of ``size`` rows."""
    return WarmStart(np.empty((size, 4), np.int64), np.empty((size, 6)), np.zeros(1, np.int64))


class SolverScratch(NamedTuple):
    """The contact solve's scratch (new_solver), rows per contact, per body and per warm-start
    entry; allocated once per run."""

    idx: np.ndarray  # (rows,) the contact's row in the contact buffers
    ra: np.ndarray  # (rows, 3) lever arm on a, m
    rb: np.ndarray  # (rows, 3) lever arm on b, m
    frame: np.ndarray  # (rows, 3, 3) rows n, t1, t2
    ang_a: np.ndarray  # (rows, 5, 3) angular Jacobian rows of a: n, t1, t2, rolling about t1, t2
    ang_b: np.ndarray  # (rows, 5, 3) the same for b
    res_a: np.ndarray  # (rows, 5, 3) responses I^-1 J^T of a
    res_b: np.ndarray  # (rows, 5, 3) responses I^-1 J^T of b
    mass: np.ndarray  # (rows, 5) effective masses 1 / (J M^-1 J^T)
    target: np.ndarray  # (rows, 3) velocity targets along n, t1, t2, m/s
    bias: np.ndarray  # (rows, 5) targets with a fixed body b's velocity folded in
    mu: np.ndarray  # (rows,) friction coefficient
    roll: np.ndarray  # (rows,) rolling resistance length, m
    speed: np.ndarray  # (rows,) approach speed, m/s
    impact: np.ndarray  # (rows,) bool: approach faster than the bounce threshold
    r: np.ndarray  # (rows, 5) impulses, N s (rolling rows N m s)
    v: np.ndarray  # (bodies, 3) world linear velocity being solved, m/s
    w: np.ndarray  # (bodies, 3) world angular velocity being solved, rad/s
    iw: np.ndarray  # (bodies, 3, 3) world inverse inertia
    head: np.ndarray  # (bodies,) warm-start list head
    next: np.ndarray  # (warm rows,) warm-start list link
    used: np.ndarray  # (warm rows,) bool: warm-start entry taken
    swept: np.ndarray  # (bodies,) the last sweep that changed the body
    v0: np.ndarray  # (bodies, 3) linear velocity at the start of the sweep
    w0: np.ndarray  # (bodies, 3) angular velocity at the start of the sweep
    seen: np.ndarray  # (bodies,) the last sweep that updated the body
    touched: np.ndarray  # (bodies,) the bodies the sweep updated


def new_solver(rows, n_bodies, warm_rows):
    """The contact solve's scratch (SolverScratch) for up to ``rows`` contacts, allocated once
    per run and grown with the contacts (in numpy: a kernel would be one more compile on a
    fresh install's first run, before its compile units start)."""
    return SolverScratch(
        np.empty(rows, np.int64),
        np.empty((rows, 3)),
        np.empty((rows, 3)),
        np.empty((rows, 3, 3)),
        np.empty((rows, 5, 3)),
        np.empty((rows, 5, 3)),
        np.empty((rows, 5, 3)),
        np.empty((rows, 5, 3)),
        np.empty((rows, 5)),
        np.empty((rows, 3)),
        np.empty((rows, 5)),
        np.empty(rows),
        np.empty(rows),
        np.empty(rows),
        np.empty(rows, np.bool_),
        np.empty((rows, 5)),
        np.empty((n_bodies, 3)),
        np.empty((n_bodies, 3)),
        np.empty((n_bodies, 3, 3)),
        np.empty(n_bodies, np.int64),
        np.empty(warm_rows, np.int64),
        np.empty(warm_rows, np.bool_),
        np.empty(n_bodies, np.int64),
        np.empty((n_bodies, 3)),
        np.empty((n_bodies, 3)),
        np.empty(n_bodies, np.int64),
        np.empty(n_bodies, np.int64),
    )


@nb.njit(cache=True, _nrt=False)
def _contact_frames(buf, nc, pos, inv_mass, solver):
    """Per contact k < nc: frame rows (n, t1, t2), lever arms, Jacobian rows (angular parts;
    rows 3, 4 roll about t1, t2), responses I^-1 J^T and effective masses."""
    pts, nrm, pair = buf.points, buf.normals, buf.pairs
    idx, ra, rb, frame = solver.idx, solver.ra, solver.rb, solver.frame
    ang_a, ang_b = solver.ang_a, solver.ang_b
    for k in range(nc):
        c = idx[k]
        a, b = pair[c, 0], pair[c, 1]
        fixed_b = inv_mass[b] == 0.0
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
        for j in range(3):  # contact rows: linear along the frame row, angular r x d
            d0, d1, d2 = frame[k, j, 0], frame[k, j, 1], frame[k, j, 2]
            ang_a[k, j, 0] = ra[k, 1] * d2 - ra[k, 2] * d1
            ang_a[k, j, 1] = ra[k, 2] * d0 - ra[k, 0] * d2
            ang_a[k, j, 2] = ra[k, 0] * d1 - ra[k, 1] * d0
            ang_b[k, j, 0] = rb[k, 1] * d2 - rb[k, 2] * d1
            ang_b[k, j, 1] = rb[k, 2] * d0 - rb[k, 0] * d2
            ang_b[k, j, 2] = rb[k, 0] * d1 - rb[k, 1] * d0
            _response(k, j, a, b, inv_mass[a] + inv_mass[b], fixed_b, solver)
        for j in range(3, 5):  # rolling rows: angular only, about t1 and t2
            for x in range(3):
                ang_a[k, j, x] = ang_b[k, j, x] = frame[k, j - 2, x]
            _response(k, j, a, b, 0.0, fixed_b, solver)


@nb.njit(cache=True, inline="always")
def _response(k, j, a, b, linear, fixed_b, solver):
    """Responses I^-1 J^T (angular) of row j of contact k on a and b, and the row's effective
    mass: 1 / (``linear`` (1/m_a + 1/m_b, or 0 for a rolling row) + the angular terms). A
    fixed b (``fixed_b``: static or kinematic, zero inverse inertia) adds nothing, and its
    response is never read (_row_apply skips it), so neither is computed."""
    ang_a, ang_b, res_a, res_b, iw = (
        solver.ang_a,
        solver.ang_b,
        solver.res_a,
        solver.res_b,
        solver.iw,
    )
    inverse = linear
    for x in range(3):
        res_a[k, j, x] = (
            iw[a, x, 0] * ang_a[k, j, 0] + iw[a, x, 1] * ang_a[k, j, 1] + iw[a, x, 2] * ang_a[k, j, 2]
        )
        if fixed_b:
            inverse += ang_a[k, j, x] * res_a[k, j, x]
            continue
        res_b[k, j, x] = (
            iw[b, x, 0] * ang_b[k, j, 0] + iw[b, x, 1] * ang_b[k, j, 1] + iw[b, x, 2] * ang_b[k, j, 2]
        )
        inverse += ang_a[k, j, x] * res_a[k, j, x] + ang_b[k, j, x] * res_b[k, j, x]
    solver.mass[k, j] = 1.0 / inverse


@nb.njit(cache=True, inline="always")
def _row_velocity(k, j, a, b, jacobian, vel, linear, both):
    """Relative velocity of contact k along Jacobian row j (a's part, and b's if ``both``):
    jacobian = (frame, angular rows of a, angular rows of b), vel = (v, w) of the bodies."""
    frame, ang_a, ang_b = jacobian
    v, w = vel
    u = 0.0
    for x in range(3):
        u += ang_a[k, j, x] * w[a, x]
        if linear:
            u += frame[k, j, x] * v[a, x]
    if both:
        for x in range(3):
            u -= ang_b[k, j, x] * w[b, x]
            if linear:
                u -= frame[k, j, x] * v[b, x]
    return u


@nb.njit(cache=True, inline="always")
def _row_apply(k, j, a, b, impulse, response, inv_masses, vel, linear):
    """Apply ``impulse`` along row j of contact k to both bodies (b gets the reaction):
    response = (frame, responses of a, responses of b), inv_masses = (1/m_a, 1/m_b), vel =
    (v, w) of the bodies. A body of inverse mass 0 (static or kinematic) keeps its velocity
    and is not written: contacts of different bodies on the same wall then do not wait on
    each other's stores."""
    frame, res_a, res_b = response
    ima, imb = inv_masses
    v, w = vel
    if ima > 0.0:
        for x in range(3):
            w[a, x] += impulse * res_a[k, j, x]
            if linear:
                v[a, x] += impulse * ima * frame[k, j, x]
    if imb > 0.0:
        for x in range(3):
            w[b, x] -= impulse * res_b[k, j, x]
            if linear:
                v[b, x] -= impulse * imb * frame[k, j, x]


@nb.njit(cache=True, inline="always")
def _disk(x1, x2, limit):
    """(x1, x2) projected onto the disk of radius ``limit``."""
    mag = math.sqrt(x1 * x1 + x2 * x2)
    if mag > limit:
        f = limit / mag
        return x1 * f, x2 * f
    return x1, x2


@nb.njit(cache=True, _nrt=False)
def _select(gaps, count, slop, idx):
    """Rows of the contacts touching (gap <= slop) into idx; returns how many."""
    nc = 0
    for c in range(count):
        if gaps[c] <= slop:
            idx[nc] = c
            nc += 1
    return nc


@nb.njit(cache=True, _nrt=False)
def _targets(m, opt, buf, nc, dt, solver):
    """Per contact: friction and rolling coefficients, approach speed, and the velocity targets:
    Newton restitution for an impact (approach faster than the bounce threshold), else resting:
    penetration recovery at beta * depth / h (the outer step: a short sub-step dt after an
    impact must not turn a small penetration into a launch), a touching gap closed within dt,
    gravity's velocity increment over dt folded in. The bias adds a
    fixed body b's (constant) velocity along each row to the target, so sweeps need not read it."""
    gaps, pair = buf.gaps, buf.pairs
    kind, inv_mass, restitution, friction, rolling = m.kind, m.inv_mass, m.restitution, m.friction, m.rolling
    idx, frame, ang_a, ang_b = solver.idx, solver.frame, solver.ang_a, solver.ang_b
    target, bias, v, w = solver.target, solver.bias, solver.v, solver.w
    slop, thr, beta, h = opt.slop, opt.bounce_threshold, opt.beta, opt.h
    gscale = 1.0 if opt.integrator == SEMI_IMPLICIT else 0.5  # the integrators' gravity share
    gx, gy, gz = opt.gx * gscale * dt, opt.gy * gscale * dt, opt.gz * gscale * dt
    for k in range(nc):
        c = idx[k]
        a, b = pair[c, 0], pair[c, 1]
        solver.mu[k] = math.sqrt(friction[a] * friction[b])
        solver.roll[k] = max(rolling[a], rolling[b])
        un = _row_velocity(k, 0, a, b, (frame, ang_a, ang_b), (v, w), True, True)
        solver.speed[k] = -un
        solver.impact[k] = -un > thr
        target[k, 0] = target[k, 1] = target[k, 2] = 0.0
        if solver.impact[k]:
            target[k, 0] = -math.sqrt(restitution[a] * restitution[b]) * un
        else:
            dyn = (1.0 if kind[a] == DYNAMIC else 0.0) - (1.0 if kind[b] == DYNAMIC else 0.0)
            pen = max(-gaps[c] - slop, 0.0)
            target[k, 0] = beta * pen / h - max(gaps[c], 0.0) / dt
            for j in range(3):
                target[k, j] -= dyn * (gx * frame[k, j, 0] + gy * frame[k, j, 1] + gz * frame[k, j, 2])
        fixed = inv_mass[b] == 0.0
        for j in range(5):
            bias[k, j] = target[k, j] if j < 3 else 0.0
            if fixed:  # b's own velocity along row j (its part of the row, taken as "a")
                bias[k, j] += _row_velocity(k, j, b, b, (frame, ang_b, ang_b), (v, w), j < 3, False)


@nb.njit(cache=True, inline="always")
def link_warm(warm, solver):
    """Link the last solve's contacts (warm.keys, rows < warm.size) into one list per body a
    (solver.head, solver.next; in the last solve's order), none of them taken (solver.used)."""
    keys, head, nxt, used = warm.keys, solver.head, solver.next, solver.used
    for i in range(head.shape[0]):
        head[i] = -1
    for e in range(warm.size[0] - 1, -1, -1):
        nxt[e] = head[keys[e, 0]]
        head[keys[e, 0]] = e
        used[e] = False


@nb.njit(cache=True, inline="always")
def warm_match(buf, c, warm, solver):
    """The first untaken last-solve contact (link_warm) with the bodies and features of
    contact c of ``buf``, or -1."""
    pair, feat, keys, used = buf.pairs, buf.features, warm.keys, solver.used
    e = solver.head[pair[c, 0]]
    while e >= 0:
        if not used[e] and keys[e, 1] == pair[c, 1] and keys[e, 2] == feat[c, 0] and keys[e, 3] == feat[c, 1]:
            return e
        e = solver.next[e]
    return -1


@nb.njit(cache=True, _nrt=False)
def _warm_impulses(buf, nc, dt, warm, inv_mass, solver):
    """Initial impulses r from the last solve's contacts with the same (a, b, features): its
    force and rolling torque times dt, projected on the new frame and cones, and applied."""
    pair = buf.pairs
    vals = warm.forces
    idx, frame, impact, r = solver.idx, solver.frame, solver.impact, solver.r
    link_warm(warm, solver)
    for k in range(nc):
        for j in range(5):
            r[k, j] = 0.0
        if impact[k]:
            continue
        e = warm_match(buf, idx[k], warm, solver)
        if e < 0:
            continue
        solver.used[e] = True
        for j in range(3):
            r[k, j] = dt * (
                vals[e, 0] * frame[k, j, 0] + vals[e, 1] * frame[k, j, 1] + vals[e, 2] * frame[k, j, 2]
            )
        for j in range(2):
            r[k, 3 + j] = dt * (
                vals[e, 3] * frame[k, 1 + j, 0]
                + vals[e, 4] * frame[k, 1 + j, 1]
                + vals[e, 5] * frame[k, 1 + j, 2]
            )
        r[k, 0] = max(r[k, 0], 0.0)
        r[k, 1], r[k, 2] = _disk(r[k, 1], r[k, 2], solver.mu[k] * r[k, 0])
        r[k, 3], r[k, 4] = _disk(r[k, 3], r[k, 4], solver.roll[k] * r[k, 0])
    _apply_impulses(pair, nc, inv_mass, solver)


@nb.njit(cache=True, _nrt=False)
def _apply_impulses(pair, nc, inv_mass, solver):
    """Apply every contact's impulses r to its bodies' velocities."""
    idx, frame, res_a, res_b, r = (
        solver.idx,
        solver.frame,
        solver.res_a,
        solver.res_b,
        solver.r,
    )
    v, w = solver.v, solver.w
    for k in range(nc):
        a, b = pair[idx[k], 0], pair[idx[k], 1]
        ima, imb = inv_mass[a], inv_mass[b]
        for j in range(3):
            if r[k, j] != 0.0:
                _row_apply(k, j, a, b, r[k, j], (frame, res_a, res_b), (ima, imb), (v, w), True)
        for j in range(3, 5):
            if r[k, j] != 0.0:
                _row_apply(k, j, a, b, r[k, j], (frame, res_a, res_b), (ima, imb), (v, w), False)


@nb.njit(cache=True, _nrt=False)
def _sweeps(m, opt, pair, nc, rot, solver):
    """Projected Gauss-Seidel sweeps (normal row, friction disk, rolling disk of each contact)
    until no body's momentum changes over a sweep by more than tol times the largest normal
    impulse so far; returns the sweeps done (at most iters).

    The test is on the bodies, not on the impulses: where a body rests on more contacts than
    its motion needs (a box on four corners), the sweeps may shift impulse from one contact to
    another at a steady rate without changing any velocity, and such a drift would never fall
    below a tolerance on the impulses. A contact is updated only while one of its bodies moves:
    it is skipped when neither body changed over the last sweep. So a settled island
    (food on a fixed wok) stops sweeping while a busier one goes on."""
    inv_mass, inv_inertia, iters, tol = m.inv_mass, m.inv_inertia, opt.iterations, opt.tolerance
    idx, mu, roll, r, changed = solver.idx, solver.mu, solver.roll, solver.r, solver.swept
    v, w, v0, w0 = solver.v, solver.w, solver.v0, solver.w0
    seen, touched = solver.seen, solver.touched
    for i in range(changed.size):
        changed[i] = -1  # as if every body had just changed: the first sweep visits all
        seen[i] = -1
    scale = 1e-30
    for k in range(nc):
        scale = max(scale, abs(r[k, 0]))
    for sweep in range(iters):
        n_touched = 0
        for k in range(nc):
            a, b = pair[idx[k], 0], pair[idx[k], 1]
            if changed[a] < sweep - 1 and changed[b] < sweep - 1:
                continue
            for i in (a, b):
                if inv_mass[i] > 0.0 and seen[i] != sweep:  # its velocity before this sweep
                    seen[i] = sweep
                    touched[n_touched] = i
                    n_touched += 1
                    for x in range(3):
                        v0[i, x], w0[i, x] = v[i, x], w[i, x]
            _contact_update(k, a, b, inv_mass, mu[k], roll[k], solver)
            scale = max(scale, abs(r[k, 0]))
        settled = True
        for t in range(n_touched):
            i = touched[t]
            if _momentum_change2(i, rot, inv_mass, inv_inertia, solver) > (tol * scale) ** 2 * inv_mass[i]:
                changed[i] = sweep
                settled = False
        if settled:
            return sweep + 1
    return iters


@nb.njit(cache=True, inline="always")
def _momentum_change2(i, rot, inv_mass, inv_inertia, solver):
    """Body i's change of velocity over the sweep in the kinetic-energy norm, m |dv|^2 +
    dw^T I dw (kg m^2/s^2): the squared momentum change an impulse J gives it is about
    J^2 / m in this norm."""
    v, w, v0, w0 = solver.v, solver.w, solver.v0, solver.w0
    dv2 = (v[i, 0] - v0[i, 0]) ** 2 + (v[i, 1] - v0[i, 1]) ** 2 + (v[i, 2] - v0[i, 2]) ** 2
    out = dv2 / inv_mass[i]
    dx, dy, dz = w[i, 0] - w0[i, 0], w[i, 1] - w0[i, 1], w[i, 2] - w0[i, 2]
    for k in range(3):  # principal components of dw, over the principal inverse inertia
        c = rot[i, 0, k] * dx + rot[i, 1, k] * dy + rot[i, 2, k] * dz
        out += c * c / inv_inertia[i, k]
    return out


@nb.njit(cache=True, inline="always")
def _row_arrays(solver):
    """The solver arrays a Gauss-Seidel row update reads and writes: contact frames, angular
    Jacobian rows of a and b, their inverse-inertia responses, effective masses, targets,
    impulses, and the body velocities being solved."""
    return (
        solver.frame,
        solver.ang_a,
        solver.ang_b,
        solver.res_a,
        solver.res_b,
        solver.mass,
        solver.bias,
        solver.r,
        solver.v,
        solver.w,
    )


@nb.njit(cache=True, inline="always")
def _contact_update(k, a, b, inv_mass, mu, roll, solver):
    """One Gauss-Seidel update of contact k: normal row, then the friction disk |r_T| <= mu r_N
    and the rolling disk (rolling r_N)."""
    frame, ang_a, ang_b, res_a, res_b, mass, bias, r, v, w = _row_arrays(solver)
    ima, imb = inv_mass[a], inv_mass[b]
    both = imb > 0.0  # else b's velocity is fixed, and in the bias
    u = _row_velocity(k, 0, a, b, (frame, ang_a, ang_b), (v, w), True, both)
    rn = max(0.0, r[k, 0] + (bias[k, 0] - u) * mass[k, 0])
    dn = rn - r[k, 0]
    if dn != 0.0:
        _row_apply(k, 0, a, b, dn, (frame, res_a, res_b), (ima, imb), (v, w), True)
        r[k, 0] = rn
    if mu > 0.0:
        _disk_update(k, 1, a, b, ima, imb, mu * rn, True, both, solver)
    if roll > 0.0:
        _disk_update(k, 3, a, b, ima, imb, roll * rn, False, both, solver)


@nb.njit(cache=True, inline="always")
def _disk_update(k, j, a, b, ima, imb, limit, linear, both, solver):
    """Gauss-Seidel update of rows j, j + 1 of contact k (friction: linear; rolling: angular
    only) projected onto the disk of radius ``limit``."""
    frame, ang_a, ang_b, res_a, res_b, mass, bias, r, v, w = _row_arrays(solver)
    jacobian, response, vel = (frame, ang_a, ang_b), (frame, res_a, res_b), (v, w)
    u1 = _row_velocity(k, j, a, b, jacobian, vel, linear, both)
    u2 = _row_velocity(k, j + 1, a, b, jacobian, vel, linear, both)
    x1, x2 = _disk(
        r[k, j] + (bias[k, j] - u1) * mass[k, j], r[k, j + 1] + (bias[k, j + 1] - u2) * mass[k, j + 1], limit
    )
    _row_apply(k, j, a, b, x1 - r[k, j], response, (ima, imb), vel, linear)
    _row_apply(k, j + 1, a, b, x2 - r[k, j + 1], response, (ima, imb), vel, linear)
    r[k, j], r[k, j + 1] = x1, x2


@nb.njit(cache=True, _nrt=False)
def _keep_warm(buf, nc, dt, warm, solver):
    """Store the solved contacts pushing (r_N > 0) as the next solve's warm start, as forces
    r / dt, in detection order. Not after a solve with an impact: the impact's impulse spreads
    through resting contacts, and over a short sub-step it would read as a huge force."""
    pair, feat = buf.pairs, buf.features
    keys, vals, size = warm.keys, warm.forces, warm.size
    idx, frame, impact, r = solver.idx, solver.frame, solver.impact, solver.r
    m = 0
    for k in range(nc):
        if impact[k]:
            size[0] = 0
            return
    for k in range(nc):
        if r[k, 0] <= 0.0 or m >= keys.shape[0]:
            continue
        c = idx[k]
        keys[m, 0], keys[m, 1], keys[m, 2], keys[m, 3] = pair[c, 0], pair[c, 1], feat[c, 0], feat[c, 1]
        for x in range(3):
            vals[m, x] = (r[k, 0] * frame[k, 0, x] + r[k, 1] * frame[k, 1, x] + r[k, 2] * frame[k, 2, x]) / dt
            vals[m, 3 + x] = (r[k, 3] * frame[k, 1, x] + r[k, 4] * frame[k, 2, x]) / dt
        m += 1
    size[0] = m


class Outcome(NamedTuple):
    """What a contact model gives one contact, for its record row (write_record)."""

    impulse: tuple  # (x, y, z) impulse on body a, N s, world
    normal: tuple  # (x, y, z) unit normal from b to a
    ra: tuple  # (x, y, z) contact point less a's centre, m, world
    rb: tuple  # the same for b
    speed: float  # approach speed, m/s
    slip: float  # tangential speed after the response, m/s
    roll: float  # rolling speed after the response, m/s (rolling_speed)
    impact: bool  # approach faster than the bounce threshold (an impact)


@nb.njit(cache=True, inline="always")
def rolling_speed(w, a, b, normal, ra):
    """Rolling speed (m/s) of contact point ra (m, from a's centre) with normal ``normal``:
    the relative angular velocity of a and b (w, rad/s, world) across the normal times |ra|."""
    wn = 0.0
    for x in range(3):
        wn += (w[a, x] - w[b, x]) * normal[x]
    wt2 = 0.0
    for x in range(3):
        wt2 += (w[a, x] - w[b, x] - wn * normal[x]) ** 2
    return math.sqrt(wt2) * math.sqrt(ra[0] ** 2 + ra[1] ** 2 + ra[2] ** 2)


@nb.njit(cache=True, inline="always")
def write_record(rec, nrec, buf, c, rot, when, outcome):
    """Record row nrec (codes.RECORD_FIELDS) of contact c of ``buf`` (bodies, point, features,
    barycentric weights) at when = (time s, outer step), with the contact model's ``outcome``
    (Outcome); the lever arms go to each body's frame by its rotation rot[a], rot[b]."""
    pts, pair, feat, bar = buf.points, buf.pairs, buf.features, buf.bary
    a, b = pair[c, 0], pair[c, 1]
    impulse, normal, ra, rb = outcome.impulse, outcome.normal, outcome.ra, outcome.rb
    rec[nrec, REC_TIME] = when[0]
    rec[nrec, REC_STEP] = when[1]
    rec[nrec, REC_A] = a
    rec[nrec, REC_B] = b
    for x in range(3):
        rec[nrec, REC_POINT + x] = pts[c, x]
        rec[nrec, REC_IMPULSE + x] = impulse[x]
        rec[nrec, REC_BARY + x] = bar[c, x]
        rec[nrec, REC_NORMAL + x] = normal[x]
        rec[nrec, REC_LOCAL_A + x] = rot[a, 0, x] * ra[0] + rot[a, 1, x] * ra[1] + rot[a, 2, x] * ra[2]
        rec[nrec, REC_LOCAL_B + x] = rot[b, 0, x] * rb[0] + rot[b, 1, x] * rb[1] + rot[b, 2, x] * rb[2]
    rec[nrec, REC_SPEED] = outcome.speed
    rec[nrec, REC_SLIP] = outcome.slip
    rec[nrec, REC_ROLL] = outcome.roll
    rec[nrec, REC_IMPACT] = 1.0 if outcome.impact else 0.0
    rec[nrec, REC_FEAT_A] = feat[c, 0]
    rec[nrec, REC_FEAT_B] = feat[c, 1]


@nb.njit(cache=True, _nrt=False)
def _records(buf, nc, rot, when, rec, nrec, solver):
    """Append a record row per contact pushing (or impacting) after the solve, in detection
    order, at when = (time s, outer step); returns the record count, -1 when rec is full."""
    pair = buf.pairs
    idx, ra, rb, frame, ang_a, ang_b = (
        solver.idx,
        solver.ra,
        solver.rb,
        solver.frame,
        solver.ang_a,
        solver.ang_b,
    )
    target, speed0, impact, r, v, w = (
        solver.target,
        solver.speed,
        solver.impact,
        solver.r,
        solver.v,
        solver.w,
    )
    for k in range(nc):
        if r[k, 0] <= 0.0 and not impact[k]:
            continue
        if nrec >= rec.shape[0]:
            return -1
        c = idx[k]
        a, b = pair[c, 0], pair[c, 1]
        # slip: tangential relative velocity with gravity's increment (target) removed
        s1 = _row_velocity(k, 1, a, b, (frame, ang_a, ang_b), (v, w), True, True) - target[k, 1]
        s2 = _row_velocity(k, 2, a, b, (frame, ang_a, ang_b), (v, w), True, True) - target[k, 2]
        normal = (frame[k, 0, 0], frame[k, 0, 1], frame[k, 0, 2])
        arm_a = (ra[k, 0], ra[k, 1], ra[k, 2])
        impulse = (
            r[k, 0] * frame[k, 0, 0] + r[k, 1] * frame[k, 1, 0] + r[k, 2] * frame[k, 2, 0],
            r[k, 0] * frame[k, 0, 1] + r[k, 1] * frame[k, 1, 1] + r[k, 2] * frame[k, 2, 1],
            r[k, 0] * frame[k, 0, 2] + r[k, 1] * frame[k, 1, 2] + r[k, 2] * frame[k, 2, 2],
        )
        outcome = Outcome(
            impulse,
            normal,
            arm_a,
            (rb[k, 0], rb[k, 1], rb[k, 2]),
            speed0[k],
            math.sqrt(s1 * s1 + s2 * s2),
            rolling_speed(w, a, b, normal, arm_a),
            impact[k],
        )
        write_record(rec, nrec, buf, c, rot, when, outcome)
        nrec += 1
    return nrec


@nb.njit(cache=True, _nrt=False)
def resolve(m, opt, d, solver, count, dt, time, step, nrec):
    """Impulse-level contact solve (module doc) of the contacts d.contacts[:count] at time
    ``time`` (s) of outer step ``step``, over a (sub-)step of dt seconds, in the scratch
    ``solver`` (new_solver, rows >= count), warm-started from d.warm (updated); updates
    d.phi; appends records to d.rec from row nrec (returns the new count, -1 when full);
    counts contacts and PGS sweeps in d.stats. It allocates nothing and is compiled without
    reference counting, with all it calls."""
    buf, warm = d.contacts, d.warm
    nc = _select(buf.gaps, count, opt.slop, solver.idx)
    if nc == 0:
        warm.size[0] = 0
        return nrec
    world_velocities(m.kind, d.rot, d.phi, d.kin_v, d.kin_w, solver.v, solver.w)
    inv_inertia_world(m.kind, d.rot, m.inv_inertia, solver.iw)
    _contact_frames(buf, nc, d.pos, m.inv_mass, solver)
    _targets(m, opt, buf, nc, dt, solver)
    _warm_impulses(buf, nc, dt, warm, m.inv_mass, solver)
    d.stats.contacts[0] += nc
    d.stats.sweeps[0] += _sweeps(m, opt, buf.pairs, nc, d.rot, solver)
    _keep_warm(buf, nc, dt, warm, solver)
    store_twists(m.kind, d.rot, solver.v, solver.w, d.phi)
    return _records(buf, nc, d.rot, (time, step), d.rec, nrec, solver)
