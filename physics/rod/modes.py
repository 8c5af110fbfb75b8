"""Flexural modes of a rod about a static equilibrium, as a jassy ModalModel.

Linearisation: the constrained motions are v = Z u with Z a basis of ker C(q*) (boundary
conditions and, in the mixed model, the gluing rows); stiffness K = d2V + lam* . d2g (exact
Lagrangian Hessian at the equilibrium q*, lam*), mass M(q*). The reduced generalized
eigenproblem Z^T K Z u = w^2 Z^T M Z u is solved with scipy.linalg.eigh, whose eigenvectors
are mass-normalised (u^T Z^T M Z u = 1). Rigid modes (w^2 <= 1e-9 max w^2) are dropped.

Gains follow the project convention (physics.modal.fem, ugens.modal): the displacement impulse
response at point p per 1 N s, a[p, k] = |phi_k(p)|^2 / w_k (m per N s), with phi_k(p) = J(p) Z u_k
the 2D displacement of mode k at p; with a unit ``direction`` n, a = (n . phi_k(p))^2 / w_k.
Decays use the damping law of physics.modal.materials: d(f) = d0 + pi loss f + beta (2 pi f)^2 / 2
(1/s; loss = loss factor 1/Q, d0 = alpha/2 and beta of Rayleigh damping C = alpha M + beta K).
"""

from __future__ import annotations

import math

import numpy as np
import scipy.linalg as sla

from jassy.errors import JassyError
from jassy.modal_model import ModalModel
from physics.rod.statics import solve_static


def locate(form, s: float) -> tuple[int, float]:
    """(element, local arc length) of the point at arc length s (m) from the start."""
    L, n = form.model.length, form.model.n
    if not (isinstance(s, (int, float, np.floating)) and math.isfinite(s) and 0.0 <= s <= L):
        raise JassyError(f"points: expected arc lengths in [0, {L:g}] m, got {s!r}")
    e = min(int(s / (L / n)), n - 1)
    return e, float(s - e * L / n)


def rod_modes(form, q: np.ndarray | None = None, lam: np.ndarray | None = None, n_modes: int | None = None):
    """(omega rad/s (k,), shapes (ndof, k) mass-normalised, q*) about the equilibrium q*
    (default: solve_static(form); pass q and lam of an equilibrium to skip the solve)."""
    if q is None:
        res = solve_static(form, load_steps=4)
        q, lam = res.q, res.lam
    elif lam is None:
        raise JassyError("lam: expected the constraint multipliers of the equilibrium q (from solve_static)")
    _, _, K = form.potential(q)
    K = K + form.constraint_hessian(q, lam)
    K = K.toarray() if hasattr(K, "toarray") else np.asarray(K)
    M = form.dynamics(q, np.zeros(form.ndof)).M
    M = M.toarray() if hasattr(M, "toarray") else np.asarray(M)
    C, _ = form.constraints(q)
    Z = sla.null_space(C.toarray()) if C.shape[0] else np.eye(form.ndof)
    Kr, Mr = Z.T @ K @ Z, Z.T @ M @ Z
    w2, U = sla.eigh(0.5 * (Kr + Kr.T), 0.5 * (Mr + Mr.T))
    keep = w2 > 1e-9 * max(float(np.max(np.abs(w2))), 1e-300)
    w2, U = w2[keep], U[:, keep]
    if n_modes is not None:
        w2, U = w2[:n_modes], U[:, :n_modes]
    return np.sqrt(w2), Z @ U, q


def modal_model(form, points, n_modes: int = 8, q=None, lam=None, d0: float = 0.0, loss: float = 1e-3,
                beta: float = 0.0, direction=None, name: str = "rod") -> ModalModel:  # fmt: skip
    """ModalModel of the rod's first ``n_modes`` flexural modes with gains at ``points``
    (arc lengths in m; named "s=<value>") and decays from the damping law above."""
    for key, v in (("d0", d0), ("loss", loss), ("beta", beta)):
        if not (math.isfinite(v) and v >= 0):
            raise JassyError(f"{key}: expected a finite number >= 0, got {v!r}")
    pts = np.atleast_1d(np.asarray(points, dtype=np.float64))
    if pts.ndim != 1 or pts.size == 0:
        raise JassyError(f"points: expected one or more arc lengths (m), got {points!r}")
    omega, shapes, q = rod_modes(form, q, lam, n_modes)
    if omega.size == 0:
        raise JassyError("modal_model: the rod has no flexural mode (check the boundary conditions)")
    if direction is not None:
        d = np.asarray(direction, dtype=np.float64)
        if d.shape != (2,) or not np.isfinite(d).all() or np.linalg.norm(d) == 0:
            raise JassyError(f"direction: expected a non-zero 2D vector, got {direction!r}")
        d = d / np.linalg.norm(d)
    gains = np.empty((pts.size, omega.size))
    for i, s in enumerate(pts):
        _, cols, J = form.point_jacobian(q, *locate(form, float(s)))
        disp = J @ shapes[cols]  # (2, k)
        amp2 = (d @ disp) ** 2 if direction is not None else np.sum(disp * disp, axis=0)
        gains[i] = amp2 / omega
    f = omega / (2 * np.pi)
    decays = d0 + np.pi * loss * f + 0.5 * beta * omega**2
    return ModalModel(f, decays, gains, tuple(f"s={s:g}" for s in pts), name)
