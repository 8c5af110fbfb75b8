"""Mixed super-circle: per-element unknowns glued by constraints; banded KKT, linear in n.

q = (x_i, y_i, theta_i, kappa_i) for i = 0..n-1 (ndof = 4n): the start pose and curvature of
each element. Gluing constraints X_{i+1} - Phi(X_i, kappa_i) = 0 (3(n-1) rows) plus the
boundary rows (start: rows on X_0; end: rows on Phi(X_{n-1})) give the bilateral system
C v = c. M, D and K are block diagonal (4 x 4 blocks, ``bsr_matrix``); M is the kinetic energy
rho_A int |r_dot|^2 ds of each arc by Gauss-Legendre quadrature (arc.NQ points).
``kkt_factor`` orders the KKT unknowns element by element (multipliers between the blocks they
glue) so [[A, C^T], [C, 0]] is banded (half-bandwidth BAND = 4) and factors it with a banded
LU with partial pivoting (physics.rod.band, numba): O(n) time. ``kkt_band`` writes the KKT matrix
of a step straight into that band storage from the per-element blocks (no sparse matrices), and
``step`` factors it. ``advance`` re-glues the elements exactly by forward kinematics from X_0
(continuity holds to round-off after every step).

Additions to FormulationBase: RodState.lam and advance(..., lam) (geometric stiffness of
the gluing constraints in the next step, see physics.rod.model); ``constraint_hessian``,
``potential``, ``dynamics``, ``point_hessian``, ``point_jacobians``, ``angle_jacobians``,
``project``, ``kkt_factor`` and ``kkt_band`` are extra.
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from jassy.errors import JassyError
from jassy.jit import drop_stale_cache, specialise
from physics.rod import arc, band
from physics.rod.band import band_fill, band_lu, band_solve, band_solve_vec
from physics.rod.model import BC_ROWS, Arcs, Dynamics, FormulationBase, RodModel, RodState, sparse_from_blocks

drop_stale_cache(__file__, [arc, band])  # its cache holds copies of their kernels

BAND = 4
"""Half-bandwidth of the KKT matrix in MixedRod.perm order: a gluing multiplier sits between the
element it leaves and the one it enters; its row on the element it leaves is d Phi_r/d(x, y, theta,
kappa), where d Phi_x/dy = d Phi_y/dx = d Phi_theta/d(x, y) = 0, so it reaches at most 4 positions."""


class Elements(NamedTuple):
    """The arc elements' angles, curvatures, lengths and their rates."""

    theta: np.ndarray  #: tangent angle at each element's start (rad)
    kappa: np.ndarray  #: curvature (1/m)
    seg: np.ndarray  #: length (m)
    thd: np.ndarray  #: d theta / dt (rad/s)
    kd: np.ndarray  #: d kappa / dt (1/(m s))


class Quadrature(NamedTuple):
    """Gauss-Legendre points and weights on [0, 1]."""

    x: np.ndarray
    w: np.ndarray


class ElementTerms(NamedTuple):
    """Per-element outputs of :func:`_element_terms`."""

    mass: np.ndarray  #: (n, 4, 4) mass blocks on (x, y, theta, kappa) (kg, kg m, ...)
    gyro: np.ndarray  #: (n, 4) gyroscopic forces
    grad: np.ndarray  #: (n, 4) gravity gradient
    hess: np.ndarray  #: (n, 2, 2) gravity Hessian on (theta, kappa)
    hess_psd: np.ndarray  #: (n, 2, 2) its positive semi-definite part


#: The Gauss-Legendre rule of the element integrals.
GAUSS = Quadrature(arc.GAUSS_X, arc.GAUSS_W)


