"""Free-motion integrators for rigid bodies (no contact): semi-implicit, RK4, adaptive RK4.

Each advances one body's (position p in m, unit quaternion q, body twist phi) by h seconds
under gravity g (m/s^2, world) and a constant body-frame wrench ``ext`` (N m, N):

- ``SEMI_IMPLICIT`` (the default): the centre of mass moves in closed form under the step's
  constant acceleration a = g + R f / m (gravity and the body force f taken at the step's
  start): p1 = p + h v + h^2 a / 2, v1 = v + h a, exact for ballistic flight at any step. The
  angular part uses the implicit midpoint rule on Euler's equations, which conserves the
  kinetic energy and |L| of a torque-free body exactly (they are quadratic invariants); the
  orientation moves by exp(h w_mid) on SO(3).
- ``RK4``: classical Runge-Kutta on (p, q, phi) with the Newton-Euler right-hand side; the
  quaternion is renormalised after the step (a projection that keeps fourth order).
- ``ADAPTIVE``: RK4 with step doubling (error estimate |y_h - y_{h/2,h/2}| / 15), sub-steps
  chosen to keep the error per step below ``tol`` (rad/s, m/s and rad).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba as nb
import numpy as np

from jassy.jit import drop_stale_cache
from physics.rigid import spatial
from physics.rigid.spatial import mtv, mv, newton_euler, quat_mul, quat_to_mat

drop_stale_cache(__file__, [spatial])  # its cache holds copies of spatial's kernels

SEMI_IMPLICIT = 0
RK4 = 1
ADAPTIVE = 2
METHODS = {"semi-implicit": SEMI_IMPLICIT, "rk4": RK4, "adaptive": ADAPTIVE}


class FreeBody(NamedTuple):
    """One body's state and loads for a step of free motion."""

    p: np.ndarray  # (3,) centre-of-mass position, m
    q: np.ndarray  # (4,) unit quaternion of the principal frame
    phi: np.ndarray  # (6,) body-frame twist (rad/s, m/s)
    inertia: np.ndarray  # (3,) principal moments, kg m^2
    mass: float  # kg
    gravity: np.ndarray  # (3,) m/s^2, world
    ext: np.ndarray  # (6,) constant body-frame wrench (N m, N)


@nb.njit(cache=True)
def _body_wrench(q, mass, gravity, ext):
    """Body-frame wrench of gravity plus ``ext``."""
    r = quat_to_mat(q)
    f = ext.copy()
    f[3:] += mass * mtv(r, gravity)
    return f


@nb.njit(cache=True)
def _derivative(q, phi, inertia, mass, gravity, ext):
    """(dp/dt, dq/dt, dphi/dt) at the state (q, phi)."""
    r = quat_to_mat(q)
    dp = mv(r, phi[3:])
    dq = 0.5 * quat_mul(q, np.array([0.0, phi[0], phi[1], phi[2]]))
    dphi = newton_euler(inertia, mass, phi, _body_wrench(q, mass, gravity, ext))
    return dp, dq, dphi


@nb.njit(cache=True)
def rk4_step(p, q, phi, inertia, mass, gravity, ext, h):
    """One classical RK4 step; returns (p, q, phi) with q renormalised."""
    k1p, k1q, k1f = _derivative(q, phi, inertia, mass, gravity, ext)
    k2p, k2q, k2f = _derivative(q + 0.5 * h * k1q, phi + 0.5 * h * k1f, inertia, mass, gravity, ext)
    k3p, k3q, k3f = _derivative(q + 0.5 * h * k2q, phi + 0.5 * h * k2f, inertia, mass, gravity, ext)
    k4p, k4q, k4f = _derivative(q + h * k3q, phi + h * k3f, inertia, mass, gravity, ext)
    p1 = p + h / 6.0 * (k1p + 2.0 * k2p + 2.0 * k3p + k4p)
    q1 = q + h / 6.0 * (k1q + 2.0 * k2q + 2.0 * k3q + k4q)
    q1 /= math.sqrt(np.sum(q1 * q1))
    phi1 = phi + h / 6.0 * (k1f + 2.0 * k2f + 2.0 * k3f + k4f)
    return p1, q1, phi1


