"""Free-motion integrators for rigid bodies (no contact): semi-implicit Euler, RK4, adaptive RK4.

Each advances one body's (position p in m, unit quaternion q, body twist phi) by h seconds
under gravity g (m/s^2, world) and a constant body-frame wrench ``ext`` (N m, N):

- ``SEMI_IMPLICIT``: velocity first, then pose with the new velocity (symplectic Euler). The
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

import numba as nb
import numpy as np

from physics.rigid.spatial import cross, dot3, mtv, mv, newton_euler, quat_exp, quat_mul, quat_to_mat

SEMI_IMPLICIT = 0
RK4 = 1
ADAPTIVE = 2
METHODS = {"semi-implicit": SEMI_IMPLICIT, "rk4": RK4, "adaptive": ADAPTIVE}


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


@nb.njit(cache=True)
def solve3(m, b):
    """Solution of the 3 x 3 system m x = b by Cramer's rule."""
    c0 = cross(m[:, 1], m[:, 2])
    det = m[0, 0] * c0[0] + m[1, 0] * c0[1] + m[2, 0] * c0[2]
    c1 = cross(m[:, 2], m[:, 0])
    c2 = cross(m[:, 0], m[:, 1])
    return np.array([dot3(c0, b), dot3(c1, b), dot3(c2, b)]) / det


@nb.njit(cache=True)
def semi_implicit_step(p, q, phi, inertia, mass, gravity, ext, h):
    """Symplectic Euler with an implicit-midpoint angular update (see module doc)."""
    w0 = phi[:3]
    tau = ext[:3]
    w1 = w0 + h * (tau - cross(w0, inertia * w0)) / inertia  # explicit guess
    jac = np.empty((3, 3))
    for _ in range(20):  # Newton on g(w1) = I (w1 - w0)/h + wm x I wm - tau, wm = (w0 + w1)/2
        wm = 0.5 * (w0 + w1)
        iwm = inertia * wm
        g = inertia * (w1 - w0) / h + cross(wm, iwm) - tau
        # dg/dw1 = I/h + 0.5 ([wm] I - [I wm]), [x] the cross-product matrix
        x0, x1, x2 = wm[0], wm[1], wm[2]
        y0, y1, y2 = iwm[0], iwm[1], iwm[2]
        i0, i1, i2 = inertia[0], inertia[1], inertia[2]
        jac[0, 0], jac[0, 1], jac[0, 2] = i0 / h, 0.5 * (-x2 * i1 + y2), 0.5 * (x1 * i2 - y1)
        jac[1, 0], jac[1, 1], jac[1, 2] = 0.5 * (x2 * i0 - y2), i1 / h, 0.5 * (-x0 * i2 + y0)
        jac[2, 0], jac[2, 1], jac[2, 2] = 0.5 * (-x1 * i0 + y1), 0.5 * (x0 * i1 - y0), i2 / h
        dw = solve3(jac, g)
        w1 = w1 - dw
        if abs(dw[0]) + abs(dw[1]) + abs(dw[2]) <= 1e-14 * (1.0 + abs(w1[0]) + abs(w1[1]) + abs(w1[2])):
            break
    wm = 0.5 * (w0 + w1)
    r0 = quat_to_mat(q)
    v_world = mv(r0, phi[3:]) + h * (mv(r0, ext[3:]) / mass + gravity)
    p1 = p + h * v_world
    q1 = quat_mul(q, quat_exp(h * wm))
    q1 /= math.sqrt(np.sum(q1 * q1))
    phi1 = np.empty(6)
    phi1[:3] = w1
    phi1[3:] = mtv(quat_to_mat(q1), v_world)
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
