"""The 2D discrete frictional contact problem (DFCP, Cadoux 2009) in its reduced (Delassus) form.

Find impulses r = (r_N, r_T) per contact (N s) and relative velocities u = W r + w (m/s) with

    C(mu) = {|r_T| <= mu r_N} ∋ r  ⊥  u~ = u + mu |u_T| e_N ∈ C(mu)*     (De Saxcé & Feng 1998),

i.e. take-off (r = 0, u_N >= 0), stick (u = 0, r in C) or slip (u_N = 0, r_T = -mu r_N sign u_T).
W (2c x 2c, symmetric positive semi-definite, contact i on rows 2i (normal) and 2i+1 (tangent))
comes from system.py's Schur complements of the KKT matrix with bilateral constraints.

Solver: projected Gauss-Seidel over contacts (numba kernel); each 2x2 contact problem is solved
exactly by enumeration (take-off / stick / slip+ / slip-, as Siconos fc2d NSGS), with the
projection r <- Pi_C(r - rho u~) as a fallback. It stops when the natural-map residual

    res = ||e|| / ||rho o w||,   e_i = r_i - Pi_C(r_i - rho_i u~_i),   rho_i = 1 / ||W_ii||_F

(per-contact scaling of the talk's PGS; e in N s, scale-free, 0 when w = 0) is below ``tol``, or
after ``max_iter`` sweeps (then ``converged`` is False). A contact whose ||W_ii|| is < 1e-13 of the
largest cannot be moved by any impulse: it keeps r = r0 (rho = 0).
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from jassy.errors import JassyError


@dataclass(frozen=True)
class DFCPResult:
    """Solution r (c, 2) impulses (N s), u (c, 2) = W r + w (m/s), sweeps done, final residual."""

    r: np.ndarray
    u: np.ndarray
    iterations: int
    residual: float
    converged: bool


@numba.njit(cache=True)
def cone_project(rn, rt, mu):
    """Euclidean projection of (rn, rt) on C(mu) = {|rt| <= mu rn} (Siconos fc2d_compute_error)."""
    if abs(rt) <= mu * rn:
        return rn, rt
    if mu * abs(rt) <= -rn:
        return 0.0, 0.0
    pn = (mu * abs(rt) + rn) / (mu * mu + 1.0)
    return pn, mu * pn * np.sign(rt)


@numba.njit(cache=True)
def _local_solve(a, b, d, zn, zt, mu, rn0, rt0, rho):
    """Exact solution of one contact: W_ii = [[a, b], [b, d]], u = W_ii r + z."""
    if zn >= 0.0:
        return 0.0, 0.0
    det = a * d - b * b
    if det > 1e-14 * (a * d + 1e-300):
        rn = (-zn * d + b * zt) / det
        rt = (-a * zt + b * zn) / det
        if rn >= 0.0 and abs(rt) <= mu * rn * (1.0 + 1e-12):
            return rn, rt
    for s in (1.0, -1.0):
        den = a - s * mu * b
        if den > 0.0:
            rn = -zn / den
            ut = (b - s * mu * d) * rn + zt
            if rn >= 0.0 and s * ut >= 0.0:
                return rn, -s * mu * rn
    un = a * rn0 + b * rt0 + zn
    ut = b * rn0 + d * rt0 + zt
    return cone_project(rn0 - rho * (un + mu * abs(ut)), rt0 - rho * ut, mu)


@numba.njit(cache=True)
def _velocities(W, w, r, u):
    """u = W r + w, in place (no temporary)."""
    n = w.size
    for k in range(n):
        acc = w[k]
        for j in range(n):
            acc += W[k, j] * r[j]
        u[k] = acc


@numba.njit(cache=True)
def _residual(W, w, r, mu, rho, u):
    """Relative natural-map residual of r, with u = W r + w written into ``u``."""
    _velocities(W, w, r, u)
    num = 0.0
    den = 0.0
    for i in range(mu.size):
        un, ut = u[2 * i], u[2 * i + 1]
        pn, pt = cone_project(r[2 * i] - rho[i] * (un + mu[i] * abs(ut)), r[2 * i + 1] - rho[i] * ut, mu[i])
        num += (r[2 * i] - pn) ** 2 + (r[2 * i + 1] - pt) ** 2
        den += (rho[i] * w[2 * i]) ** 2 + (rho[i] * w[2 * i + 1]) ** 2
    if den == 0.0:
        return np.sqrt(num)
    return np.sqrt(num / den)


@numba.njit(cache=True)
def _scaling(W, c, rho):
    """rho_i = 1 / ||W_ii||_F, or 0 for a contact that no impulse can move (||W_ii|| ~ 0)."""
    big = 0.0
    for i in range(c):
        rho[i] = np.sqrt(W[2 * i, 2 * i] ** 2 + 2 * W[2 * i, 2 * i + 1] ** 2 + W[2 * i + 1, 2 * i + 1] ** 2)
        big = max(big, rho[i])
    for i in range(c):
        rho[i] = 1.0 / rho[i] if rho[i] > 1e-13 * big else 0.0


@numba.njit(cache=True)
def _pgs(W, w, mu, r, u, tol, max_iter):
    """Gauss-Seidel sweeps from r until the residual is below tol; u = W r + w on return."""
    c = mu.size
    rho = np.empty(c)
    _scaling(W, c, rho)
    res = _residual(W, w, r, mu, rho, u)
    it = 0
    while res > tol and it < max_iter:
        for i in range(c):
            a = W[2 * i, 2 * i]
            b = W[2 * i, 2 * i + 1]
            d = W[2 * i + 1, 2 * i + 1]
            rn0, rt0 = r[2 * i], r[2 * i + 1]
            zn = u[2 * i] - a * rn0 - b * rt0
            zt = u[2 * i + 1] - b * rn0 - d * rt0
            if rho[i] == 0.0:
                continue
            rn, rt = _local_solve(a, b, d, zn, zt, mu[i], rn0, rt0, rho[i])
            dn, dt = rn - rn0, rt - rt0
            if dn != 0.0 or dt != 0.0:
                r[2 * i], r[2 * i + 1] = rn, rt
                for k in range(2 * c):
                    u[k] += W[k, 2 * i] * dn + W[k, 2 * i + 1] * dt
        it += 1
        res = _residual(W, w, r, mu, rho, u)
    return it, res


@numba.njit(cache=True)
def _finite(x) -> bool:
    total = 0.0
    for v in x.ravel():
        total += v * 0.0  # NaN for a NaN or an infinity
    return total == 0.0


@numba.njit(cache=True)
def _checked_pgs(W, w, mu, r, u, tol, max_iter):
    """``_pgs`` after the value checks (in one compiled call: a small problem's solve costs
    microseconds, less than a handful of numpy checks from Python). Sweeps are -1 on bad
    values."""
    if not (_finite(W) and _finite(w) and _finite(mu) and _finite(r)):
        return -1, np.inf
    for m in mu:
        if m < 0.0:
            return -1, np.inf
    return _pgs(W, w, mu, r, u, tol, max_iter)


def _array(x, ndim: int) -> np.ndarray:
    """x as a C-contiguous float64 array (x itself when it already is one)."""
    if type(x) is np.ndarray and x.dtype == np.float64 and x.flags.c_contiguous and x.ndim == ndim:
        return x
    return np.ascontiguousarray(x, dtype=np.float64).reshape((-1,) if ndim == 1 else np.shape(x))


def solve_dfcp(W, w, mu, r0=None, tol: float = 1e-10, max_iter: int = 10000) -> DFCPResult:
    """Solve (W r + w, r) in C(mu) by projected Gauss-Seidel; W (2c, 2c), w (2c,), mu (c,) or scalar,
    r0 (c, 2) warm start (N s). Stops on the residual (module docstring) or after max_iter sweeps."""
    W, w = _array(W, 2), _array(w, 1)
    c = w.size // 2
    if w.size != 2 * c or W.shape != (2 * c, 2 * c):
        raise JassyError(f"W, w: expected shapes (2c, 2c) and (2c,), got {W.shape} and {w.shape}")
    mu = np.full(c, float(mu)) if np.ndim(mu) == 0 else _array(mu, 1).copy()
    if mu.size != c:
        raise JassyError(f"mu: expected a scalar or {c} values, got {mu.size}")
    if not (tol > 0 and max_iter >= 1):
        raise JassyError(f"tol, max_iter: expected tol > 0 and max_iter >= 1, got {tol}, {max_iter}")
    r = np.zeros(2 * c) if r0 is None else np.array(r0, dtype=np.float64).reshape(-1)
    if r.size != 2 * c:
        raise JassyError(f"r0: expected {c} contacts x 2 values, got {r.size}")
    if c == 0:
        return DFCPResult(np.zeros((0, 2)), np.zeros((0, 2)), 0, 0.0, True)
    u = np.empty(2 * c)
    it, res = _checked_pgs(W, w, mu, r, u, float(tol), int(max_iter))
    if it < 0:
        raise JassyError("W, w, mu: expected finite values and mu >= 0")
    return DFCPResult(r.reshape(c, 2), u.reshape(c, 2), int(it), float(res), bool(res <= tol))


def natural_map_residual(W, w, r, mu) -> float:
    """The solver's stopping residual (module docstring) for impulses r (c, 2)."""
    W, w = _array(W, 2), _array(w, 1)
    c = w.size // 2
    mu = np.broadcast_to(np.asarray(mu, dtype=np.float64), (c,)).copy()
    rho = np.empty(c)
    _scaling(W, c, rho)
    return float(_residual(W, w, np.array(r, dtype=np.float64).reshape(-1), mu, rho, np.empty(2 * c)))
