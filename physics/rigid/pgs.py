"""Frictional contact by projected Gauss-Seidel (PGS) on the 3-D Coulomb cone.

Impulse-level problem for c contacts, each with local frame (normal n, tangents t1, t2):

    u = W r + b,   K_mu = {r : |r_T| <= mu r_N},   Coulomb: r in K_mu, u_N >= 0, r_N u_N = 0,
    and if r_N > 0 either u_T = 0 (stick) or |r_T| = mu r_N with r_T = -alpha u_T (slip).

``W`` (3c x 3c, m/(N s) = 1/kg) is the Delassus matrix J M^-1 J^T with rows ordered
(n, t1, t2) per contact; ``b`` (m/s) is the free relative contact velocity J v_free, into
which the caller folds restitution or stabilisation targets (e.g. b_N += e v_N^-, so that
u_N >= 0 means "separates at least at the target velocity"). Impulses r are in N s.

Per-contact update (one PGS sweep visits the contacts in order; this is the *normal-then-
tangent-disk* scheme, not an exact 3x3 block solve):

1. normal: r_N <- max(0, r_N - u_N / W_nn) (exact 1-D solve of the local problem);
2. tangent: r_T <- Proj_{|.| <= mu r_N}(r_T - u_T / l_T), with u_T refreshed for the new r_N
   and l_T the largest eigenvalue of the 2x2 tangential block. With a scalar step the fixed
   point is exactly Coulomb's maximal-dissipation law (r_T antiparallel to u_T when
   slipping); for an isotropic tangential block it is the exact 2-D disk solve.

u is kept current by column updates (W symmetric), so the residual costs O(c) per sweep.
Stopping residual (Siconos fc3d natural map, unweighted, rho = 1):

    residual = || r - Proj_{K_mu}(r - (u + mu |u_T| e_N)) ||_2 ,

which is zero exactly at Coulomb solutions (De Saxce's bipotential form).
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np
import scipy.sparse as sp

from jassy.errors import JassyError


class PGSResult(NamedTuple):
    """r (c, 3) impulses (N s) and u (c, 3) = W r + b velocities (m/s), rows (n, t1, t2);
    iterations = sweeps done; residual = natural-map norm (see module doc)."""

    r: np.ndarray
    u: np.ndarray
    iterations: int
    residual: float


@numba.njit(cache=True)
def _proj_cone(xn, xt1, xt2, mu):
    """Euclidean projection of (xn, xt1, xt2) onto {|x_T| <= mu x_N}."""
    t = np.sqrt(xt1 * xt1 + xt2 * xt2)
    if t <= mu * xn:
        return xn, xt1, xt2
    if mu * t <= -xn:
        return 0.0, 0.0, 0.0
    s = (xn + mu * t) / (1.0 + mu * mu)
    return s, mu * s * xt1 / t, mu * s * xt2 / t


@numba.njit(cache=True)
def _natural_residual(r, u, mu):
    acc = 0.0
    for i in range(mu.size):
        k = 3 * i
        ut = np.sqrt(u[k + 1] ** 2 + u[k + 2] ** 2)
        pn, p1, p2 = _proj_cone(r[k] - u[k] - mu[i] * ut, r[k + 1] - u[k + 1], r[k + 2] - u[k + 2], mu[i])
        acc += (r[k] - pn) ** 2 + (r[k + 1] - p1) ** 2 + (r[k + 2] - p2) ** 2
    return np.sqrt(acc)


@numba.njit(cache=True)
def _local_step(r, u, blk, mu, i):
    """Normal-then-tangent-disk update of contact i; returns the impulse change (3,)."""
    k = 3 * i
    rn = max(0.0, r[k] - u[k] / blk[i, 0, 0])
    dn = rn - r[k]
    ut1 = u[k + 1] + blk[i, 1, 0] * dn
    ut2 = u[k + 2] + blk[i, 2, 0] * dn
    a, c, d = blk[i, 1, 1], blk[i, 1, 2], blk[i, 2, 2]
    lmax = 0.5 * (a + d) + np.sqrt(0.25 * (a - d) ** 2 + c * c)
    x1 = r[k + 1] - ut1 / lmax
    x2 = r[k + 2] - ut2 / lmax
    rad = mu[i] * rn
    nrm = np.sqrt(x1 * x1 + x2 * x2)
    if nrm > rad:
        s = rad / nrm
        x1 *= s
        x2 *= s
    return dn, x1 - r[k + 1], x2 - r[k + 2]


@numba.njit(cache=True)
def _pgs_dense(W, b, blk, mu, r, tol, max_iter):
    c = mu.size
    u = W @ r + b
    res = _natural_residual(r, u, mu)
    it = 0
    while res > tol and it < max_iter:
        for i in range(c):
            d0, d1, d2 = _local_step(r, u, blk, mu, i)
            k = 3 * i
            r[k] += d0
            r[k + 1] += d1
            r[k + 2] += d2
            for j in range(3 * c):  # column k of symmetric W, read as contiguous rows
                u[j] += W[k, j] * d0 + W[k + 1, j] * d1 + W[k + 2, j] * d2
        it += 1
        res = _natural_residual(r, u, mu)
    u = W @ r + b
    return r, u, it, _natural_residual(r, u, mu)


@numba.njit(cache=True)
def _csr_matvec(indptr, indices, data, x, b):
    y = b.copy()
    for row in range(b.size):
        for p in range(indptr[row], indptr[row + 1]):
            y[row] += data[p] * x[indices[p]]
    return y


@numba.njit(cache=True)
def _pgs_csr(indptr, indices, data, b, blk, mu, r, tol, max_iter):
    c = mu.size
    u = _csr_matvec(indptr, indices, data, r, b)
    res = _natural_residual(r, u, mu)
    it = 0
    while res > tol and it < max_iter:
        for i in range(c):
            dr = _local_step(r, u, blk, mu, i)
            for m in range(3):
                row = 3 * i + m
                r[row] += dr[m]
                for p in range(indptr[row], indptr[row + 1]):  # column of symmetric W
                    u[indices[p]] += data[p] * dr[m]
        it += 1
        res = _natural_residual(r, u, mu)
    u = _csr_matvec(indptr, indices, data, r, b)
    return r, u, it, _natural_residual(r, u, mu)


def _as_contact_vector(x, c: int, name: str) -> np.ndarray:
    a = np.asarray(x, dtype=np.float64)
    if a.shape not in ((3 * c,), (c, 3)):
        raise JassyError(f"{name}: expected shape ({3 * c},) or ({c}, 3), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise JassyError(f"{name}: must be finite")
    return a.reshape(3 * c).copy()


def _diag_blocks(W, c: int) -> np.ndarray:
    if sp.issparse(W):
        coo = W.tocoo()
        keep = coo.row // 3 == coo.col // 3
        blk = np.zeros((c, 3, 3))
        np.add.at(blk, (coo.row[keep] // 3, coo.row[keep] % 3, coo.col[keep] % 3), coo.data[keep])
        return blk
    idx = np.arange(c)
    return np.ascontiguousarray(W.reshape(c, 3, c, 3)[idx, :, idx, :])


def solve_friction_pgs(W, b, mu, r0=None, tol: float = 1e-10, max_iter: int = 1000) -> PGSResult:
    """Solve the 3-D Coulomb contact problem u = W r + b by projected Gauss-Seidel.

    W: (3c, 3c) symmetric PSD Delassus matrix (1/kg), dense ndarray or scipy.sparse, rows
    (n, t1, t2) per contact, positive normal and tangential diagonal. b: (3c,) or (c, 3)
    free contact velocity (m/s, restitution folded in). mu: (c,) or scalar friction
    coefficients >= 0. r0: warm-start impulses (3c,) or (c, 3), N s (default 0).
    tol: natural-map residual at which to stop; max_iter: maximum sweeps. The returned
    residual tells whether tol was reached (residual <= tol) or max_iter ran out."""
    b = np.asarray(b, dtype=np.float64)
    c = b.size // 3
    if c == 0 or b.size != 3 * c:
        raise JassyError(f"b: expected 3c > 0 entries (n, t1, t2 per contact), got shape {b.shape}")
    b = _as_contact_vector(b, c, "b")
    mu = np.broadcast_to(np.asarray(mu, dtype=np.float64), (c,)).copy()
    if not np.all(np.isfinite(mu)) or np.any(mu < 0):
        raise JassyError("mu: friction coefficients must be finite and >= 0")
    r = np.zeros(3 * c) if r0 is None else _as_contact_vector(r0, c, "r0")
    if not (tol > 0) or int(max_iter) < 0:
        raise JassyError(f"tol/max_iter: expected tol > 0 and max_iter >= 0, got {tol}, {max_iter}")
    if W is None or W.shape != (3 * c, 3 * c):
        raise JassyError(f"W: expected shape ({3 * c}, {3 * c}), got {getattr(W, 'shape', None)}")
    blk = _diag_blocks(W, c)
    if not (np.all(blk[:, 0, 0] > 0) and np.all(blk[:, 1, 1] > 0) and np.all(blk[:, 2, 2] > 0)):
        raise JassyError("W: diagonal entries (normal and tangential) must be positive")
    if sp.issparse(W):
        csr = sp.csr_matrix(W, dtype=np.float64)
        if not np.all(np.isfinite(csr.data)) or abs(csr - csr.T).max() > 1e-9 * abs(csr).max():
            raise JassyError("W: must be finite and symmetric")
        out = _pgs_csr(csr.indptr, csr.indices, csr.data, b, blk, mu, r, float(tol), int(max_iter))
    else:
        Wd = np.ascontiguousarray(W, dtype=np.float64)
        if not np.all(np.isfinite(Wd)) or not np.allclose(Wd, Wd.T, rtol=1e-9, atol=1e-12 * abs(Wd).max()):
            raise JassyError("W: must be finite and symmetric")
        out = _pgs_dense(Wd, b, blk, mu, r, float(tol), int(max_iter))
    r, u, it, res = out
    return PGSResult(r.reshape(c, 3), u.reshape(c, 3), int(it), float(res))