@numba.njit(cache=True)
def _element_terms(el, rho_a, g, rule, terms):
    """Per element: mass block, gyroscopic force, gravity gradient/Hessian on (theta, kappa)
    into ``terms`` (an ElementTerms); el: the Elements, rule: the Quadrature, rho_a: mass per
    length (kg/m), g: gravity (m/s^2). Returns the gravity potential minus rho_A g sum l y_i.
    With c = (1, i, dr/dtheta, dr/dkappa) (complex), M_ab = rho_A int Re(conj(c_a) c_b) ds;
    the (x, y) block is rho_A l I."""
    theta, kappa, seg, thd, kd = el
    gx, gw = rule
    mass, gyro, grad, hess, hess_psd = terms
    v_sum = 0.0
    for i in range(theta.size):
        rot = np.exp(1j * theta[i])
        li = seg[i]
        m02 = m03 = m12 = m13 = m22 = m23 = m33 = 0.0
        g0 = g1 = g2 = g3 = 0.0
        r2 = r3 = 0.0
        h00 = h01 = h11 = p00 = p01 = p11 = 0.0
        for k in range(gx.size):
            tau = li * gx[k]
            w = li * gw[k]
            e0, e1, e2 = arc.unit_moments(kappa[i] * tau)
            f0 = tau * e0
            f1 = tau * tau * e1
            f2 = tau * tau * tau * e2
            c2 = 1j * rot * f0
            c3 = 1j * rot * f1
            acc = -rot * (thd[i] * thd[i] * f0 + 2.0 * thd[i] * kd[i] * f1 + kd[i] * kd[i] * f2)
            m02 += w * c2.real
            m12 += w * c2.imag
            m03 += w * c3.real
            m13 += w * c3.imag
            m22 += w * (c2.real * c2.real + c2.imag * c2.imag)
            m23 += w * (c2.real * c3.real + c2.imag * c3.imag)
            m33 += w * (c3.real * c3.real + c3.imag * c3.imag)
            g0 += w * acc.real
            g1 += w * acc.imag
            g2 += w * (c2.real * acc.real + c2.imag * acc.imag)
            g3 += w * (c3.real * acc.real + c3.imag * acc.imag)
            wg = rho_a * g * w * (li - tau)
            tangent = rot * (1.0 + 1j * kappa[i] * tau * e0)  # e^{i phi}, e^{iz} = 1 + i z E_0(z)
            cphi, sphi = tangent.real, tangent.imag
            v_sum += wg * sphi
            r2 += wg * cphi
            r3 += wg * tau * cphi
            h = -wg * sphi
            hp = -wg * min(sphi, 0.0)
            h00 += h
            h01 += h * tau
            h11 += h * tau * tau
            p00 += hp
            p01 += hp * tau
            p11 += hp * tau * tau
        mass[i, 0, 0] = mass[i, 1, 1] = rho_a * li
        mass[i, 0, 1] = mass[i, 1, 0] = 0.0
        mass[i, 0, 2] = mass[i, 2, 0] = rho_a * m02
        mass[i, 0, 3] = mass[i, 3, 0] = rho_a * m03
        mass[i, 1, 2] = mass[i, 2, 1] = rho_a * m12
        mass[i, 1, 3] = mass[i, 3, 1] = rho_a * m13
        mass[i, 2, 2] = rho_a * m22
        mass[i, 2, 3] = mass[i, 3, 2] = rho_a * m23
        mass[i, 3, 3] = rho_a * m33
        gyro[i, 0] = -rho_a * g0
        gyro[i, 1] = -rho_a * g1
        gyro[i, 2] = -rho_a * g2
        gyro[i, 3] = -rho_a * g3
        grad[i, 0] = 0.0
        grad[i, 1] = rho_a * g * li
        grad[i, 2] = r2
        grad[i, 3] = r3
        hess[i, 0, 0], hess[i, 0, 1], hess[i, 1, 0], hess[i, 1, 1] = h00, h01, h01, h11
        hess_psd[i, 0, 0], hess_psd[i, 0, 1], hess_psd[i, 1, 0], hess_psd[i, 1, 1] = p00, p01, p01, p11
    return v_sum


