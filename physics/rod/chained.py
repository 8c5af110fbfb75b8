"""Chained super-circle: reduced coordinates q = (x0, y0, theta0, kappa_0..kappa_{n-1}).

Positions follow by forward kinematics (arc.forward_kinematics); the Jacobian of the point at
arc length sigma in element m is, in complex form (x = Re, y = Im),
dr/dx0 = 1, dr/dy0 = i, dr/dtheta0 = i (r - r_0),
dr/dkappa_j = i (l_j r + e^{i theta_j} F1(kappa_j, l_j) - l_j r_{j+1}) for j < m,
dr/dkappa_m = i e^{i theta_m} F1(kappa_m, sigma - s_m), 0 for j > m.
M = rho_A int J^T J ds (dense (n+3)^2, Gauss-Legendre, arc.NQ points per element); gravity
V_g = rho_A g (L y0 + int (L - s) sin theta ds) with gradient rho_A g int (L - s) lambda_j cos theta
and Hessian -rho_A g int (L - s) lambda_a lambda_b sin theta (lambda_j = d theta / d q_j).
Boundary conditions are rows of C: identity rows at the start, tip-point Jacobian rows at the
end. ``kkt_factor`` is a dense LU (O(n^3)). Extra methods beyond FormulationBase:
``potential``, ``dynamics``, ``constraint_hessian``, ``point_hessian``, ``project``, ``kkt_factor``.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from jassy.errors import JassyError
from physics.rod import arc
from physics.rod.model import BC_ROWS, Arcs, Dynamics, FormulationBase, RodModel, RodState


class DenseKKT:
    """Dense LU of [[A, C^T], [C, 0]]."""

    def __init__(self, A, C):
        A = A.toarray() if sp.issparse(A) else np.asarray(A)
        C = C.toarray() if sp.issparse(C) else np.asarray(C)
        self.ndof = A.shape[0]
        kkt = np.block([[A, C.T], [C, np.zeros((C.shape[0], C.shape[0]))]])
        self.lu = sla.lu_factor(kkt, check_finite=False)

    def solve(self, b: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(v, lam) with A v + C^T lam = b, C v = c; b (ndof,) or (ndof, k)."""
        x = sla.lu_solve(
            self.lu, np.concatenate((np.asarray(b, float), np.asarray(c, float))), check_finite=False
        )
        return x[: self.ndof], x[self.ndof :]


