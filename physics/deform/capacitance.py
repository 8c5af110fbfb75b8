"""The capacitance-matrix algorithm (CMA): contact on top of reference Green's functions.

When s free vertices S switch to prescribed displacement (contact), the Sherman-Morrison-
Woodbury formula gives the new solution from Xi of the reference problem (physics.deform.
greens): with E the n x s selection, C = -E^T Xi E (the s x s capacitance matrix, 3x3
blocks), v0 = Xi (I - E E^T) v_bar' - E E^T v_bar' (v_bar' = prescribed values with the
contact displacements in the switched slots),

    v = v0 + (I + Xi) E C^{-1} E^T v0.

E^T v is the contact tractions, O(s^2) once C is factored; the whole v is O(ns). ``smw_solve``
evaluates this literally (loads on the other free vertices allowed).

``CapacitanceSolver`` is the haptic form with vertex masks (James & Pai 2001): constraint m
(centred at free vertex c_m) spreads its force F_m (N) as the traction p_j = tau_mj F_m over
the mask vertices j (weights w_j = (1 - (d_j/rho)^2)^2 at rest distance d_j < rho, tau =
w / sum_j w_j a_j, so sum_j a_j p_j = F_m) and prescribes the work-conjugate average
displacement sum_j omega_mj u_j = u_bar_m (omega = w a / sum w a). With all other free
vertices traction-free, u_bar = K F with the mask compliance K_mn = sum_jk omega_mj
Xi_jk tau_nk (= -C for rho = 0, where F_m = a_m p_m). K is gathered and LU-factored when
the contact set changes (O(s^2 mask^2 + s^3)) and reused while it does not: forces are
then O(s^2), the displacement field O(ns).
"""

from __future__ import annotations

import numba as nb
import numpy as np
import scipy.linalg as sla
from scipy.spatial import cKDTree

from jassy.errors import JassyError
from physics.deform.bem import dof_columns
from physics.deform.greens import GreensFunctions


def smw_solve(greens: GreensFunctions, switched, u_switched, loads=None) -> tuple[np.ndarray, np.ndarray]:
    """Solution of the reference problem with the free vertices ``switched`` given the
    displacements ``u_switched`` (s, 3) in m and the other free vertices the tractions
    ``loads`` (n, 3) Pa (rows of fixed/switched vertices ignored; default zero), by the
    SMW formula of the module doc. Returns (u (n, 3) m, p (n, 3) Pa) at every vertex."""
    n, xi = greens.n, greens.xi
    S = np.asarray(switched, dtype=np.int64).ravel()
    uS = np.asarray(u_switched, dtype=np.float64).reshape(-1, 3)
    if S.size == 0 or np.unique(S).size != S.size or np.any(greens.col_of[S] < 0):
        raise JassyError("switched: expected distinct free vertex indices")
    if uS.shape != (S.size, 3) or not np.all(np.isfinite(uS)):
        raise JassyError(f"u_switched: expected a finite ({S.size}, 3) array")
    load = np.zeros((n, 3)) if loads is None else np.array(loads, dtype=np.float64)
    if load.shape != (n, 3) or not np.all(np.isfinite(load)):
        raise JassyError(f"loads: expected a finite ({n}, 3) array")
    load[greens.fixed] = 0.0
    load[S] = 0.0
    rows = dof_columns(n, S)  # E picks these slots
    cols = dof_columns(greens.free.size, greens.col_of[S])
    v0 = xi @ load[greens.free].ravel()  # Xi (I - E E^T) v_bar'
    v0[rows] -= uS.ravel()  # - E E^T v_bar'
    y = sla.lu_solve(sla.lu_factor(-xi[np.ix_(rows, cols)]), v0[rows])  # C^{-1} E^T v0
    v = v0 + xi[:, cols] @ y
    v[rows] += y
    v = v.reshape(n, 3)
    u = np.where(greens.fixed[:, None], 0.0, v)
    p = np.where(greens.fixed[:, None], v, load)
    u[S], p[S] = uS, v[S]
    return u, p


