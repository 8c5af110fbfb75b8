"""Delassus operator of a contact step: W = H K^{-1}|_v H^T with K = [[A, C^T], [C, 0]] (v then lam),
the free solution x_free = K^{-1} (b, c) and x = x_free + K^{-1} (H^T r, 0) once r is known.

K is given in band storage (physics.rod.band) with pos[i] = band position of unknown i.

* ``SchurDelassus``: B = the unknowns touched by H, plus the multipliers of constraints acting only
  on them or entering them (``_absorb``: for a rod, the gluing rows into a contact element, so every
  rod segment left in I is held at one end only), I = the rest, in band order. K_II is K with the B
  rows and columns replaced by identity ones (same band storage, no renumbering): independent
  diagonal blocks (rod segments between contacts), found from its band and factored by one band
  LU. For each block, the columns of K_IB that reach it are solved within the block, so
  S = K_BB - K_BI K_II^{-1} K_IB costs O(N) and is banded in B order (a block couples only the
  contacts on either side of it). Then W = H_B S^{-1} H_B^T (one multi-RHS band solve of
  size |B|); x_free = K^{-1} (b, c) through the partition, and the final x (x_B by one S solve,
  x_I by one K_II solve) polished by iterative refinement to a componentwise backward error
  < 1e-10 (with the contact impulses, stuck contacts cancel large terms in S). RuntimeError if
  K_II or S is singular, I is empty, or the refinement fails: the caller then solves directly.
* ``DirectDelassus``: K factorised once (band LU, or equilibrated SuperLU when K is not banded),
  2c solves with [H^T; 0]: O(N c), the reference.
"""

from __future__ import annotations

import numba
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from jassy.jit import drop_stale_cache
from physics.rod import band
from physics.rod.band import band_lu, band_residual, band_solve, band_solve_vec

drop_stale_cache(__file__, [band])  # its cache holds copies of their kernels


@numba.njit(cache=True)
def _absorb(ab, kl, ku, is_b, is_primal):
    """Move to B the multipliers whose nonzero couplings all lie in B, and those coupled to a primal
    B unknown that follows them in band order (for a rod: the gluing rows entering a contact
    element), so that no block of K_II is constrained at both ends (a straight rod segment held at
    both ends has redundant constraints: K_II singular or ill-conditioned)."""
    n = ab.shape[0]
    kv = kl + ku
    m = max(kl, ku)
    given = is_b.copy()
    seen = np.zeros(n, dtype=np.bool_)
    for q0 in range(n):
        if not given[q0]:
            continue
        for p in range(max(0, q0 - m), min(n, q0 + m + 1)):  # candidates: multipliers next to B
            if given[p] or is_primal[p] or seen[p]:
                continue
            seen[p] = True
            found, inside, ahead = False, True, False
            for q in range(max(0, p - m), min(n, p + m + 1)):
                if q == p:
                    continue
                a = ab[p, kv + q - p] if -ku <= q - p <= kl else 0.0
                t = ab[q, kv + p - q] if -ku <= p - q <= kl else 0.0
                if a != 0.0 or t != 0.0:
                    found = True
                    inside = inside and given[q]
                    ahead = ahead or (q > p and given[q] and is_primal[q])
            if found and (inside or ahead):
                is_b[p] = True


@numba.njit(cache=True)
def _h_transpose(indptr, bcols, data, nb):
    """H_B^T (nb, 2c) dense from the CSR rows of H (columns as B indices)."""
    out = np.zeros((nb, indptr.size - 1))
    for r in range(indptr.size - 1):
        for t in range(indptr[r], indptr[r + 1]):
            out[bcols[t], r] += data[t]
    return out


@numba.njit(cache=True)
def _delassus(indptr, bcols, data, xb):
    """W = H_B X_B, symmetrised (X_B = S^{-1} H_B^T)."""
    m = indptr.size - 1
    W = np.zeros((m, m))
    for r in range(m):
        for t in range(indptr[r], indptr[r + 1]):
            v = data[t]
            for c in range(m):
                W[r, c] += v * xb[bcols[t], c]
    for r in range(m):
        for c in range(r + 1, m):
            a = 0.5 * (W[r, c] + W[c, r])
            W[r, c] = a
            W[c, r] = a
    return W


