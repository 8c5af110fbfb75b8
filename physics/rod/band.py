"""Band matrices (numba): LU with partial pivoting, multi-RHS solves, residuals, and a band order
(reverse Cuthill-McKee) for a general sparse pattern.

Storage (LAPACK gbtrf's, transposed so a column is contiguous): an n x n matrix with kl
sub- and ku super-diagonals is an array ``ab`` of shape (n, 2 kl + ku + 1) with
ab[j, kv + i - j] = A[i, j], kv = kl + ku; the first kl entries of a row are room for the
fill-in of the LU. ``band_lu`` factors in place (rows swapped within the band, as dgbtf2);
``band_solve`` solves for a block of right-hand sides b (n, k) in place, the inner loops running
over the k columns. It can be restricted to rows [lo, hi) of a block-diagonal band matrix: the
LU of such a matrix never pivots nor fills across its blocks (entries outside a block are exact
zeros), so the blocks are solved independently.
"""

from __future__ import annotations

import numba
import numpy as np
import scipy.sparse as sp
from scipy.sparse import csgraph


@numba.njit(cache=True)
def band_lu(ab, kl, ku, piv):
    """In-place LU with partial pivoting; piv[j] = row swapped with j. Returns 0 or the 1-based
    index of a zero pivot."""
    n = ab.shape[0]
    kv = kl + ku
    ju = 0
    for j in range(n):
        km = min(kl, n - 1 - j)
        jp = 0
        best = abs(ab[j, kv])
        for i in range(1, km + 1):
            if abs(ab[j, kv + i]) > best:
                best = abs(ab[j, kv + i])
                jp = i
        piv[j] = j + jp
        if best == 0.0:
            return j + 1
        ju = max(ju, min(j + ku + jp, n - 1))
        if jp != 0:
            for c in range(j, ju + 1):
                a = ab[c, kv + j - c]
                ab[c, kv + j - c] = ab[c, kv + j + jp - c]
                ab[c, kv + j + jp - c] = a
        inv = 1.0 / ab[j, kv]
        for i in range(1, km + 1):
            ab[j, kv + i] *= inv
        for c in range(j + 1, ju + 1):
            f = ab[c, kv + j - c]
            if f != 0.0:
                for i in range(1, km + 1):
                    ab[c, kv + j + i - c] -= ab[j, kv + i] * f
    return 0


@numba.njit(cache=True)
def band_solve(lu, kl, ku, piv, b, lo, hi):
    """Solve A x = b in place for rows [lo, hi) of a block-diagonal A (b row r is row lo + r);
    lo = 0, hi = n for the whole matrix."""
    kv = kl + ku
    k = b.shape[1]
    for j in range(lo, hi):
        p = piv[j]
        r = j - lo
        if p != j:
            for c in range(k):
                t = b[r, c]
                b[r, c] = b[p - lo, c]
                b[p - lo, c] = t
        for i in range(1, min(kl, hi - 1 - j) + 1):
            f = lu[j, kv + i]
            if f != 0.0:
                for c in range(k):
                    b[r + i, c] -= f * b[r, c]
    for j in range(hi - 1, lo - 1, -1):
        r = j - lo
        inv = 1.0 / lu[j, kv]
        for c in range(k):
            b[r, c] *= inv
        for i in range(1, min(j - lo, kv) + 1):
            f = lu[j, kv - i]
            if f != 0.0:
                for c in range(k):
                    b[r - i, c] -= f * b[r, c]


@numba.njit(cache=True)
def band_solve_vec(lu, kl, ku, piv, b, lo, hi):
    """band_solve for one right-hand side b (hi - lo,) (branch-free row swaps)."""
    kv = kl + ku
    mid = max(lo, hi - kl)
    for j in range(lo, hi):
        r = j - lo
        q = piv[j] - lo
        bj = b[q]
        b[q] = b[r]
        b[r] = bj
        if j < mid:
            for i in range(1, kl + 1):
                b[r + i] -= lu[j, kv + i] * bj
        else:
            for i in range(1, hi - j):
                b[r + i] -= lu[j, kv + i] * bj
    for j in range(hi - 1, lo - 1, -1):
        r = j - lo
        bj = b[r] / lu[j, kv]
        b[r] = bj
        for i in range(1, min(j - lo, kv) + 1):
            b[r - i] -= lu[j, kv - i] * bj


@numba.njit(cache=True)
def band_residual(ab, kl, ku, x, rhs):
    """(rhs - A x, componentwise backward error max_i |rhs - A x|_i / (|A| |x| + |rhs|)_i)."""
    n = ab.shape[0]
    kv = kl + ku
    res = rhs.copy()
    scale = np.abs(rhs)
    for j in range(n):
        xj = x[j]
        for i in range(max(0, j - ku), min(n, j + kl + 1)):
            a = ab[j, kv + i - j]
            res[i] -= a * xj
            scale[i] += abs(a * xj)
    omega = 0.0
    for i in range(n):
        if res[i] != 0.0:
            omega = max(omega, abs(res[i]) / scale[i])
    return res, omega


@numba.njit(cache=True)
def band_fill(rows, cols, vals, kv, ab):
    """Add entries (rows, cols, vals), given in band positions, into ab."""
    for t in range(rows.size):
        ab[cols[t], kv + rows[t] - cols[t]] += vals[t]


class BandOrder:
    """A reverse Cuthill-McKee order of an n x n sparsity pattern (entries rows, cols) and its
    bandwidths; ``band`` fills band storage for values on that pattern, or is None when the band is
    wider than ``max_band`` (a sparse solver does better)."""

    def __init__(self, rows: np.ndarray, cols: np.ndarray, n: int, max_band: int = 64):
        pattern = sp.csr_matrix((np.ones(rows.size), (rows, cols)), shape=(n, n))
        order = csgraph.reverse_cuthill_mckee(pattern + pattern.T, symmetric_mode=True)
        self.pos = np.empty(n, dtype=np.int64)
        self.pos[order] = np.arange(n)
        d = self.pos[rows] - self.pos[cols]
        self.kl, self.ku = int(max(0, np.max(d, initial=0))), int(max(0, -np.min(d, initial=0)))
        self.n, self.banded = n, max(self.kl, self.ku) <= max_band

    def fits(self, rows: np.ndarray, cols: np.ndarray) -> bool:
        """Whether entries (rows, cols) of an n x n matrix lie within this order's band."""
        if rows.size and max(rows.max(), cols.max()) >= self.n:
            return False
        d = self.pos[rows] - self.pos[cols]
        return bool(np.all((d <= self.kl) & (-d <= self.ku)))

    def band(self, rows: np.ndarray, cols: np.ndarray, vals: np.ndarray):
        """(ab, kl, ku, pos) with the entries summed into band storage, or None if not banded."""
        if not self.banded:
            return None
        ab = np.zeros((self.n, 2 * self.kl + self.ku + 1))
        band_fill(self.pos[rows], self.pos[cols], vals.astype(np.float64), self.kl + self.ku, ab)
        return ab, self.kl, self.ku, self.pos