@numba.njit(cache=True)
def _scatter_kkt(A, jac, start_rows, end_rows, K, kv):
    """[[A, C^T], [C, 0]] into band storage K (physics.rod.band) in MixedRod.perm order, from the
    element blocks A (n, 4, 4) and end-pose Jacobians jac (n, 3, 4) (gluing rows -jac on element i,
    identity on the start of element i + 1); the structural zeros of jac (see BAND) are skipped."""
    n, ns = A.shape[0], start_rows.size
    for i in range(n):
        base = ns + 7 * i
        for a in range(4):
            for b in range(4):
                K[base + b, kv + a - b] = A[i, a, b]
    for r in range(ns):
        d = ns + start_rows[r]
        K[d, kv + r - d] = 1.0
        K[r, kv + d - r] = 1.0
    for i in range(n):
        last = i == n - 1
        for r in range(end_rows.size if last else 3):
            m = ns + 7 * i + 4 + r
            row = end_rows[r] if last else r
            for a in range(4):
                if a < 2 and a != row:
                    continue
                d = ns + 7 * i + a
                val = jac[i, row, a] if last else -jac[i, row, a]
                K[d, kv + m - d] = val
                K[m, kv + d - m] = val
            if not last:
                d = ns + 7 * (i + 1) + r
                K[d, kv + m - d] = 1.0
                K[m, kv + d - m] = 1.0


@numba.njit(cache=True)
def _lam_blocks(theta, kappa, seg, lam_xy, psd, out):
    """out[i] = lam_x d2x/dq2 + lam_y d2y/dq2 of each element's end point on (theta, kappa)
    (arc.position_hessian at s = l); psd: the positive part of each 2 x 2 block (its negative
    eigenvalue dropped, in closed form)."""
    for i in range(theta.size):
        e0, e1, e2 = arc.unit_moments(kappa[i] * seg[i])
        rot = -np.exp(1j * theta[i])
        li = seg[i]
        h00 = rot * (li * e0)
        h01 = rot * (li * li * e1)
        h11 = rot * (li * li * li * e2)
        lx, ly = lam_xy[i, 0], lam_xy[i, 1]
        a = lx * h00.real + ly * h00.imag
        b = lx * h01.real + ly * h01.imag
        d = lx * h11.real + ly * h11.imag
        if psd:
            m = 0.5 * (a + d)
            rad = np.hypot(0.5 * (a - d), b)
            hi, lo = m + rad, m - rad
            if hi <= 0.0:
                a = b = d = 0.0
            elif lo < 0.0:  # hi u u^T = hi (H - lo I) / (hi - lo)
                f = hi / (hi - lo)
                a, b, d = f * (a - lo), f * b, f * (d - lo)
        out[i, 0, 0], out[i, 0, 1], out[i, 1, 0], out[i, 1, 1] = a, b, b, d


