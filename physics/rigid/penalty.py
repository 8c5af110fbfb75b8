"""Penalty contact models (numba): contact forces over a (sub-)step instead of an impulse solve.

Normal force from the penetration x (m) and its rate xdot (m/s), clamped at f >= 0:

- ``LINEAR``: f = k x + c xdot (a spring-damper);
- ``HUNT_CROSSLEY``: f = k x^p + c x^p xdot, zero at first touch (Hunt and Crossley,
  "Coefficient of restitution interpreted as damping in vibroimpact", J. Appl. Mech. 42, 1975).

Friction is Coulomb's, regularised below ``Options.friction_speed``. The update is symplectic:
velocities change now, positions after (the stepper's advance stage). Each pushing contact
gives a record row (impulses.write_record) with the slip and rolling speed after the update;
a contact is an impact when it approaches faster than ``Options.bounce_threshold`` and was not
pushing at the last solve (the same bodies and features: the contacts kept in the warm-start
table), so a bounce that lasts several steps is one impact, at its first step. The scratch is
the impulse solve's (impulses.new_solver): nothing is allocated.
"""

from __future__ import annotations

import math

import numba as nb

from jassy.jit import drop_stale_cache
from physics.rigid import codes, impulses, integrate
from physics.rigid.codes import HUNT_CROSSLEY, LINEAR
from physics.rigid.impulses import (
    Outcome,
    inv_inertia_world,
    link_warm,
    rolling_speed,
    store_twists,
    warm_match,
    world_velocities,
    write_record,
)

drop_stale_cache(__file__, [codes, impulses, integrate])  # its cache holds copies of their kernels


@nb.njit(cache=True, inline="always")
def normal_force(opt, x, xdot):
    """Normal force (N) of the penalty model ``opt.contact`` at penetration x > 0 (m) closing at
    xdot (m/s), before the clamp at 0. An unknown model code is an error."""
    if opt.contact == LINEAR:
        return opt.stiffness * x + opt.damping * xdot
    if opt.contact == HUNT_CROSSLEY:
        xp = x**opt.exponent
        return opt.stiffness * xp + opt.damping * xp * xdot
    raise ValueError("penalty.normal_force: unknown contact model code")


@nb.njit(cache=True, inline="always")
def _velocity_at(i, r, v, w):
    """World velocity (m/s) of the point r (m, from body i's centre) of body i."""
    return (
        v[i, 0] + w[i, 1] * r[2] - w[i, 2] * r[1],
        v[i, 1] + w[i, 2] * r[0] - w[i, 0] * r[2],
        v[i, 2] + w[i, 0] * r[1] - w[i, 1] * r[0],
    )


@nb.njit(cache=True, inline="always")
def _push(i, imp, r, inv_mass, iw, v, w):
    """Body i's velocities v[i], w[i] after the impulse imp (N s, world) at r (m, from its
    centre): dv = imp / m, dw = I^-1 (r x imp)."""
    t0 = r[1] * imp[2] - r[2] * imp[1]
    t1 = r[2] * imp[0] - r[0] * imp[2]
    t2 = r[0] * imp[1] - r[1] * imp[0]
    for x in range(3):
        v[i, x] += inv_mass[i] * imp[x]
        w[i, x] += iw[i, x, 0] * t0 + iw[i, x, 1] * t1 + iw[i, x, 2] * t2


@nb.njit(cache=True, _nrt=False)
def _forces(m, opt, d, solver, count, dt):
    """Apply the penalty impulse of every penetrating contact d.contacts[:count] over dt
    seconds to the velocities solver.v, solver.w; the k-th pushing contact's row in the
    buffers, lever arms, impulse, approach speed and impact flag go to row k of solver.idx,
    ra, rb, r, speed, impact. Returns how many push."""
    buf, pos = d.contacts, d.pos
    pts, nrm, gaps, pair = buf.points, buf.normals, buf.gaps, buf.pairs
    v, w, iw = solver.v, solver.w, solver.iw
    nk = 0
    for c in range(count):
        x = -gaps[c]
        if x <= 0.0:
            continue
        a, b = pair[c, 0], pair[c, 1]
        n = (nrm[c, 0], nrm[c, 1], nrm[c, 2])
        ra = (pts[c, 0] - pos[a, 0], pts[c, 1] - pos[a, 1], pts[c, 2] - pos[a, 2])
        rb = (pts[c, 0] - pos[b, 0], pts[c, 1] - pos[b, 1], pts[c, 2] - pos[b, 2])
        ua, ub = _velocity_at(a, ra, v, w), _velocity_at(b, rb, v, w)
        u = (ua[0] - ub[0], ua[1] - ub[1], ua[2] - ub[2])
        un = u[0] * n[0] + u[1] * n[1] + u[2] * n[2]
        xdot = -un
        fn = max(normal_force(opt, x, xdot), 0.0)
        ut = (u[0] - un * n[0], u[1] - un * n[1], u[2] - un * n[2])
        slip = math.sqrt(ut[0] ** 2 + ut[1] ** 2 + ut[2] ** 2)
        friction = -math.sqrt(m.friction[a] * m.friction[b]) * fn / max(slip, opt.friction_speed)
        imp = (
            (fn * n[0] + friction * ut[0]) * dt,
            (fn * n[1] + friction * ut[1]) * dt,
            (fn * n[2] + friction * ut[2]) * dt,
        )
        _push(a, imp, ra, m.inv_mass, iw, v, w)
        _push(b, (-imp[0], -imp[1], -imp[2]), rb, m.inv_mass, iw, v, w)
        solver.idx[nk] = c
        solver.speed[nk] = xdot
        solver.impact[nk] = xdot > opt.bounce_threshold
        for j in range(3):
            solver.ra[nk, j], solver.rb[nk, j], solver.r[nk, j] = ra[j], rb[j], imp[j]
        nk += 1
    return nk


