"""Mixed super-circle: per-element unknowns glued by constraints; banded KKT, linear in n.

q = (x_i, y_i, theta_i, kappa_i) for i = 0..n-1 (ndof = 4n): the start pose and curvature of
each element. Gluing constraints X_{i+1} - Phi(X_i, kappa_i) = 0 (3(n-1) rows) plus the
boundary rows (start: rows on X_0; end: rows on Phi(X_{n-1})) give the bilateral system
C v = c. M, D and K are block diagonal (4 x 4 blocks, ``bsr_matrix``); M is the kinetic energy
rho_A int |r_dot|^2 ds of each arc by Gauss-Legendre quadrature (arc.NQ points).
``kkt_factor`` orders the KKT unknowns element by element (multipliers between the blocks they
glue) so [[A, C^T], [C, 0]] is banded (half-bandwidth <= 7) and factors it with a banded
LU with partial pivoting (numba, LAPACK gbtrf storage): O(n) time. ``advance`` re-glues the
elements exactly by forward kinematics from X_0 (continuity holds to round-off after every step).

Additions to the R1/R2 contract: RodState.lam and advance(..., lam) (geometric stiffness of
the gluing constraints in the next step, see physics.rod.model); ``constraint_hessian``,
``potential``, ``dynamics``, ``point_hessian``, ``project`` and ``kkt_factor`` are extra.
"""

from __future__ import annotations

import numba
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from jassy.errors import JassyError
from physics.rod import arc
from physics.rod.model import BC_ROWS, Arcs, Dynamics, FormulationBase, RodModel, RodState, sparse_from_blocks


@numba.njit(cache=True)
def _element_terms(theta, kappa, seg, thd, kd, rho_a, g, gx, gw, mass, gyro, grad, hess, hess_psd):
    """Per element: mass block, gyroscopic force, gravity gradient/Hessian on (theta, kappa).
    Returns the gravity potential minus rho_A g sum l y_i."""
    v_sum = 0.0
    for i in range(theta.size):
        rot = np.exp(1j * theta[i])
        li = seg[i]
        for a in range(4):
            gyro[i, a] = 0.0
            grad[i, a] = 0.0
            for b in range(4):
                mass[i, a, b] = 0.0
        for a in range(2):
            for b in range(2):
                hess[i, a, b] = 0.0
                hess_psd[i, a, b] = 0.0
        grad[i, 1] = rho_a * g * li
        for k in range(gx.size):
            tau = li * gx[k]
            w = li * gw[k]
            e0, e1, e2 = arc.unit_moments(kappa[i] * tau)
            f0 = tau * e0
            f1 = tau * tau * e1
            f2 = tau * tau * tau * e2
            c = (1.0 + 0j, 1j, 1j * rot * f0, 1j * rot * f1)
            acc = -rot * (thd[i] * thd[i] * f0 + 2.0 * thd[i] * kd[i] * f1 + kd[i] * kd[i] * f2)
            for a in range(4):
                ca = c[a].conjugate()
                gyro[i, a] -= rho_a * w * (ca * acc).real
                for b in range(4):
                    mass[i, a, b] += rho_a * w * (ca * c[b]).real
            phi = theta[i] + kappa[i] * tau
            wg = rho_a * g * w * (li - tau)
            cphi, sphi = np.cos(phi), np.sin(phi)
            v_sum += wg * sphi
            grad[i, 2] += wg * cphi
            grad[i, 3] += wg * tau * cphi
            h = -wg * sphi
            hp = -wg * min(sphi, 0.0)
            vv = (1.0, tau, tau * tau)
            hess[i, 0, 0] += h * vv[0]
            hess[i, 0, 1] += h * vv[1]
            hess[i, 1, 1] += h * vv[2]
            hess_psd[i, 0, 0] += hp * vv[0]
            hess_psd[i, 0, 1] += hp * vv[1]
            hess_psd[i, 1, 1] += hp * vv[2]
        hess[i, 1, 0] = hess[i, 0, 1]
        hess_psd[i, 1, 0] = hess_psd[i, 0, 1]
    return v_sum


@numba.njit(cache=True)
def _bandwidths(rows, cols, perm):
    kl = 0
    ku = 0
    for k in range(rows.size):
        d = perm[rows[k]] - perm[cols[k]]
        kl = max(kl, d)
        ku = max(ku, -d)
    return kl, ku


@numba.njit(cache=True)
def _scatter(rows, cols, vals, perm, kv, ab):
    """Add entries (rows, cols, vals), renumbered by perm, into band storage."""
    for k in range(rows.size):
        i = perm[rows[k]]
        j = perm[cols[k]]
        ab[kv + i - j, j] += vals[k]