@nb.njit(cache=True)
def gather_compliance(xi, ptr, verts, omega, tau, col_of, active, s, K):
    """K[:3s, :3s] = mask compliance (module doc) of the constraints centred at active[:s]."""
    for a in range(s):
        ma = active[a]
        for b in range(s):
            mb = active[b]
            for p in range(3):
                for q in range(3):
                    K[3 * a + p, 3 * b + q] = 0.0
            for ja in range(ptr[ma], ptr[ma + 1]):
                rj = 3 * verts[ja]
                wj = omega[ja]
                for kb in range(ptr[mb], ptr[mb + 1]):
                    ck = 3 * col_of[verts[kb]]
                    w = wj * tau[kb]
                    for p in range(3):
                        for q in range(3):
                            K[3 * a + p, 3 * b + q] += w * xi[rj + p, ck + q]


@nb.njit(cache=True)
def displacement_at(xi, ptr, verts, tau, col_of, active, s, forces, query, out):
    """out[i] = displacement (m) of free vertex query[i] under constraint forces[:s] (N)."""
    for i in range(query.shape[0]):
        r = 3 * query[i]
        for p in range(3):
            out[i, p] = 0.0
        for a in range(s):
            m = active[a]
            for kb in range(ptr[m], ptr[m + 1]):
                ck = 3 * col_of[verts[kb]]
                t = tau[kb]
                for p in range(3):
                    out[i, p] += t * (xi[r + p, ck] * forces[a, 0] + xi[r + p, ck + 1] * forces[a, 1]
                                      + xi[r + p, ck + 2] * forces[a, 2])  # fmt: skip


@nb.njit(cache=True)
def lu_factor_small(A, m, piv):
    """In-place LU with partial pivoting of A[:m, :m]; False if singular."""
    for k in range(m):
        p = k
        for i in range(k + 1, m):
            if abs(A[i, k]) > abs(A[p, k]):
                p = i
        piv[k] = p
        if p != k:
            for j in range(m):
                A[k, j], A[p, j] = A[p, j], A[k, j]
        if A[k, k] == 0.0:
            return False
        inv = 1.0 / A[k, k]
        for i in range(k + 1, m):
            A[i, k] *= inv
            f = A[i, k]
            for j in range(k + 1, m):
                A[i, j] -= f * A[k, j]
    return True


@nb.njit(cache=True)
def lu_solve_small(A, m, piv, b):
    """Solve (LU of A[:m, :m]) x = b[:m] in place."""
    for k in range(m):
        p = piv[k]
        if p != k:
            b[k], b[p] = b[p], b[k]
    for i in range(m):
        acc = b[i]
        for j in range(i):
            acc -= A[i, j] * b[j]
        b[i] = acc
    for i in range(m - 1, -1, -1):
        acc = b[i]
        for j in range(i + 1, m):
            acc -= A[i, j] * b[j]
        b[i] = acc / A[i, i]