class BandedKKT:
    """LU of [[A, C^T], [C, 0]] in an element-by-element order (banded, partial pivoting): from
    sparse A, C, or (``from_band``) from band storage already in that order."""

    def __init__(self, A, C, perm: np.ndarray):
        ndof = A.shape[0]
        a, c = A.tocoo(), C.tocoo()
        vals = np.concatenate((a.data, c.data, c.data))
        nz = vals != 0.0
        rows = perm[np.concatenate((a.row, c.row + ndof, c.col))[nz]]
        cols = perm[np.concatenate((a.col, c.col, c.row + ndof))[nz]]
        kl = int(max(0, np.max(rows - cols, initial=0)))
        ku = int(max(0, np.max(cols - rows, initial=0)))
        ab = np.zeros((perm.size, 2 * kl + ku + 1))
        band_fill(rows, cols, vals[nz], kl + ku, ab)
        self._factor(ab, kl, ku, perm, ndof)

    @classmethod
    def from_band(cls, ab: np.ndarray, kl: int, ku: int, perm: np.ndarray, ndof: int) -> BandedKKT:
        """Factor band storage ab (overwritten) of the KKT matrix in ``perm`` order."""
        self = cls.__new__(cls)
        self._factor(ab, kl, ku, perm, ndof)
        return self

    def _factor(self, ab, kl, ku, perm, ndof):
        self.lu, self.kl, self.ku, self.perm, self.ndof, self.size = ab, kl, ku, perm, ndof, perm.size
        self.piv = np.empty(self.size, dtype=np.int64)
        info = band_lu(self.lu, kl, ku, self.piv)
        if info != 0:
            raise JassyError(
                f"KKT system: singular (pivot {info}); check the boundary conditions and constraints"
            )

    def solve(self, b: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(v, lam) with A v + C^T lam = b, C v = c; b (ndof,) or (ndof, k)."""
        rhs = np.concatenate((np.asarray(b, dtype=np.float64), np.asarray(c, dtype=np.float64)))
        x = np.empty(rhs.shape)
        x[self.perm] = rhs
        if rhs.ndim == 1:
            band_solve_vec(self.lu, self.kl, self.ku, self.piv, x, 0, self.size)
        else:
            band_solve(self.lu, self.kl, self.ku, self.piv, x, 0, self.size)
        x = x[self.perm]
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
        self._element_run = None  # _element_terms' compiled entry point, found at the first call
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
        # fresh contiguous float64 copies and float scalars: the same types at every call, so
        # the compiled entry point is looked up once (numba's dispatcher types records slowly)
        rows = (th, k, self.l, vv[2::4], vv[3::4])
        args = (
            Elements(*(np.array(a, dtype=np.float64) for a in rows)),
            float(m.rho_A),
            float(m.gravity),
            GAUSS,
            ElementTerms(mass, gyro, grad, hess, hess_psd),
        )
        if self._element_run is None:
            self._element_run = specialise(_element_terms, *args)
        vg = self._element_run(*args)
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

    def _gluing(self, q):
        """(end-pose Jacobians jac (n, 3, 4), constraint values g (m,))."""
        x, y, th, k = self._split(q)
        jac = arc.end_pose_jacobian(th, k, self.l)
        ex, ey, et = arc.end_pose(x, y, th, k, self.l)
        ends = np.stack((ex, ey, et), axis=1)
        starts = np.stack((x, y, th), axis=1)
        g = np.concatenate((
            starts[0, self.start_rows] - np.asarray(self.model.start)[self.start_rows],
            (starts[1:] - ends[:-1]).ravel(),
            ends[-1, self.end_rows] - self.end_target[self.end_rows],
        ))  # fmt: skip
        return jac, g

    def constraints(self, q):
        """(C sparse (m, 4n), g (m,)): boundary rows, gluing rows, end rows."""
        jac, g = self._gluing(q)
        return self._c_matrix(jac), g

    def _c_matrix(self, jac: np.ndarray):
        n, ns, ne = self.n, self.start_rows.size, self.end_rows.size
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
        return sp.csr_matrix((vals, (rows, cols)), shape=(self.n_constraints, self.ndof))

    def _lam_hessian(self, q, lam: np.ndarray, psd: bool) -> np.ndarray:
        """(n, 2, 2) blocks on (theta_i, kappa_i) of sum_k lam_k d2 g_k / dq2."""
        _, _, th, k = self._split(q)
        n, ns = self.n, self.start_rows.size
        lam_xy = np.zeros((n, 2))
        lam_xy[:-1] = -lam[ns : ns + 3 * (n - 1)].reshape(n - 1, 3)[:, :2]
        lam_end = np.zeros(3)
        lam_end[self.end_rows] = lam[ns + 3 * (n - 1) :]
        lam_xy[-1] += lam_end[:2]
        out = np.empty((n, 2, 2))
        _lam_blocks(th, k, self.l, lam_xy, psd, out)
        return out

    def constraint_hessian(self, q, lam: np.ndarray, psd: bool = False):
        """sum_k lam_k d2 g_k / dq2 (sparse, blocks on (theta_i, kappa_i)); psd: keep only the
        positive part of each 2 x 2 block."""
        blocks = np.zeros((self.n, 4, 4))
        blocks[:, 2:, 2:] = self._lam_hessian(q, lam, psd)
        return sparse_from_blocks(blocks)

    def _step_terms(self, state: RodState, h: float):
        """(A blocks (n, 4, 4), b (ndof,), jac (n, 3, 4), g (m,)) of one linearly implicit step (the
        terms of FormulationBase.linear_system, per element)."""
        self.check_step(h)
        v = np.asarray(state.v, dtype=np.float64)
        if v.shape != (self.ndof,):
            raise JassyError(f"v: expected {self.ndof} velocities, got shape {v.shape}")
        m = self.model
        A, gyro, grad, _, hess_psd, _ = self._terms(state.q, v)
        b = np.einsum("nab,nb->na", A, v.reshape(-1, 4)) + h * (gyro - grad)
        A[:, 3, 3] += (h * m.damping + h * h * m.EI) * self.l
        A[:, 2:, 2:] += (h * h) * hess_psd
        jac, g = self._gluing(state.q)
        if state.lam is not None and state.lam.shape == g.shape:
            A[:, 2:, 2:] += h * self._lam_hessian(state.q, state.lam, psd=True)
        return A, b.ravel(), jac, g

    def linear_system(self, state: RodState, h: float) -> tuple:
        """(A, b, C, c) as FormulationBase.linear_system, assembled per element."""
        A, b, jac, g = self._step_terms(state, h)
        return sparse_from_blocks(A), b, self._c_matrix(jac), -g / h

    def kkt_band(self, state: RodState, h: float, out: np.ndarray | None = None):
        """(K, rhs): the KKT matrix of ``linear_system(state, h)`` in band storage (physics.rod.band;
        ``perm`` order, kl = ku = BAND) and rhs = (b, c) in natural order, without sparse matrices.
        ``out``: a zeroed (ndof + m, 3 BAND + 1) array to fill."""
        A, b, jac, g = self._step_terms(state, h)
        K = np.zeros((self.perm.size, 3 * BAND + 1)) if out is None else out
        _scatter_kkt(A, jac, self.start_rows, self.end_rows, K, 2 * BAND)
        return K, np.concatenate((b, -g / h))

    def step(self, state: RodState, h: float) -> RodState:
        """One contact-free step (band KKT assembled and factored directly)."""
        K, rhs = self.kkt_band(state, h)
        v, lam = BandedKKT.from_band(K, BAND, BAND, self.perm, self.ndof).solve(
            rhs[: self.ndof], rhs[self.ndof :]
        )
        return self.advance(state, v, h, lam)

    def angle_jacobians(self, q, elements: np.ndarray, s: np.ndarray):
        """(cols (m, 4), d phi / dq (m, 4)) of the tangent angle phi = theta_i + kappa_i s at arc
        length s (m) of each element (the cross-section's rotation)."""
        e = np.asarray(elements, dtype=np.int64)
        d = np.zeros((e.size, 4))
        d[:, 2] = 1.0
        d[:, 3] = s
        return 4 * e[:, None] + np.arange(4), d

    def point_jacobians(self, q, elements: np.ndarray, s: np.ndarray):
        """Vectorised point_jacobian: (points (m, 2), cols (m, 4), J (m, 2, 4))."""
        x, y, th, k = self._split(q)
        e = np.asarray(elements, dtype=np.int64)
        s = np.asarray(s, dtype=np.float64)
        le = self.model.length / self.n
        if np.any((e < 0) | (e >= self.n)) or not np.all((s >= -1e-12 * le) & (s <= le * (1 + 1e-12))):
            raise JassyError(f"elements, s: expected elements in [0, {self.n - 1}] and s in [0, {le:g}] m")
        f = arc.moments(k[e], s)
        rot = np.exp(1j * th[e])
        p = x[e] + 1j * y[e] + rot * f[0]
        d0, d1 = 1j * rot * f[0], 1j * rot * f[1]
        J = np.zeros((e.size, 2, 4))
        J[:, 0, 0] = J[:, 1, 1] = 1.0
        J[:, 0, 2], J[:, 1, 2], J[:, 0, 3], J[:, 1, 3] = d0.real, d0.imag, d1.real, d1.imag
        return np.column_stack((p.real, p.imag)), 4 * e[:, None] + np.arange(4), J

    def kkt_factor(self, A, C, method: str = "banded"):
        """Factor [[A, C^T], [C, 0]] once; ``.solve(b, c) -> (v, lam)`` (banded LU or "splu")."""
        if method == "splu" or C.shape[0] != self.n_constraints:
            return SparseKKT(sp.csr_matrix(A), sp.csr_matrix(C))
        if method != "banded":
            raise JassyError(f"method: expected 'banded' or 'splu', got {method!r}")
        return BandedKKT(A, C, self.perm)