@numba.njit(cache=True)
def _decoupled(ab, kl, ku, is_b):
    """K with the B rows and columns replaced by identity ones: K_II in place, block diagonal
    once B is removed; and the boundaries of its independent diagonal blocks (B positions alone)."""
    n = ab.shape[0]
    kv = kl + ku
    out = ab.copy()
    for p in range(n):
        if is_b[p]:
            for i in range(max(0, p - ku), min(n, p + kl + 1)):  # column p
                out[p, kv + i - p] = 0.0
            for q in range(max(0, p - kl), min(n, p + ku + 1)):  # row p
                out[q, kv + p - q] = 0.0
            out[p, kv] = 1.0
    cuts = [0]
    reach = 0
    for a in range(n):
        for b in range(a + 1, min(n, a + max(kl, ku) + 1)):
            up = out[b, kv + a - b] if b - a <= ku else 0.0
            lo = out[a, kv + b - a] if b - a <= kl else 0.0
            if up != 0.0 or lo != 0.0:
                reach = max(reach, b)
        if reach <= a:
            cuts.append(a + 1)
    return out, np.array(cuts, dtype=np.int64)


@numba.njit(cache=True)
def _group(keys, vals, nkeys):
    """Stable counting sort of vals by keys in [0, nkeys): (start (nkeys + 1,), sorted vals)."""
    start = np.zeros(nkeys + 1, dtype=np.int64)
    for k in keys:
        start[k + 1] += 1
    start = np.cumsum(start)
    fill = start[:-1].copy()
    out = np.empty(keys.size, dtype=np.int64)
    for t in range(keys.size):
        out[fill[keys[t]]] = vals[t]
        fill[keys[t]] += 1
    return start, out


@numba.njit(cache=True)
def _couplings(ab, kl, ku, is_b, bidx, cuts):
    """Per block s of K_II, the B indices coupled to it, increasing: columns of K_IB in
    cols[cstart[s]:cstart[s + 1]] and rows of K_BI in rows[rstart[s]:rstart[s + 1]]."""
    n = ab.shape[0]
    kv = kl + ku
    nseg = cuts.size - 1
    seg = np.empty(n, dtype=np.int64)
    for s in range(nseg):
        seg[cuts[s] : cuts[s + 1]] = s
    m = bidx.size * (kl + ku + 1)
    cs, cj = np.empty(m, dtype=np.int64), np.empty(m, dtype=np.int64)
    rs, rj = np.empty(m, dtype=np.int64), np.empty(m, dtype=np.int64)
    lastc = np.full(nseg, -1, dtype=np.int64)
    lastr = np.full(nseg, -1, dtype=np.int64)
    nc = nr = 0
    for jb in range(bidx.size):
        q = bidx[jb]
        for i in range(max(0, q - ku), min(n, q + kl + 1)):  # K[i, q]: column of K_IB
            if not is_b[i] and ab[q, kv + i - q] != 0.0 and lastc[seg[i]] != jb:
                lastc[seg[i]] = jb
                cs[nc], cj[nc] = seg[i], jb
                nc += 1
        for i in range(max(0, q - kl), min(n, q + ku + 1)):  # K[q, i]: row of K_BI
            if not is_b[i] and ab[i, kv + q - i] != 0.0 and lastr[seg[i]] != jb:
                lastr[seg[i]] = jb
                rs[nr], rj[nr] = seg[i], jb
                nr += 1
    cstart, cols = _group(cs[:nc], cj[:nc], nseg)
    rstart, rows = _group(rs[:nr], rj[:nr], nseg)
    return cstart, cols, rstart, rows


@numba.njit(cache=True)
def _schur(ab, kl, ku, is_b, idx, bidx, lu, piv, cuts):
    """S = K_BB - K_BI K_II^{-1} K_IB in band storage (B order): (S, its half-bandwidth)."""
    n = ab.shape[0]
    kv = kl + ku
    nb = bidx.size
    cstart, cols, rstart, rows = _couplings(ab, kl, ku, is_b, bidx, cuts)
    w = 0
    for jb in range(nb):  # K_BB
        p = bidx[jb]
        for i in range(max(0, p - ku), min(n, p + kl + 1)):
            if is_b[i] and ab[p, kv + i - p] != 0.0:
                w = max(w, abs(idx[i] - jb))
    nseg = cuts.size - 1
    for s in range(nseg):
        c0, c1, r0, r1 = cstart[s], cstart[s + 1], rstart[s], rstart[s + 1]
        if c1 > c0 and r1 > r0:  # lists are increasing
            w = max(w, max(cols[c1 - 1], rows[r1 - 1]) - min(cols[c0], rows[r0]))
    sv = 2 * w
    S = np.zeros((nb, 3 * w + 1))
    for jb in range(nb):
        p = bidx[jb]
        for i in range(max(0, p - ku), min(n, p + kl + 1)):
            if is_b[i] and ab[p, kv + i - p] != 0.0:
                S[jb, sv + idx[i] - jb] = ab[p, kv + i - p]
    for s in range(nseg):
        lo, hi = cuts[s], cuts[s + 1]
        c0, c1, r0, r1 = cstart[s], cstart[s + 1], rstart[s], rstart[s + 1]
        if c1 == c0 or r1 == r0:
            continue
        z = np.zeros((hi - lo, c1 - c0))
        for t in range(c1 - c0):  # columns of K_IB restricted to the block
            q = bidx[cols[c0 + t]]
            for i in range(max(lo, q - ku), min(hi, q + kl + 1)):
                if not is_b[i]:
                    z[i - lo, t] = ab[q, kv + i - q]
        band_solve(lu, kl, ku, piv, z, lo, hi)
        for u in range(r0, r1):  # S[jb, cols] -= K[q, block] z
            jb = rows[u]
            q = bidx[jb]
            for i in range(max(lo, q - kl), min(hi, q + ku + 1)):
                v = ab[i, kv + q - i]
                if v != 0.0 and not is_b[i]:
                    for t in range(c1 - c0):
                        S[cols[c0 + t], sv + jb - cols[c0 + t]] -= v * z[i - lo, t]
    return S, w


