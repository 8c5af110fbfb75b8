"""Linear complementarity by Lemke's method, and the contact LCPs built on it.

LCP(M, q): find z >= 0 with w = M z + q >= 0 and z.w = 0. ``lemke`` runs complementary
pivoting with the artificial variable z0 and covering vector e = 1 on a dense tableau
[I | -M | -e | q] (numba), with lexicographic tie-breaking in the ratio test (the I block
holds B^-1), which rules out cycling on degenerate problems. It terminates with a solution
for P-matrices and, when the LCP is feasible, for copositive-plus matrices (e.g. PSD M);
otherwise it ends on a secondary ray ("ray termination").

``frictionless_contact``: normal impulses for W = J M^-1 J^T, b = J v_free (+ restitution).
``polyhedral_friction_lcp``: the Stewart-Trinkle / Anitescu-Potra LCP with a k-direction
polygonal friction cone, a cross-check for the PGS solver on small problems.
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

from jassy.errors import JassyError


class LCPResult(NamedTuple):
    """z, w = M z + q (recomputed from z), pivots done, status in {"solved", "ray termination",
    "max pivots"}."""

    z: np.ndarray
    w: np.ndarray
    pivots: int
    status: str


_SOLVED, _RAY, _MAXPIV = 0, 1, 2
_STATUS = {_SOLVED: "solved", _RAY: "ray termination", _MAXPIV: "max pivots"}


@numba.njit(cache=True)
def _pivot(T, row, col):
    T[row] /= T[row, col]
    for i in range(T.shape[0]):
        if i != row and T[i, col] != 0.0:
            T[i] -= T[i, col] * T[row]


@numba.njit(cache=True)
def _ratio_row(T, col, n, z0_row, tol):
    """Lexicographic minimum-ratio row for entering column ``col``; -1 if the column is a ray."""
    d = T[:, col]
    rhs = T[:, 2 * n + 1]
    thresh = tol * max(1.0, np.max(np.abs(d)))
    cand = np.empty(n, np.int64)
    m = 0
    theta = np.inf
    for i in range(n):
        if d[i] > thresh:
            cand[m] = i
            m += 1
            theta = min(theta, rhs[i] / d[i])
    if m == 0:
        return -1
    tie = 1e-11 * (1.0 + abs(theta))
    k = 0
    for j in range(m):
        i = cand[j]
        if rhs[i] / d[i] <= theta + tie:
            if i == z0_row:  # let z0 leave whenever it ties: that ends the path
                return i
            cand[k] = i
            k += 1
    m = k
    c = 0
    while m > 1 and c < n:  # break ties on the columns of B^-1
        best = np.inf
        for j in range(m):
            best = min(best, T[cand[j], c] / d[cand[j]])
        k = 0
        for j in range(m):
            i = cand[j]
            if T[i, c] / d[i] <= best + 1e-13 * (1.0 + abs(best)):
                cand[k] = i
                k += 1
        m = k
        c += 1
    return cand[0]


@numba.njit(cache=True)
def _lemke(M, q, max_pivots, tol):
    n = q.size
    z = np.zeros(n)
    if np.min(q) >= 0.0:
        return z, 0, _SOLVED
    T = np.zeros((n, 2 * n + 2))
    for i in range(n):
        T[i, i] = 1.0
        T[i, 2 * n] = -1.0
        T[i, 2 * n + 1] = q[i]
        for j in range(n):
            T[i, n + j] = -M[i, j]
    basis = np.arange(n)  # 0..n-1: w_i, n..2n-1: z_i, 2n: z0
    row = 0
    for i in range(n):  # most negative q; on ties the last index is the lexicographic choice
        if q[i] <= q[row]:
            row = i
    _pivot(T, row, 2 * n)
    leaving = basis[row]
    basis[row] = 2 * n
    z0_row = row
    pivots = 1
    status = _MAXPIV
    while pivots < max_pivots:
        entering = leaving + n if leaving < n else leaving - n
        row = _ratio_row(T, entering, n, z0_row, tol)
        if row < 0:
            status = _RAY
            break
        _pivot(T, row, entering)
        pivots += 1
        leaving = basis[row]
        basis[row] = entering
        if leaving == 2 * n:
            status = _SOLVED
            break
    for i in range(n):
        if n <= basis[i] < 2 * n:
            z[basis[i] - n] = T[i, 2 * n + 1]
    return z, pivots, status


def lemke(M, q, max_pivots: int | None = None, tol: float = 1e-12) -> LCPResult:
    """Solve LCP(M, q) (w = M z + q, w >= 0, z >= 0, z.w = 0) by Lemke's method.

    M: (n, n); q: (n,). max_pivots: default 50 n + 100. tol: relative pivot threshold.
    Check ``status``: on "ray termination" (no solution found: infeasible or M not
    copositive-plus) or "max pivots", z is the last basic point, not a solution."""
    M = np.ascontiguousarray(M, dtype=np.float64)
    q = np.ascontiguousarray(q, dtype=np.float64).ravel()
    n = q.size
    if n == 0 or M.shape != (n, n):
        raise JassyError(
            f"M, q: expected M of shape (n, n) and q of shape (n,), n > 0; got {M.shape}, {q.shape}"
        )
    if not (np.all(np.isfinite(M)) and np.all(np.isfinite(q))):
        raise JassyError("M, q: must be finite")
    if not (0 < tol < 1e-3):
        raise JassyError(f"tol: expected 0 < tol < 1e-3, got {tol}")
    maxp = 50 * n + 100 if max_pivots is None else int(max_pivots)
    if maxp < 1:
        raise JassyError(f"max_pivots: expected >= 1, got {max_pivots}")
    z, piv, st = _lemke(M, q, maxp, float(tol))
    return LCPResult(z, M @ z + q, int(piv), _STATUS[int(st)])


def frictionless_contact(W, b) -> np.ndarray:
    """Normal contact impulses (c,), N s, from 0 <= lambda  _|_  W lambda + b >= 0.

    W: (c, c) Delassus matrix J M^-1 J^T (1/kg, PSD); b: (c,) free normal velocity J v_free
    (m/s), plus the restitution term e v^- if wanted. Raises JassyError if Lemke fails."""
    res = lemke(W, b)
    if res.status != "solved":
        raise JassyError(f"W, b: frictionless contact LCP not solved by Lemke ({res.status})")
    return res.z


def polyhedral_friction_lcp(W, b, mu, directions: int = 8):
    """Stewart-Trinkle / Anitescu-Potra friction LCP with a ``directions``-gon friction cone.

    W: (3c, 3c) Delassus matrix, rows (n, t1, t2) per contact; b: (3c,) or (c, 3) free contact
    velocity (m/s); mu: (c,) or scalar. Tangent impulse = sum_k beta_k d_k over the unit
    directions d_k at angles 2 pi k / directions, with 0 <= c_n _|_ u_N >= 0,
    0 <= beta_k _|_ lambda + d_k.u_T >= 0, 0 <= lambda _|_ mu c_n - sum beta >= 0 (lambda ~ |u_T|).
    Returns (r (c, 3) N s, u (c, 3) = W r + b m/s, LCPResult); raises JassyError if Lemke fails."""
    b = np.asarray(b, dtype=np.float64).ravel()
    c = b.size // 3
    W = np.asarray(W, dtype=np.float64)
    if c == 0 or b.size != 3 * c or W.shape != (3 * c, 3 * c):
        raise JassyError(f"W, b: expected W (3c, 3c) and b (3c,), got {W.shape}, {b.shape}")
    mu = np.broadcast_to(np.asarray(mu, dtype=np.float64), (c,))
    if np.any(mu < 0) or not np.all(np.isfinite(mu)):
        raise JassyError("mu: friction coefficients must be finite and >= 0")
    k = int(directions)
    if k < 3:
        raise JassyError(f"directions: expected >= 3, got {directions}")
    ang = 2 * np.pi * np.arange(k) / k
    nb = 1 + k
    E = np.zeros((3 * c, c * nb))
    idx = np.arange(c)
    E[3 * idx, idx * nb] = 1.0
    for j in range(k):
        E[3 * idx + 1, idx * nb + 1 + j] = np.cos(ang[j])
        E[3 * idx + 2, idx * nb + 1 + j] = np.sin(ang[j])
    Ehat = np.zeros((c * nb, c))
    for j in range(k):
        Ehat[idx * nb + 1 + j, idx] = 1.0
    U = -Ehat.T.copy()
    U[idx, idx * nb] = mu
    M = np.block([[E.T @ W @ E, Ehat], [U, np.zeros((c, c))]])
    q = np.concatenate([E.T @ b, np.zeros(c)])
    res = lemke(M, q)
    if res.status != "solved":
        raise JassyError(f"W, b, mu: polyhedral friction LCP not solved by Lemke ({res.status})")
    r = E @ res.z[: c * nb]
    return r.reshape(c, 3), (W @ r + b).reshape(c, 3), res