class ChainedRod(FormulationBase):
    """Chained super-circle formulation of a RodModel (see module docstring)."""

    def __init__(self, model: RodModel):
        if not isinstance(model, RodModel):
            raise JassyError(f"model: expected a RodModel, got {type(model).__name__}")
        self.model = model
        self.n = model.n
        self.ndof = model.n + 3
        self.l = model.l
        self.kappa0 = model.kappa0
        self.kappa_index = slice(3, None)
        self.start_rows = np.array(BC_ROWS[model.start_bc], dtype=np.int64)
        self.end_rows = np.array(BC_ROWS[model.end_bc], dtype=np.int64)
        self.end_target = model.end_target
        n = self.n
        self.elem = np.repeat(np.arange(n), arc.NQ)  # element of each quadrature point
        self.tau = (self.l[:, None] * arc.GAUSS_X[None, :]).ravel()  # local arc length
        self.w = (self.l[:, None] * arc.GAUSS_W[None, :]).ravel()
        s_nodes = np.concatenate(([0.0], np.cumsum(self.l)))
        self.sigma = s_nodes[self.elem] + self.tau
        # lambda_j(sigma) = d theta(sigma) / d (theta0, kappa_j): 1, l_j (j < m), tau (j = m)
        lam = np.where(np.arange(n)[None, :] < self.elem[:, None], self.l[None, :], 0.0)
        lam[np.arange(lam.shape[0]), self.elem] = self.tau
        self.lam = np.hstack((np.ones((lam.shape[0], 1)), lam))
        self._below = np.arange(n)[None, :] < self.elem[:, None]
        diag = np.zeros(self.ndof)
        diag[3:] = model.EI * self.l
        self._bend = np.diag(diag)
        diag[3:] = model.damping * self.l
        self._damp = np.diag(diag)

    def _check(self, q) -> np.ndarray:
        q = np.asarray(q, dtype=np.float64)
        if q.shape != (self.ndof,):
            raise JassyError(
                f"q: expected {self.ndof} values (x0, y0, theta0, n curvatures), got shape {q.shape}"
            )
        return q

    def initial_state(self, kappa=None) -> RodState:
        """Rod at ``model.start`` with curvatures ``kappa`` (default: rest curvature), at rest."""
        kappa = (
            self.kappa0 if kappa is None else np.broadcast_to(np.asarray(kappa, dtype=np.float64), (self.n,))
        )
        return RodState(np.concatenate((self.model.start, kappa)), np.zeros(self.ndof))

    def nodes(self, q):
        """Node positions (complex, n+1) and angles (n+1,)."""
        q = self._check(q)
        return arc.forward_kinematics(q[0], q[1], q[2], q[3:], self.l)

    def arcs(self, q) -> Arcs:
        r, th = self.nodes(q)
        return Arcs(
            r[:-1].real.copy(), r[:-1].imag.copy(), th[:-1].copy(), np.array(q[3:], float), self.l.copy()
        )

    def project(self, q: np.ndarray) -> np.ndarray:
        return q

    def _jacobian(self, q, r, th, elem, tau):
        """Complex Jacobian (P, n+3) and positions (P,) at points (elem, tau)."""
        k = q[3:]
        f = arc.moments(k[elem], tau)
        rot = np.exp(1j * th[elem])
        p = r[elem] + rot * f[0]
        b = np.exp(1j * th[:-1]) * arc.moments(k, self.l)[1] - self.l * r[1:]
        below = np.arange(self.n)[None, :] < elem[:, None]
        J = np.empty((p.size, self.ndof), dtype=np.complex128)
        J[:, 0], J[:, 1], J[:, 2] = 1.0, 1j, 1j * (p - r[0])
        J[:, 3:] = np.where(below, 1j * (self.l[None, :] * p[:, None] + b[None, :]), 0.0)
        J[np.arange(p.size), 3 + elem] = 1j * rot * f[1]
        return J, p

    def point_jacobian(self, q, element: int, s: float):
        """(point (2,), cols, J (2, len(cols))) at arc length s (m) of ``element``."""
        self.check_point(element, s)
        r, th = self.nodes(q)
        J, p = self._jacobian(self._check(q), r, th, np.array([element]), np.array([float(s)]))
        cols = np.arange(4 + element)
        return np.array([p[0].real, p[0].imag]), cols, np.stack((J[0, cols].real, J[0, cols].imag))

    def point_hessian(self, q, element: int, s: float):
        """(cols, H (2, k, k)): d2 x/dq2 and d2 y/dq2 on (theta0, kappa_0..kappa_element).
        d2 r(s)/dq_a dq_b = -int_0^s lambda_a lambda_b e^{i theta} d sigma."""
        self.check_point(element, s)
        q = self._check(q)
        e = element
        _, th = self.nodes(q)
        lens = self.l[: e + 1].copy()
        lens[e] = s
        f = np.exp(1j * th[: e + 1]) * arc.moments(q[3 : 4 + e], lens)
        ell = np.concatenate(([1.0], self.l[: e + 1]))
        s0 = np.concatenate((np.cumsum(f[0][::-1])[::-1], [0.0]))  # sum_{m >= k} E0_m
        idx = np.arange(e + 2)
        H = np.outer(ell, ell) * s0[np.maximum.outer(idx, idx)]
        t2 = np.where(idx[:, None] < idx[None, 1:], ell[:, None] * f[1][None, :], 0.0)  # (a, m): a <= m
        H[:, 1:] += t2
        H[1:, :] += t2.T
        H[idx[1:], idx[1:]] += f[2]
        H = -H
        return 2 + idx, np.stack((H.real, H.imag))

    def dynamics(self, q, v) -> Dynamics:
        q = self._check(q)
        v = np.asarray(v, dtype=np.float64)
        m = self.model
        r, th = self.nodes(q)
        J, _ = self._jacobian(q, r, th, self.elem, self.tau)
        Jx, Jy = J.real, J.imag
        M = m.rho_A * (Jx.T @ (self.w[:, None] * Jx) + Jy.T @ (self.w[:, None] * Jy))
        # velocity-quadratic acceleration -int_0^sigma omega^2 e^{i theta}, omega linear per element
        kd = v[3:]
        omega = v[2] + np.concatenate(([0.0], np.cumsum(kd * self.l)))[:-1]
        fn = np.exp(1j * th[:-1]) * arc.moments(q[3:], self.l)
        full = omega**2 * fn[0] + 2 * omega * kd * fn[1] + kd**2 * fn[2]
        before = np.concatenate(([0j], np.cumsum(full)))[self.elem]
        fq = arc.moments(q[3:][self.elem], self.tau)
        o, kq = omega[self.elem], kd[self.elem]
        acc = -(before + np.exp(1j * th[self.elem]) * (o**2 * fq[0] + 2 * o * kq * fq[1] + kq**2 * fq[2]))
        gyro = -m.rho_A * (Jx.T @ (self.w * acc.real) + Jy.T @ (self.w * acc.imag))
        _, grad, K = self._gravity(q, th, psd=True)
        return Dynamics(M, self._damp, K, grad, gyro)

    def _gravity(self, q, th, psd: bool):
        m = self.model
        phi = th[self.elem] + q[3:][self.elem] * self.tau
        wg = m.rho_A * m.gravity * self.w * (m.length - self.sigma)
        s = np.sin(phi)
        V = m.rho_A * m.gravity * m.length * q[1] + float(wg @ s)
        grad = np.zeros(self.ndof)
        grad[1] = m.rho_A * m.gravity * m.length
        grad[2:] = self.lam.T @ (wg * np.cos(phi))
        dk = q[3:] - self.kappa0
        grad[3:] += m.EI * self.l * dk
        V += 0.5 * m.EI * float(self.l @ (dk * dk))
        K = self._bend.copy()
        weight = -wg * (np.minimum(s, 0.0) if psd else s)
        K[2:, 2:] += self.lam.T @ (weight[:, None] * self.lam)
        return V, grad, K

    def potential(self, q):
        """(V J, grad V, exact Hessian (dense)) of bending + gravity."""
        q = self._check(q)
        _, th = self.nodes(q)
        return self._gravity(q, th, psd=False)

    def _end_rows(self, q):
        """Tip pose, and its Jacobian rows (3, ndof)."""
        p, cols, J = self.point_jacobian(q, self.n - 1, self.l[-1])
        rows = np.zeros((3, self.ndof))
        rows[:2, cols] = J
        rows[2, 2] = 1.0
        rows[2, 3:] = self.l
        return np.array([p[0], p[1], q[2] + float(self.l @ q[3:])]), rows

    def constraints(self, q):
        """(C sparse (m, n+3), g (m,)): start rows then end rows."""
        q = self._check(q)
        start = np.eye(3, self.ndof)[self.start_rows]
        g = [q[self.start_rows] - np.asarray(self.model.start)[self.start_rows]]
        rows = [start]
        if self.end_rows.size:
            pose, jr = self._end_rows(q)
            rows.append(jr[self.end_rows])
            g.append(pose[self.end_rows] - self.end_target[self.end_rows])
        return sp.csr_matrix(np.vstack(rows)), np.concatenate(g)

    def constraint_hessian(self, q, lam: np.ndarray, psd: bool = False) -> np.ndarray:
        """sum_k lam_k d2 g_k / dq2 (dense; only the end rows are nonlinear); psd: keep only
        its positive part."""
        H = np.zeros((self.ndof, self.ndof))
        le = np.zeros(3)
        le[self.end_rows] = lam[self.start_rows.size :]
        if le[0] or le[1]:
            cols, h = self.point_hessian(q, self.n - 1, self.l[-1])
            hb = le[0] * h[0] + le[1] * h[1]
            if psd:
                w, U = np.linalg.eigh(hb)
                hb = (U * np.maximum(w, 0.0)) @ U.T
            H[np.ix_(cols, cols)] = hb
        return H

    def kkt_factor(self, A, C, method: str = "dense"):
        """Factor [[A, C^T], [C, 0]] once (dense LU); ``.solve(b, c) -> (v, lam)``."""
        if method != "dense":
            raise JassyError(f"method: expected 'dense', got {method!r}")
        return DenseKKT(A, C)