@numba.njit(cache=True)
def _reduce(ab, kl, ku, is_b, bidx, lu, piv, rhs):
    """t = rhs_B - K_BI K_II^{-1} rhs_I (rhs in band order): S x_B = t."""
    n = ab.shape[0]
    kv = kl + ku
    z = rhs.copy()
    for jb in range(bidx.size):
        z[bidx[jb]] = 0.0
    band_solve_vec(lu, kl, ku, piv, z, 0, n)
    t = np.empty(bidx.size)
    for jb in range(bidx.size):  # t = rhs_B - K_BI z_I
        q = bidx[jb]
        acc = rhs[q]
        for p in range(max(0, q - kl), min(n, q + ku + 1)):
            if not is_b[p]:
                acc -= ab[p, kv + q - p] * z[p]
        t[jb] = acc
    return t


@numba.njit(cache=True)
def _expand(ab, kl, ku, is_b, bidx, lu, piv, rhs, xb):
    """x (band order) with x_B = xb and x_I = K_II^{-1} (rhs_I - K_IB x_B)."""
    n = ab.shape[0]
    kv = kl + ku
    x = rhs.copy()
    for jb in range(bidx.size):
        x[bidx[jb]] = 0.0
    for jb in range(bidx.size):
        q = bidx[jb]
        for i in range(max(0, q - ku), min(n, q + kl + 1)):
            if not is_b[i]:
                x[i] -= ab[q, kv + i - q] * xb[jb]
    band_solve_vec(lu, kl, ku, piv, x, 0, n)
    for jb in range(bidx.size):
        x[bidx[jb]] = xb[jb]
    return x