@nb.njit(cache=True, inline="always")
def _solve3(row0, row1, row2, b):
    """Solution (x0, x1, x2) of the 3 x 3 linear system J x = b by Cramer's rule (J's rows and
    b as 3-tuples of scalars)."""
    j00, j01, j02 = row0
    j10, j11, j12 = row1
    j20, j21, j22 = row2
    b0, b1, b2 = b
    c00, c01, c02 = j11 * j22 - j12 * j21, j12 * j20 - j10 * j22, j10 * j21 - j11 * j20
    det = j00 * c00 + j01 * c01 + j02 * c02
    x0 = b0 * c00 + b1 * (j02 * j21 - j01 * j22) + b2 * (j01 * j12 - j02 * j11)
    x1 = b0 * c01 + b1 * (j00 * j22 - j02 * j20) + b2 * (j02 * j10 - j00 * j12)
    x2 = b0 * c02 + b1 * (j01 * j20 - j00 * j21) + b2 * (j00 * j11 - j01 * j10)
    return x0 / det, x1 / det, x2 / det


@nb.njit(cache=True, inline="always")
def _implicit_midpoint_omega(w0, w1, w2, i0, i1, i2, t0, t1, t2, h):
    """w(t + h) of Euler's equations I dw/dt + w x I w = tau by the implicit midpoint rule,
    Newton's method on g(w') = I (w' - w)/h + wm x I wm - tau, wm = (w + w')/2 (scalars)."""
    # explicit guess
    x0 = w0 + h * (t0 - (w1 * i2 * w2 - w2 * i1 * w1)) / i0
    x1 = w1 + h * (t1 - (w2 * i0 * w0 - w0 * i2 * w2)) / i1
    x2 = w2 + h * (t2 - (w0 * i1 * w1 - w1 * i0 * w0)) / i2
    for _ in range(20):
        m0, m1, m2 = 0.5 * (w0 + x0), 0.5 * (w1 + x1), 0.5 * (w2 + x2)
        y0, y1, y2 = i0 * m0, i1 * m1, i2 * m2
        g0 = i0 * (x0 - w0) / h + (m1 * y2 - m2 * y1) - t0
        g1 = i1 * (x1 - w1) / h + (m2 * y0 - m0 * y2) - t1
        g2 = i2 * (x2 - w2) / h + (m0 * y1 - m1 * y0) - t2
        # dg/dw' = I/h + 0.5 ([wm] I - [I wm]), [x] the cross-product matrix
        d0, d1, d2 = _solve3(
            (i0 / h, 0.5 * (-m2 * i1 + y2), 0.5 * (m1 * i2 - y1)),
            (0.5 * (m2 * i0 - y2), i1 / h, 0.5 * (-m0 * i2 + y0)),
            (0.5 * (-m1 * i0 + y1), 0.5 * (m0 * i1 - y0), i2 / h),
            (g0, g1, g2),
        )
        x0, x1, x2 = x0 - d0, x1 - d1, x2 - d2
        if abs(d0) + abs(d1) + abs(d2) <= 1e-14 * (1.0 + abs(x0) + abs(x1) + abs(x2)):
            break
    return x0, x1, x2


@nb.njit(cache=True, inline="always")
def _rotate(qw, qx, qy, qz, x, y, z):
    """The vector (x, y, z) rotated by the unit quaternion q: v + 2 w (u x v) + 2 u x (u x v)."""
    cx, cy, cz = qy * z - qz * y, qz * x - qx * z, qx * y - qy * x
    return (
        x + 2.0 * (qw * cx + qy * cz - qz * cy),
        y + 2.0 * (qw * cy + qz * cx - qx * cz),
        z + 2.0 * (qw * cz + qx * cy - qy * cx),
    )