@numba.njit(cache=True)
def _band_lu(ab, kl, ku, piv):
    """In-place LU with partial pivoting of a band matrix in LAPACK gbtrf storage
    (row kl + ku + i - j holds A[i, j]; kl extra rows for fill-in). Returns 0 or the
    1-based index of a zero pivot."""
    n = ab.shape[1]
    kv = kl + ku
    ju = 0
    for j in range(n):
        km = min(kl, n - 1 - j)
        jp = 0
        best = abs(ab[kv, j])
        for i in range(1, km + 1):
            if abs(ab[kv + i, j]) > best:
                best = abs(ab[kv + i, j])
                jp = i
        piv[j] = j + jp
        if best == 0.0:
            return j + 1
        ju = max(ju, min(j + ku + jp, n - 1))
        if jp != 0:
            for c in range(j, ju + 1):
                a = ab[kv + j - c, c]
                ab[kv + j - c, c] = ab[kv + j + jp - c, c]
                ab[kv + j + jp - c, c] = a
        inv = 1.0 / ab[kv, j]
        for i in range(1, km + 1):
            ab[kv + i, j] *= inv
        for c in range(j + 1, ju + 1):
            f = ab[kv + j - c, c]
            if f != 0.0:
                for i in range(1, km + 1):
                    ab[kv + j + i - c, c] -= ab[kv + i, j] * f
    return 0


@numba.njit(cache=True)
def _band_solve(lu, kl, ku, piv, b):
    """Solve in place with the factors of _band_lu; b has shape (n, k)."""
    n = lu.shape[1]
    kv = kl + ku
    for r in range(b.shape[1]):
        for j in range(n):
            p = piv[j]
            if p != j:
                t = b[j, r]
                b[j, r] = b[p, r]
                b[p, r] = t
            for i in range(1, min(kl, n - 1 - j) + 1):
                b[j + i, r] -= lu[kv + i, j] * b[j, r]
        for j in range(n - 1, -1, -1):
            b[j, r] /= lu[kv, j]
            for i in range(1, min(j, kv) + 1):
                b[j - i, r] -= lu[kv - i, j] * b[j, r]