class SchurDelassus:
    """Partitioned Schur complement (module docstring). ab, kl, ku, pos: K in band storage;
    ndof: number of primal unknowns; H (2c, ndof) sparse; rhs = (b, c)."""

    def __init__(self, ab, kl, ku, pos, ndof, H, rhs):
        n = ab.shape[0]
        self.ab, self.kl, self.ku, self.pos, self.ndof = ab, kl, ku, pos, ndof
        H = sp.csr_matrix(H)
        H.sum_duplicates()
        is_b = np.zeros(n, dtype=np.bool_)
        is_b[pos[H.indices]] = True
        is_primal = np.zeros(n, dtype=np.bool_)
        is_primal[pos[:ndof]] = True
        _absorb(ab, kl, ku, is_b, is_primal)
        self.is_b = is_b
        self.bidx = np.nonzero(is_b)[0]
        if self.bidx.size == n:
            raise RuntimeError("no interior unknowns to condense")
        self.idx = np.full(n, -1, dtype=np.int64)
        self.idx[self.bidx] = np.arange(self.bidx.size)
        self.lu, cuts = _decoupled(ab, kl, ku, is_b)
        self.piv = np.empty(n, dtype=np.int64)
        if band_lu(self.lu, kl, ku, self.piv):
            raise RuntimeError("K_II singular")
        self.slu, self.sw = _schur(ab, kl, ku, is_b, self.idx, self.bidx, self.lu, self.piv, cuts)
        self.spiv = np.empty(self.bidx.size, dtype=np.int64)
        if band_lu(self.slu, self.sw, self.sw, self.spiv):
            raise RuntimeError("Schur complement singular")
        self.hcols = self.idx[pos[H.indices]]
        self.hrows = np.repeat(np.arange(H.shape[0]), np.diff(H.indptr))
        self.XB = _h_transpose(H.indptr, self.hcols, H.data, self.bidx.size)
        band_solve(self.slu, self.sw, self.sw, self.spiv, self.XB, 0, self.bidx.size)
        self.W = _delassus(H.indptr, self.hcols, H.data, self.XB)
        self.H = H
        self.rhs = np.empty(n)
        self.rhs[pos] = rhs
        self.t = self._reduce(self.rhs)
        self.xf = self._expand(self.rhs, self._schur_solve(self.t))
        self.x_free = self.xf[pos]

    def _reduce(self, rhs):
        return _reduce(self.ab, self.kl, self.ku, self.is_b, self.bidx, self.lu, self.piv, rhs)

    def _schur_solve(self, t):
        x = t.copy()
        band_solve_vec(self.slu, self.sw, self.sw, self.spiv, x, 0, x.size)
        return x

    def _expand(self, rhs, xb):
        return _expand(self.ab, self.kl, self.ku, self.is_b, self.bidx, self.lu, self.piv, rhs, xb)

    def _refined(self, rhs, x):
        """Iterative refinement until the componentwise backward error is < 1e-10."""
        for _ in range(4):
            res, omega = band_residual(self.ab, self.kl, self.ku, x, rhs)
            if omega < 1e-10:
                return x
            x = x + self._expand(res, self._schur_solve(self._reduce(res)))
        raise RuntimeError(f"partitioned solve not accurate (backward error {omega:.1e})")

    def solution(self, r):
        """x = K^{-1} (b + H^T r, c) in natural order (H^T r lies in B: rhs_I and K_II^{-1} rhs_I are
        those of x_free)."""
        rhs = self.rhs.copy()
        rhs[self.pos[: self.ndof]] += self.H.T @ r
        hr = np.bincount(self.hcols, weights=self.H.data * r[self.hrows], minlength=self.bidx.size)
        xb = self._schur_solve(self.t + hr)
        return self._refined(rhs, self._expand(rhs, xb))[self.pos]


class BandKKT:
    """Band LU of K (a copy of ab): ``solve(rhs)`` for rhs (N,) or (N, k) in natural order."""

    def __init__(self, ab, kl, ku, pos):
        self.lu, self.kl, self.ku, self.pos = ab.copy(), kl, ku, pos
        self.piv = np.empty(ab.shape[0], dtype=np.int64)
        info = band_lu(self.lu, kl, ku, self.piv)
        if info:
            raise RuntimeError(f"singular KKT matrix (pivot {info})")

    def solve(self, rhs):
        rhs = np.asarray(rhs, dtype=np.float64)
        x = np.empty(rhs.shape)
        x[self.pos] = rhs
        if rhs.ndim == 1:
            band_solve_vec(self.lu, self.kl, self.ku, self.piv, x, 0, x.shape[0])
        else:
            band_solve(self.lu, self.kl, self.ku, self.piv, x, 0, x.shape[0])
        return x[self.pos]


class SparseKKT:
    """SuperLU of K (sparse; the first ndof unknowns primal), symmetrically equilibrated (primal
    unknowns by 1/sqrt(A_ii), multipliers by the inverse norm of their scaled C rows): element masses
    of short mixed-model elements span many decades. ``solve(rhs)`` as BandKKT."""

    def __init__(self, K, ndof: int):
        K = sp.csr_matrix(K)
        d1 = 1.0 / np.sqrt(np.maximum(np.abs(K.diagonal()[:ndof]), 1e-300))
        Cs = K[ndof:, :ndof] @ sp.diags(d1)
        d2 = 1.0 / np.maximum(spla.norm(Cs, axis=1), 1e-300) if K.shape[0] > ndof else np.zeros(0)
        self.d = np.concatenate([d1, d2])
        D = sp.diags(self.d)
        self.lu = spla.splu((D @ K @ D).tocsc())

    def solve(self, rhs):
        d = self.d if rhs.ndim == 1 else self.d[:, None]
        return d * self.lu.solve(d * rhs)


class DirectDelassus:
    """W = H X_v with X = K^{-1} [H^T; 0]: 2c solves with one factorisation ``kkt`` (BandKKT or
    SparseKKT) of the whole K."""

    def __init__(self, kkt, ndof, H, rhs):
        self.x_free = kkt.solve(rhs)
        self.W = np.zeros((0, 0))
        self.X = np.zeros((rhs.size, 0))
        if H.shape[0]:
            E = np.zeros((rhs.size, H.shape[0]))
            E[:ndof] = H.T.toarray()
            self.X = kkt.solve(E)
            W = H @ self.X[:ndof]
            self.W = 0.5 * (W + W.T)

    def solution(self, r):
        return self.x_free + self.X @ r