@nb.njit(cache=True, _nrt=False)
def semi_implicit_into(body, h, out, ballistic=True):
    """Closed-form translation under constant acceleration with an implicit-midpoint angular
    update (see module doc) of ``body`` (FreeBody) over h seconds, written into the rows
    out = (p, q, phi) (scalar arithmetic, no allocation). ``ballistic=False``: the centre moves
    with the new velocity instead, p1 = p + h v1 (symplectic Euler), for a body held by a
    resting contact whose solve folded the step's gravity increment into its velocity (it then
    stays put with zero velocity)."""
    p, q, phi, inertia, mass, gravity, ext = body
    out_p, out_q, out_phi = out
    x0, x1, x2 = _implicit_midpoint_omega(
        phi[0], phi[1], phi[2], inertia[0], inertia[1], inertia[2], ext[0], ext[1], ext[2], h
    )
    qw, qx, qy, qz = q[0], q[1], q[2], q[3]
    ux, uy, uz = _rotate(qw, qx, qy, qz, phi[3], phi[4], phi[5])  # world velocity at the start
    ax, ay, az = _rotate(qw, qx, qy, qz, ext[3] / mass, ext[4] / mass, ext[5] / mass)
    ax, ay, az = ax + gravity[0], ay + gravity[1], az + gravity[2]
    vx, vy, vz = ux + h * ax, uy + h * ay, uz + h * az
    drift = 0.5 * h if ballistic else h
    out_p[0] = p[0] + h * (ux + drift * ax)
    out_p[1] = p[1] + h * (uy + drift * ay)
    out_p[2] = p[2] + h * (uz + drift * az)
    # q1 = q exp(h wm): exp of the rotation vector r = h (w0 + w1) / 2
    r0, r1, r2 = 0.5 * h * (phi[0] + x0), 0.5 * h * (phi[1] + x1), 0.5 * h * (phi[2] + x2)
    angle = math.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
    s = math.sin(0.5 * angle) / angle if angle > 1e-4 else 0.5 - angle * angle / 48.0
    ew, ex, ey, ez = math.cos(0.5 * angle), s * r0, s * r1, s * r2
    w1 = qw * ew - qx * ex - qy * ey - qz * ez
    a1 = qw * ex + qx * ew + qy * ez - qz * ey
    b1 = qw * ey - qx * ez + qy * ew + qz * ex
    c1 = qw * ez + qx * ey - qy * ex + qz * ew
    norm = math.sqrt(w1 * w1 + a1 * a1 + b1 * b1 + c1 * c1)
    w1, a1, b1, c1 = w1 / norm, a1 / norm, b1 / norm, c1 / norm
    out_q[0], out_q[1], out_q[2], out_q[3] = w1, a1, b1, c1
    out_phi[0], out_phi[1], out_phi[2] = x0, x1, x2
    out_phi[3], out_phi[4], out_phi[5] = _rotate(w1, -a1, -b1, -c1, vx, vy, vz)


@nb.njit(cache=True)
def semi_implicit_step(p, q, phi, inertia, mass, gravity, ext, h):
    """Closed-form translation, implicit-midpoint rotation (see module doc)."""
    p1, q1, phi1 = np.empty(3), np.empty(4), np.empty(6)
    semi_implicit_into(FreeBody(p, q, phi, inertia, mass, gravity, ext), h, (p1, q1, phi1))
    return p1, q1, phi1


@nb.njit(cache=True)
def _max_diff(pa, qa, fa, pb, qb, fb):
    d = 0.0
    for i in range(3):
        d = max(d, abs(pa[i] - pb[i]))
    for i in range(4):
        d = max(d, abs(qa[i] - qb[i]))
    for i in range(6):
        d = max(d, abs(fa[i] - fb[i]))
    return d