@nb.njit(cache=True, _nrt=False)
def _impacts_and_memory(d, solver, nk, dt):
    """An approach faster than the bounce threshold (solver.impact) stays an impact only for
    a contact that was not pushing at the last solve (d.warm); then the pushing contacts
    become the memory of the next: keys and force (N) in d.warm."""
    buf, warm = d.contacts, d.warm
    pair, feat, keys, forces = buf.pairs, buf.features, warm.keys, warm.forces
    link_warm(warm, solver)
    for k in range(nk):
        if not solver.impact[k]:
            continue
        e = warm_match(buf, solver.idx[k], warm, solver)
        if e >= 0:  # that contact was pushing: taken, so no other new contact matches it
            solver.used[e] = True
            solver.impact[k] = False
    kept = min(nk, keys.shape[0])
    for k in range(kept):
        c = solver.idx[k]
        keys[k, 0], keys[k, 1], keys[k, 2], keys[k, 3] = pair[c, 0], pair[c, 1], feat[c, 0], feat[c, 1]
        for x in range(3):
            forces[k, x] = solver.r[k, x] / dt
            forces[k, 3 + x] = 0.0
    warm.size[0] = kept


@nb.njit(cache=True, _nrt=False)
def _records(d, solver, nk, when, nrec):
    """A record row per pushing contact (solver rows of _forces) at when = (time s, outer
    step), slip and rolling speed after the update; returns the record count, -1 when d.rec
    is full."""
    buf, rot, rec = d.contacts, d.rot, d.rec
    nrm, pair = buf.normals, buf.pairs
    v, w, ra, rb, r = solver.v, solver.w, solver.ra, solver.rb, solver.r
    for k in range(nk):
        if nrec >= rec.shape[0]:
            return -1
        c = solver.idx[k]
        a, b = pair[c, 0], pair[c, 1]
        n = (nrm[c, 0], nrm[c, 1], nrm[c, 2])
        arm_a, arm_b = (ra[k, 0], ra[k, 1], ra[k, 2]), (rb[k, 0], rb[k, 1], rb[k, 2])
        ua, ub = _velocity_at(a, arm_a, v, w), _velocity_at(b, arm_b, v, w)
        u = (ua[0] - ub[0], ua[1] - ub[1], ua[2] - ub[2])
        un = u[0] * n[0] + u[1] * n[1] + u[2] * n[2]
        slip = math.sqrt((u[0] - un * n[0]) ** 2 + (u[1] - un * n[1]) ** 2 + (u[2] - un * n[2]) ** 2)
        outcome = Outcome(
            (r[k, 0], r[k, 1], r[k, 2]),
            n,
            arm_a,
            arm_b,
            solver.speed[k],
            slip,
            rolling_speed(w, a, b, n, arm_a),
            solver.impact[k],
        )
        write_record(rec, nrec, buf, c, rot, when, outcome)
        nrec += 1
    return nrec


@nb.njit(cache=True, _nrt=False)
def penalty(m, opt, d, solver, count, dt, time, step, nrec):
    """Penalty forces of the contacts d.contacts[:count] over dt seconds at ``time`` (s) of
    outer step ``step``, in the scratch ``solver`` (impulses.new_solver, rows >= count):
    updates d.phi, appends a record row per pushing contact from row nrec; returns the new
    record count, -1 when d.rec is full."""
    world_velocities(m.kind, d.rot, d.phi, d.kin_v, d.kin_w, solver.v, solver.w)
    inv_inertia_world(m.kind, d.rot, m.inv_inertia, solver.iw)
    nk = _forces(m, opt, d, solver, count, dt)
    _impacts_and_memory(d, solver, nk, dt)
    store_twists(m.kind, d.rot, solver.v, solver.w, d.phi)
    return _records(d, solver, nk, (time, step), nrec)
