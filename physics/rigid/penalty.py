"""Penalty contact models (numba): contact forces over a (sub-)step instead of an impulse solve.

Normal force from the penetration x (m) and its rate xdot (m/s), clamped at f >= 0:

- ``LINEAR``: f = k x + c xdot (a spring-damper);
- ``HUNT_CROSSLEY``: f = k x^p + c x^p xdot, zero at first touch (Hunt and Crossley,
  "Coefficient of restitution interpreted as damping in vibroimpact", J. Appl. Mech. 42, 1975).

Friction is Coulomb's, regularised below ``Options.friction_speed``. The update is symplectic:
velocities change now, positions after (the stepper's advance stage).
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from physics.rigid.codes import (
    HUNT_CROSSLEY,
    LINEAR,
    REC_A,
    REC_B,
    REC_BARY,
    REC_FEAT_A,
    REC_FEAT_B,
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
from physics.rigid.impulses import inv_inertia_world, store_twists, world_velocities
from physics.rigid.spatial import cross, dot3, mtv, mv


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


@nb.njit(cache=True)
def _apply(i, imp, r, inv_mass, iw, v, w, sign):
    v[i] += sign * inv_mass[i] * imp
    w[i] += sign * mv(iw[i], cross(r, imp))


@nb.njit(cache=True)
def _rel_velocity(a, b, ra, rb, v, w):
    return v[a] + cross(w[a], ra) - v[b] - cross(w[b], rb)


@nb.njit(cache=True)
def penalty(m, opt, d, count, dt, time, step, nrec):
    """Penalty forces of the contacts d.contacts[:count] over dt seconds at ``time`` (s) of
    outer step ``step``: updates d.phi, appends a record row per pushing contact from row nrec;
    returns the new record count, -1 when d.rec is full."""
    buf, rot, pos, rec = d.contacts, d.rot, d.pos, d.rec
    pts, nrm, gaps, pair, feat, bar = buf.points, buf.normals, buf.gaps, buf.pairs, buf.features, buf.bary
    n_bodies = m.kind.shape[0]
    v, w, iw = np.empty((n_bodies, 3)), np.empty((n_bodies, 3)), np.empty((n_bodies, 3, 3))
    world_velocities(m.kind, rot, d.phi, d.kin_v, d.kin_w, v, w)
    inv_inertia_world(m.kind, rot, m.inv_inertia, iw)
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
        fn = max(normal_force(opt, x, xdot), 0.0)
        ut = u - (dot3(u, n)) * n
        slip = math.sqrt(dot3(ut, ut))
        mu = math.sqrt(m.friction[a] * m.friction[b])
        ft = -mu * fn * ut / max(slip, opt.friction_speed)
        imp = (fn * n + ft) * dt
        _apply(a, imp, ra, m.inv_mass, iw, v, w, 1.0)
        _apply(b, imp, rb, m.inv_mass, iw, v, w, -1.0)
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
    store_twists(m.kind, rot, v, w, d.phi)
    return nrec