class BandedKKT:
    """LU of [[A, C^T], [C, 0]] in an element-by-element order (banded, partial pivoting)."""

    def __init__(self, A, C, perm: np.ndarray):
        ndof = A.shape[0]
        a, c = A.tocoo(), C.tocoo()
        rows = np.concatenate((a.row, c.row + ndof, c.col))
        cols = np.concatenate((a.col, c.col, c.row + ndof))
        vals = np.concatenate((a.data, c.data, c.data))
        self.kl, self.ku = _bandwidths(rows, cols, perm)
        self.perm, self.ndof, self.size = perm, ndof, perm.size
        self.lu = np.zeros((2 * self.kl + self.ku + 1, self.size))
        _scatter(rows, cols, vals, perm, self.kl + self.ku, self.lu)
        self.piv = np.empty(self.size, dtype=np.int64)
        info = _band_lu(self.lu, self.kl, self.ku, self.piv)
        if info != 0:
            raise JassyError(
                f"KKT system: singular (pivot {info}); check the boundary conditions and constraints"
            )

    def solve(self, b: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(v, lam) with A v + C^T lam = b, C v = c; b (ndof,) or (ndof, k)."""
        rhs = np.concatenate((np.asarray(b, dtype=np.float64), np.asarray(c, dtype=np.float64)))
        vec = rhs.ndim == 1
        x = np.empty((self.size, 1 if vec else rhs.shape[1]))
        x[self.perm] = rhs.reshape(self.size, -1)
        _band_solve(self.lu, self.kl, self.ku, self.piv, x)
        x = x[self.perm]
        x = x[:, 0] if vec else x
        return x[: self.ndof], x[self.ndof :]


class SparseKKT:
    """SuperLU (scipy splu) of [[A, C^T], [C, 0]]: the general reference for BandedKKT."""

    def __init__(self, A, C):
        self.ndof = A.shape[0]
        kkt = sp.bmat([[A, C.T], [C, None]], format="csc")
        self.lu = spla.splu(kkt)

    def solve(self, b: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        x = self.lu.solve(np.concatenate((np.asarray(b, dtype=np.float64), np.asarray(c, dtype=np.float64))))
        return x[: self.ndof], x[self.ndof :]


class MixedRod(FormulationBase):
    """Mixed super-circle formulation of a RodModel (see module docstring)."""

    def __init__(self, model: RodModel):
        if not isinstance(model, RodModel):
            raise JassyError(f"model: expected a RodModel, got {type(model).__name__}")
        self.model = model
        self.n = model.n
        self.ndof = 4 * model.n
        self.l = model.l
        self.kappa0 = model.kappa0
        self.kappa_index = slice(3, None, 4)
        self.start_rows = np.array(BC_ROWS[model.start_bc], dtype=np.int64)
        self.end_rows = np.array(BC_ROWS[model.end_bc], dtype=np.int64)
        self.end_target = model.end_target
        ns, ne, n = self.start_rows.size, self.end_rows.size, self.n
        self.n_constraints = ns + 3 * (n - 1) + ne
        perm_q = ns + 7 * np.arange(n)[:, None] + np.arange(4)[None, :]
        perm_c = ns + 7 * np.arange(n - 1)[:, None] + 4 + np.arange(3)[None, :]
        perm_e = ns + 7 * (n - 1) + 4 + np.arange(ne)
        self.perm = np.concatenate((perm_q.ravel(), np.arange(ns), perm_c.ravel(), perm_e)).astype(np.int64)
        self._bend = sparse_from_blocks(self._diag_blocks(model.EI * self.l))
        self._damp = sparse_from_blocks(self._diag_blocks(model.damping * self.l))

    def _diag_blocks(self, kappa_diag: np.ndarray) -> np.ndarray:
        blocks = np.zeros((self.n, 4, 4))
        blocks[:, 3, 3] = kappa_diag
        return blocks

    def _split(self, q: np.ndarray):
        q = np.asarray(q, dtype=np.float64)
        if q.shape != (self.ndof,):
            raise JassyError(f"q: expected {self.ndof} values (4 per element), got shape {q.shape}")
        return q[0::4], q[1::4], q[2::4], q[3::4]

    def initial_state(self, kappa=None) -> RodState:
        """Rod at ``model.start`` with curvatures ``kappa`` (default: rest curvature), at rest."""
        kappa = (
            self.kappa0 if kappa is None else np.broadcast_to(np.asarray(kappa, dtype=np.float64), (self.n,))
        )
        r, th = arc.forward_kinematics(*self.model.start, kappa, self.l)
        q = np.stack((r[:-1].real, r[:-1].imag, th[:-1], kappa), axis=1).ravel()
        return RodState(q, np.zeros(self.ndof))

    def arcs(self, q) -> Arcs:
        x, y, th, k = self._split(q)
        return Arcs(x.copy(), y.copy(), th.copy(), k.copy(), self.l.copy())

    def project(self, q: np.ndarray) -> np.ndarray:
        """Re-glue: every element starts where the previous one ends (forward kinematics)."""
        x, y, th, k = self._split(q)
        r, t = arc.forward_kinematics(x[0], y[0], th[0], k, self.l)
        return np.stack((r[:-1].real, r[:-1].imag, t[:-1], k), axis=1).ravel()

    def point_jacobian(self, q, element: int, s: float):
        """(point (2,), cols (4,), J (2, 4)) at arc length s (m) of ``element``."""
        self.check_point(element, s)
        x, y, th, k = self._split(q)
        f = arc.moments(k[element], s)
        rot = np.exp(1j * th[element])
        p = complex(x[element], y[element]) + rot * f[0]
        d = 1j * rot * f[:2]
        J = np.array([[1.0, 0.0, d[0].real, d[1].real], [0.0, 1.0, d[0].imag, d[1].imag]])
        return np.array([p.real, p.imag]), 4 * element + np.arange(4), J

    def point_hessian(self, q, element: int, s: float):
        """(cols (2,), H (2, 2, 2)): d2 x / dq2 and d2 y / dq2 on (theta, kappa) of ``element``."""
        self.check_point(element, s)
        _, _, th, k = self._split(q)
        h = arc.position_hessian(th[element], k[element], s)
        return 4 * element + np.array([2, 3]), np.stack((h.real, h.imag))

    def _terms(self, q, v):
        x, y, th, k = self._split(q)
        vv = np.zeros(self.ndof) if v is None else np.asarray(v, dtype=np.float64)
        n, m = self.n, self.model
        mass, gyro, grad = np.empty((n, 4, 4)), np.empty((n, 4)), np.empty((n, 4))
        hess, hess_psd = np.empty((n, 2, 2)), np.empty((n, 2, 2))
        vg = _element_terms(th, k, self.l, vv[2::4], vv[3::4], m.rho_A, m.gravity, arc.GAUSS_X, arc.GAUSS_W,
                            mass, gyro, grad, hess, hess_psd)  # fmt: skip
        dk = k - self.kappa0
        grad[:, 3] += m.EI * self.l * dk
        V = vg + m.rho_A * m.gravity * float(self.l @ y) + 0.5 * m.EI * float(self.l @ (dk * dk))
        return mass, gyro, grad, hess, hess_psd, V

    def _stiffness(self, hess: np.ndarray):
        blocks = np.zeros((self.n, 4, 4))
        blocks[:, 2:, 2:] = hess
        return sparse_from_blocks(blocks) + self._bend

    def dynamics(self, q, v) -> Dynamics:
        mass, gyro, grad, _, hess_psd, _ = self._terms(q, v)
        return Dynamics(
            sparse_from_blocks(mass), self._damp, self._stiffness(hess_psd), grad.ravel(), gyro.ravel()
        )

    def potential(self, q):
        """(V J, grad V, exact Hessian (sparse)) of bending + gravity."""
        _, _, grad, hess, _, V = self._terms(q, None)
        return V, grad.ravel(), self._stiffness(hess)

    def constraints(self, q):
        """(C sparse (m, 4n), g (m,)): boundary rows, gluing rows, end rows."""
        x, y, th, k = self._split(q)
        n, ns, ne = self.n, self.start_rows.size, self.end_rows.size
        jac = arc.end_pose_jacobian(th, k, self.l)
        ex, ey, et = arc.end_pose(x, y, th, k, self.l)
        ends = np.stack((ex, ey, et), axis=1)
        starts = np.stack((x, y, th), axis=1)
        rc = ns + 3 * np.arange(n - 1)[:, None] + np.arange(3)[None, :]
        re = ns + 3 * (n - 1) + np.arange(ne)
        rows = np.concatenate((
            np.arange(ns), np.repeat(rc.ravel(), 4), rc.ravel(), np.repeat(re, 4)))  # fmt: skip
        cols = np.concatenate((
            self.start_rows,
            np.repeat(4 * np.arange(n - 1), 12) + np.tile(np.arange(4), 3 * (n - 1)),
            (4 * np.arange(1, n)[:, None] + np.arange(3)[None, :]).ravel(),
            np.tile(4 * (n - 1) + np.arange(4), ne),
        ))  # fmt: skip
        vals = np.concatenate(
            (np.ones(ns), -jac[:-1].ravel(), np.ones(3 * (n - 1)), jac[-1][self.end_rows].ravel())
        )
        C = sp.csr_matrix((vals, (rows, cols)), shape=(self.n_constraints, self.ndof))
        g = np.concatenate((
            starts[0, self.start_rows] - np.asarray(self.model.start)[self.start_rows],
            (starts[1:] - ends[:-1]).ravel(),
            ends[-1, self.end_rows] - self.end_target[self.end_rows],
        ))  # fmt: skip
        return C, g

    def constraint_hessian(self, q, lam: np.ndarray, psd: bool = False):
        """sum_k lam_k d2 g_k / dq2 (sparse, blocks on (theta_i, kappa_i)); psd: keep only the
        positive part of each 2 x 2 block."""
        _, _, th, k = self._split(q)
        n, ns = self.n, self.start_rows.size
        h = arc.position_hessian(th, k, self.l)
        lam_xy = np.zeros((n, 2))
        lam_xy[:-1] = -lam[ns : ns + 3 * (n - 1)].reshape(n - 1, 3)[:, :2]
        lam_end = np.zeros(3)
        lam_end[self.end_rows] = lam[ns + 3 * (n - 1) :]
        lam_xy[-1] += lam_end[:2]
        blocks = np.zeros((n, 4, 4))
        hb = lam_xy[:, 0, None, None] * h.real + lam_xy[:, 1, None, None] * h.imag
        if psd:
            w, U = np.linalg.eigh(hb)
            hb = np.einsum("nij,nj,nkj->nik", U, np.maximum(w, 0.0), U)
        blocks[:, 2:, 2:] = hb
        return sparse_from_blocks(blocks)

    def kkt_factor(self, A, C, method: str = "banded"):
        """Factor [[A, C^T], [C, 0]] once; ``.solve(b, c) -> (v, lam)`` (banded LU or "splu")."""
        if method == "splu" or C.shape[0] != self.n_constraints:
            return SparseKKT(sp.csr_matrix(A), sp.csr_matrix(C))
        if method != "banded":
            raise JassyError(f"method: expected 'banded' or 'splu', got {method!r}")
        return BandedKKT(A, C, self.perm)