@nb.njit(cache=True)
def adaptive_advance(p, q, phi, inertia, mass, gravity, ext, h, tol, h_try):
    """Advance by h with RK4 step doubling; returns (p, q, phi, steps taken, next step guess)."""
    t = 0.0
    steps = 0
    dt = min(h_try, h) if h_try > 0.0 else h
    while t < h * (1.0 - 1e-12):
        dt = min(dt, h - t)
        pa, qa, fa = rk4_step(p, q, phi, inertia, mass, gravity, ext, dt)
        ph, qh, fh = rk4_step(p, q, phi, inertia, mass, gravity, ext, 0.5 * dt)
        pb, qb, fb = rk4_step(ph, qh, fh, inertia, mass, gravity, ext, 0.5 * dt)
        err = _max_diff(pa, qa, fa, pb, qb, fb) / 15.0
        if err <= tol or dt < 1e-12:
            t += dt
            p, q, phi = pb, qb, fb
            steps += 1
        scale = 2.0 if err == 0.0 else min(2.0, max(0.2, 0.9 * (tol / err) ** 0.2))
        dt *= scale
    return p, q, phi, steps, dt


@nb.njit(cache=True)
def advance_body(p, q, phi, inertia, mass, gravity, ext, h, method, tol):
    """Free motion of one body over h seconds with the given method (module constants)."""
    if h <= 0.0:
        return p.copy(), q.copy(), phi.copy()
    if method == SEMI_IMPLICIT:
        return semi_implicit_step(p, q, phi, inertia, mass, gravity, ext, h)
    if method == RK4:
        return rk4_step(p, q, phi, inertia, mass, gravity, ext, h)
    p1, q1, f1, _, _ = adaptive_advance(p, q, phi, inertia, mass, gravity, ext, h, tol, h)
    return p1, q1, f1


@nb.njit(cache=True, _nrt=True)
def advance_body_into(body, h, method, tol, out):
    """advance_body of ``body`` (FreeBody) written into the rows out = (p, q, phi). It
    allocates (RK4 and the adaptive method work on arrays), so it keeps numba's reference
    counting when called from a kernel compiled without it; the stepper calls
    semi_implicit_into directly for the default method."""
    p, q, phi, inertia, mass, gravity, ext = body
    out_p, out_q, out_phi = out
    if method == SEMI_IMPLICIT and h > 0.0:
        semi_implicit_into(body, h, out)
        return
    p1, q1, f1 = advance_body(p, q, phi, inertia, mass, gravity, ext, h, method, tol)
    for x in range(3):
        out_p[x] = p1[x]
    for x in range(4):
        out_q[x] = q1[x]
    for x in range(6):
        out_phi[x] = f1[x]


def integrate_free(p, q, phi, inertia, mass, h, steps, method="rk4", gravity=(0.0, 0.0, 0.0), tol=1e-10):
    """Trajectory of one free body: arrays (steps + 1) of p, q, phi sampled every h seconds."""
    if method not in METHODS:
        raise ValueError(f"method: expected one of {sorted(METHODS)}, got {method!r}")
    return _trajectory(
        np.asarray(p, float),
        np.asarray(q, float),
        np.asarray(phi, float),
        np.asarray(inertia, float),
        float(mass),
        np.asarray(gravity, float),
        float(h),
        int(steps),
        METHODS[method],
        float(tol),
    )


@nb.njit(cache=True)
def _trajectory(p, q, phi, inertia, mass, gravity, h, steps, method, tol):
    ps = np.empty((steps + 1, 3))
    qs = np.empty((steps + 1, 4))
    fs = np.empty((steps + 1, 6))
    ps[0], qs[0], fs[0] = p, q, phi
    ext = np.zeros(6)
    for i in range(steps):
        p, q, phi = advance_body(p, q, phi, inertia, mass, gravity, ext, h, method, tol)
        ps[i + 1], qs[i + 1], fs[i + 1] = p, q, phi
    return ps, qs, fs