class CapacitanceSolver:
    """Contact forces and deformation of a GreensFunctions object under s masked vertex
    constraints (module doc). ``mask_radius`` rho (m; 0 = single vertices)."""

    def __init__(self, greens: GreensFunctions, mask_radius: float = 0.0, max_contacts: int = 64):
        if not (np.isfinite(mask_radius) and mask_radius >= 0):
            raise JassyError(f"mask_radius: expected a distance >= 0 m, got {mask_radius!r}")
        if int(max_contacts) < 1:
            raise JassyError(f"max_contacts: expected an integer >= 1, got {max_contacts!r}")
        self.greens = greens
        self.mask_radius = float(mask_radius)
        self.max_contacts = int(max_contacts)
        self.ptr, self.verts, self.omega, self.tau = vertex_masks(greens, self.mask_radius)
        m = 3 * self.max_contacts
        self._K = np.zeros((m, m))
        self._piv = np.zeros(m, dtype=np.int64)
        self._active = np.zeros(self.max_contacts, dtype=np.int64)
        self._rhs = np.zeros(m)
        self._response = None
        self.s = 0
        self.refactors = 0

    @property
    def contacts(self) -> np.ndarray:
        """Centre vertices of the current constraints."""
        return self._active[: self.s].copy()

    def set_contacts(self, vertices) -> bool:
        """Make ``vertices`` (free vertex indices, distinct) the constraint set; gathers and
        factors K only if the set changed. Returns True if it did."""
        v = np.asarray(vertices, dtype=np.int64).ravel()
        if v.size == self.s and np.array_equal(v, self._active[: self.s]):
            return False
        if v.size > self.max_contacts:
            raise JassyError(f"vertices: at most max_contacts={self.max_contacts} contacts, got {v.size}")
        if v.size and (v.min() < 0 or v.max() >= self.greens.n or np.any(self.greens.col_of[v] < 0)):
            raise JassyError("vertices: expected free (not fixed) vertex indices")
        if np.unique(v).size != v.size:
            raise JassyError("vertices: expected distinct vertex indices")
        self._active[: v.size] = v
        self.s = v.size
        self._response = None
        g = self.greens
        gather_compliance(
            g.xi, self.ptr, self.verts, self.omega, self.tau, g.col_of, self._active, v.size, self._K
        )
        if not lu_factor_small(self._K, 3 * v.size, self._piv):
            raise JassyError("vertices: the contact compliance matrix is singular (overlapping masks?)")
        self.refactors += 1
        return True

    def solve(self, displacements) -> np.ndarray:
        """Forces (s, 3) in N on the body at the constraints for prescribed (mask-average)
        displacements (s, 3) in m; O(s^2) with the cached factorisation."""
        m = 3 * self.s
        self._rhs[:m] = np.asarray(displacements, dtype=np.float64).ravel()
        lu_solve_small(self._K, m, self._piv, self._rhs)
        return self._rhs[:m].reshape(self.s, 3).copy()

    def displacement_at(self, vertices, forces) -> np.ndarray:
        """Displacement (k, 3) in m of the free ``vertices`` under constraint forces (s, 3) N,
        O(k s mask) without building the full response."""
        g = self.greens
        q = np.asarray(vertices, dtype=np.int64).ravel()
        out = np.zeros((q.size, 3))
        f = np.ascontiguousarray(forces, dtype=np.float64).reshape(self.s, 3)
        displacement_at(g.xi, self.ptr, self.verts, self.tau, g.col_of, self._active, self.s, f, q, out)
        return out

    def displacements(self, forces) -> np.ndarray:
        """Displacement (n, 3) in m of every vertex under constraint forces (s, 3) N, O(ns)
        (the n x 3s response is built once per contact set); fixed vertices stay at 0."""
        g = self.greens
        if self._response is None:
            R = np.zeros((3 * g.n, 3 * self.s))
            for a, c in enumerate(self._active[: self.s]):
                sl = slice(self.ptr[c], self.ptr[c + 1])
                cols = dof_columns(g.free.size, g.col_of[self.verts[sl]]).reshape(-1, 3)
                for k in range(3):
                    R[:, 3 * a + k] = g.xi[:, cols[:, k]] @ self.tau[sl]
            R[dof_columns(g.n, np.flatnonzero(g.fixed))] = 0.0
            self._response = R
        u = self._response @ np.asarray(forces, dtype=np.float64).ravel()
        return u.reshape(g.n, 3)


def vertex_masks(greens: GreensFunctions, rho: float):
    """CSR masks of every free vertex: (ptr (n+1,), vertices, omega, tau); see module doc."""
    g = greens
    free = g.free
    tree = cKDTree(g.vertices[free])
    ptr = np.zeros(g.n + 1, dtype=np.int64)
    verts, omega, tau = [], [], []
    for c in range(g.n):
        if g.fixed[c]:
            idx = np.zeros(0, dtype=np.int64)
        elif rho > 0:
            idx = free[np.sort(tree.query_ball_point(g.vertices[c], rho))]
        else:
            idx = np.array([c])
        d = np.linalg.norm(g.vertices[idx] - g.vertices[c], axis=1)
        w = (1.0 - (d / rho) ** 2) ** 2 if rho > 0 else np.ones(idx.size)
        wa = w * g.areas[idx]
        verts.append(idx)
        omega.append(wa / wa.sum() if idx.size else wa)
        tau.append(w / wa.sum() if idx.size else w)
        ptr[c + 1] = ptr[c] + idx.size
    return ptr, np.concatenate(verts), np.concatenate(omega), np.concatenate(tau)
