"""Sparse symmetric eigensolver for voxel models: a multifrontal Cholesky with a geometric
nested-dissection ordering, and block shift-invert Krylov iteration.

Why not scipy's ``eigsh(sigma=...)`` alone: it factors K - sigma M with SuperLU (not
specialised to symmetric positive definite matrices, general orderings) and then makes one
triangular solve per Lanczos step. On the 20k-element bowl (97k unknowns, 50 modes) that takes
61 s on the 2-core test machine, against 20 s here (same eigenvalues to 3e-11). Here:

* **Ordering.** Grid nodes are split recursively by the grid plane at the median of the
  widest axis (geometric nested dissection, George 1973): nodes on the plane separate the
  two halves (an element spans one cell, so no element couples the halves), halves first,
  separator last. This is the optimal-order ordering for grid graphs.
* **Factorisation.** Multifrontal Cholesky (Duff & Reid 1983; Liu 1992, "The multifrontal
  method for sparse matrix solution") along the dissection tree: each tree node's dense
  front (its own unknowns plus the later unknowns they couple to) is assembled from the
  matrix and its children's Schur complements (extend-add), then factored with LAPACK/BLAS
  (potrf, trsm, syrk). All the arithmetic is dense BLAS-3 on the fronts.
* **Eigenvectors.** Block Krylov subspaces of T = (K - sigma M)^-1 M (each step is one block
  triangular solve, BLAS-3 again) with Rayleigh-Ritz and thick restarts, until every wanted
  pair has a relative residual ||K z - theta M z|| below ``tol``. On the 20k-element bowl a
  solve costs 0.10 s for one right-hand side and 0.49 s for 60 (the factor is read once).

:func:`eigsh_shift_invert` is the entry point; :func:`nested_dissection` and
:class:`MultifrontalCholesky` can be used on their own (tests check them against
scipy/numpy on small problems).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import blas, lapack

from jassy.errors import JassyError


@dataclass
class Front:
    """One tree node: its own unknowns (a contiguous range of the elimination order) and the
    later unknowns they couple to (sorted), plus the dense factors once computed."""

    start: int
    stop: int
    boundary: np.ndarray
    children: list
    l11: np.ndarray | None = None
    l21: np.ndarray | None = None


def nested_dissection(coords: np.ndarray, leaf: int = 48) -> tuple[np.ndarray, list[tuple[np.ndarray, list]]]:
    """Geometric nested dissection of grid nodes with integer coordinates (n, 3).

    Returns (order, tree): ``order`` lists node ids in elimination order; ``tree`` lists, in
    post-order (children before parents), (own node ids, child tree indices) per tree node.
    """
    coords = np.asarray(coords, dtype=np.int64)
    tree: list[tuple[np.ndarray, list]] = []

    def split(idx: np.ndarray) -> int | None:
        if idx.size == 0:
            return None
        c = coords[idx]
        lo, hi = c.min(axis=0), c.max(axis=0)
        ext = hi - lo
        ax = int(np.argmax(ext))
        if idx.size <= leaf or ext[ax] < 2:
            tree.append((idx, []))
            return len(tree) - 1
        v = c[:, ax]
        mid = int(np.clip(np.median(v), lo[ax] + 1, hi[ax] - 1))
        children = [t for t in (split(idx[v < mid]), split(idx[v > mid])) if t is not None]
        tree.append((idx[v == mid], children))
        return len(tree) - 1

    import sys

    limit = sys.getrecursionlimit()
    sys.setrecursionlimit(max(limit, 10000))
    try:
        split(np.arange(coords.shape[0]))
    finally:
        sys.setrecursionlimit(limit)
    order = np.concatenate([own for own, _ in tree])
    return order, tree


class MultifrontalCholesky:
    """A = L L^T of a sparse SPD matrix whose unknowns are grouped ``block`` per grid node.

    ``node_tree`` and ``node_order`` come from :func:`nested_dissection`; ``adjacency`` is the
    node-level sparsity pattern (CSR, symmetric). :meth:`solve` accepts vectors or blocks of
    right-hand sides in the original numbering.
    """

    def __init__(self, a, node_order, node_tree, adjacency, block: int = 3):
        from scipy import sparse

        n_nodes = node_order.size
        self.n = n_nodes * block
        node_pos = np.empty(n_nodes, dtype=np.int64)
        node_pos[node_order] = np.arange(n_nodes)
        # symbolic: boundary node positions of every front, children first
        adj = sparse.csr_matrix(adjacency)
        adj_pos = sparse.csr_matrix(
            (np.ones(adj.nnz), node_pos[adj.indices], adj.indptr), shape=adj.shape
        )  # row = node id, column = position of the neighbour
        fronts: list[Front] = []
        pos = 0
        for own, children in node_tree:
            start, stop = pos, pos + own.size
            pos = stop
            nbr = adj_pos[own].indices
            parts = [nbr[nbr >= stop]] + [fronts[c].boundary for c in children]
            bnd = np.unique(np.concatenate(parts))
            fronts.append(Front(start, stop, bnd[bnd >= stop], list(children)))
        self.fronts = fronts
        self.block = block
        dof_order = (block * node_order[:, None] + np.arange(block)).ravel()
        self.perm = dof_order  # permuted index i holds original unknown perm[i]
        ap = sparse.csc_matrix(a)[dof_order][:, dof_order].tocsc()
        self._factor(ap)

    def _dofs(self, node_positions: np.ndarray) -> np.ndarray:
        b = self.block
        return (b * node_positions[:, None] + np.arange(b)).ravel()

    def _factor(self, ap) -> None:
        b = self.block
        local = np.full(self.n, -1, dtype=np.int64)
        updates: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        indptr, indices, data = ap.indptr, ap.indices, ap.data
        self.nnz = 0
        for t, fr in enumerate(self.fronts):
            o0, o1 = b * fr.start, b * fr.stop
            bdofs = self._dofs(fr.boundary)
            m_own = o1 - o0
            size = m_own + bdofs.size
            local[o0:o1] = np.arange(m_own)
            local[bdofs] = np.arange(m_own, size)
            front = np.zeros((size, size))
            lo, hi = indptr[o0], indptr[o1]
            rows = indices[lo:hi]
            cols = np.repeat(np.arange(m_own), np.diff(indptr[o0 : o1 + 1]))
            keep = rows >= o0
            front[local[rows[keep]], cols[keep]] = data[lo:hi][keep]
            for c in fr.children:
                cdofs, upd = updates.pop(c)
                li = local[cdofs]
                front[np.ix_(li, li)] += upd
            l11, info = lapack.dpotrf(front[:m_own, :m_own], lower=1, clean=1, overwrite_a=0)
            if info != 0:
                raise JassyError(
                    "modes: the shifted stiffness matrix is not positive definite (a disconnected "
                    "or degenerate voxel model?)"
                )
            l21 = blas.dtrsm(1.0, l11, front[m_own:, :m_own], side=1, lower=1, trans_a=1)
            fr.l11, fr.l21 = l11, l21
            self.nnz += m_own * (m_own + 1) // 2 + l21.size
            if bdofs.size:
                upd = blas.dsyrk(-1.0, l21, beta=1.0, c=front[m_own:, m_own:], lower=1)
                upd = np.tril(upd) + np.tril(upd, -1).T
                updates[t] = (bdofs, upd)
            local[o0:o1] = -1
            local[bdofs] = -1

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """A^-1 rhs for a vector (n,) or a block (n, r)."""
        x = np.asarray(rhs, dtype=np.float64)
        one = x.ndim == 1
        y = x[self.perm].reshape(self.n, -1).copy()
        b = self.block
        bdof = [self._dofs(fr.boundary) for fr in self.fronts]
        for fr, bd in zip(self.fronts, bdof, strict=True):
            o0, o1 = b * fr.start, b * fr.stop
            yo = blas.dtrsm(1.0, fr.l11, y[o0:o1], lower=1)
            y[o0:o1] = yo
            if bd.size:
                y[bd] = blas.dgemm(-1.0, fr.l21, yo, beta=1.0, c=y[bd])
        for fr, bd in zip(reversed(self.fronts), reversed(bdof), strict=True):
            o0, o1 = b * fr.start, b * fr.stop
            yo = y[o0:o1]
            if bd.size:
                yo = blas.dgemm(-1.0, fr.l21, y[bd], beta=1.0, c=yo, trans_a=1)
            y[o0:o1] = blas.dtrsm(1.0, fr.l11, yo, lower=1, trans_a=1)
        out = np.empty_like(y)
        out[self.perm] = y
        return out[:, 0] if one else out


def _m_orthonormalise(w: np.ndarray, v: np.ndarray, mv: np.ndarray, m) -> tuple[np.ndarray, np.ndarray]:
    """Make w M-orthogonal to the columns of v (M-orthonormal; mv = M v) and M-orthonormal
    itself: two classical Gram-Schmidt passes, then normalisation through the eigenvectors of
    the Gram matrix (columns that vanish are dropped). Returns (w, M w)."""
    if v.shape[1]:
        for _ in range(2):
            w = w - v @ (mv.T @ w)
    for _ in range(2):
        mw = m @ w
        g = w.T @ mw
        g = 0.5 * (g + g.T)
        lam, q = np.linalg.eigh(g)
        keep = lam > 1e-12 * max(lam.max(), 1e-300)
        s = q[:, keep] / np.sqrt(lam[keep])
        w, mw = w @ s, mw @ s
        if np.all(np.abs(lam[keep] - 1.0) < 1e-10):
            break
    return w, mw


@dataclass
class EigenResult:
    eigenvalues: np.ndarray
    vectors: np.ndarray
    residuals: np.ndarray
    cycles: int
    solves: int


def eigsh_shift_invert(
    k_mat,
    m_mat,
    n_eig: int,
    sigma: float,
    solver=None,
    block: int | None = None,
    steps: int = 6,
    tol: float = 1e-8,
    max_cycles: int = 30,
    seed: int = 12345,
    skip: int = 0,
) -> EigenResult:
    """The ``n_eig`` eigenpairs of K x = lambda M x nearest above ``sigma`` (< all of them).

    ``solver(B)`` must return (K - sigma M)^-1 B for blocks B. Block Krylov of
    T = (K - sigma M)^-1 M from a seeded random block, Rayleigh-Ritz with M-orthonormal
    bases, restarts keeping the best Ritz vectors; stops when every wanted pair but the first
    ``skip`` (the rigid modes, whose accuracy does not matter) has
    ||K z - theta M z|| <= tol (|theta| + |sigma|) ||M z||. Vectors are M-orthonormal.
    """
    n = k_mat.shape[0]
    bs = min(block or max((n_eig + 1) // 2, 8), n)
    keep_n = min(n, n_eig + bs // 2)
    dim = min(n, keep_n + steps * bs)
    v = np.empty((n, dim))
    mv = np.empty((n, dim))
    kv = np.empty((n, dim))
    rng = np.random.default_rng(seed)
    w = rng.standard_normal((n, bs))
    mw = m_mat @ w
    nk = 0  # filled columns (the kept Ritz vectors come first)
    solves = 0
    res = np.array([np.inf])
    for cycle in range(1, max_cycles + 1):
        filled = nk
        for _ in range(steps):
            room = dim - filled
            if room <= 0:
                break
            w = solver(mw)
            solves += w.shape[1]
            w, mw = _m_orthonormalise(w, v[:, :filled], mv[:, :filled], m_mat)
            w, mw = w[:, :room], mw[:, :room]
            c = w.shape[1]
            if c == 0:
                break
            v[:, filled : filled + c] = w
            mv[:, filled : filled + c] = mw
            kv[:, filled : filled + c] = k_mat @ w
            filled += c
        a = v[:, :filled].T @ kv[:, :filled]
        a = 0.5 * (a + a.T)
        theta, y = np.linalg.eigh(a)
        want = min(n_eig, filled)
        keep = min(filled, keep_n)
        y = y[:, :keep]
        z, kz, mz = v[:, :filled] @ y, kv[:, :filled] @ y, mv[:, :filled] @ y
        r = kz[:, :want] - mz[:, :want] * theta[:want]
        res = np.linalg.norm(r, axis=0) / (
            (np.abs(theta[:want]) + abs(sigma)) * np.linalg.norm(mz[:, :want], axis=0)
        )
        if want == n_eig and np.all(res[skip:] <= tol):
            return EigenResult(theta[:want], z[:, :want], res, cycle, solves)
        v[:, :keep], mv[:, :keep], kv[:, :keep] = z, mz, kz
        nk = keep
        bad = skip + np.flatnonzero(res[skip:] > tol)
        if bad.size == 0:
            bad = np.arange(min(bs, keep))
        w, mw = z[:, bad[:bs]], mz[:, bad[:bs]]
    raise JassyError(
        f"modes: the eigensolver did not converge in {max_cycles} cycles "
        f"(worst relative residual {np.max(res[skip:]):.2g}); try fewer modes or another pitch"
    )
