"""Static equilibrium of a rod formulation: Newton on the KKT system with load continuation.

Minimises bending + gravity energy minus the work of dead point loads subject to the
formulation's constraints g(q) = 0 (boundary conditions, and the gluing rows of the mixed
model). Each Newton step solves [[H, C^T], [C, 0]] [dq; lam] = [-grad; -g] with the exact
Lagrangian Hessian H = d2V + d2(-F.r) + lam . d2g, so convergence is quadratic. Gravity and
loads are ramped in ``load_steps`` equal increments (each solved to ``tol``), which keeps the
iterates on the branch connected to the unloaded rest shape; curvature steps are limited to
0.5 rad per element (kappa l).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
import scipy.sparse as sp

from jassy.errors import JassyError
from physics.rod.model import PointLoad


@dataclass
class StaticResult:
    """Equilibrium q, multipliers lam (constraint forces, N or N m), Newton iterations,
    final step size |dq|_inf and whether it converged."""

    q: np.ndarray
    lam: np.ndarray
    iterations: int
    step: float
    converged: bool


def _add_blocks(K, blocks, ndof):
    if not blocks:
        return K
    if sp.issparse(K):
        rows = np.concatenate([np.repeat(c, c.size) for c, _ in blocks])
        cols = np.concatenate([np.tile(c, c.size) for c, _ in blocks])
        vals = np.concatenate([h.ravel() for _, h in blocks])
        return K + sp.csr_matrix((vals, (rows, cols)), shape=(ndof, ndof))
    K = K.copy()
    for c, h in blocks:
        K[np.ix_(c, c)] += h
    return K


def newton(form, q: np.ndarray, lam: np.ndarray | None, loads=(), tol: float = 1e-10, max_iter: int = 60):
    """Newton-KKT iterations on one formulation from q; returns a StaticResult."""
    scale = np.ones(form.ndof)
    scale[form.kappa_index] = form.l
    lam = np.zeros(form.constraints(q)[1].size) if lam is None else lam
    step = math.inf
    for it in range(1, max_iter + 1):
        _, grad, K = form.potential(q)
        _, g_load, blocks = form.load_terms(q, loads)
        C, g = form.constraints(q)
        H = _add_blocks(K, blocks, form.ndof) + form.constraint_hessian(q, lam)
        dq, lam_new = form.kkt_factor(H, C).solve(-(grad + g_load), -g)
        step = float(np.max(np.abs(dq * scale)))
        alpha = min(1.0, 0.5 / step) if step > 0 else 1.0
        q = form.project(q + alpha * dq)
        lam = lam + alpha * (lam_new - lam)
        if not np.all(np.isfinite(q)):
            raise JassyError("static solve: diverged (non-finite state); use more load_steps")
        if alpha == 1.0 and step < tol:
            return StaticResult(q, lam, it, step, True)
    return StaticResult(q, lam, max_iter, step, False)


def solve_static(form, q0: np.ndarray | None = None, loads=(), load_steps: int = 1, tol: float = 1e-10,
                 max_iter: int = 60) -> StaticResult:  # fmt: skip
    """Equilibrium of ``form`` (ChainedRod or MixedRod) under gravity and dead ``loads``
    (PointLoad list), ramped from zero in ``load_steps`` steps, starting at q0 (default: the
    rest shape). Raises JassyError if a load step does not converge."""
    if isinstance(load_steps, bool) or not isinstance(load_steps, (int, np.integer)) or load_steps < 1:
        raise JassyError(f"load_steps: expected an integer >= 1, got {load_steps!r}")
    for load in loads:
        if not isinstance(load, PointLoad):
            raise JassyError(f"loads: expected PointLoad items, got {type(load).__name__}")
    q = form.initial_state().q if q0 is None else form.project(np.asarray(q0, dtype=np.float64))
    model, lam, res = form.model, None, None
    total = 0
    for k in range(1, load_steps + 1):
        t = k / load_steps
        f = type(form)(replace(model, gravity=t * model.gravity))
        scaled = [PointLoad(p.element, p.s, (t * p.force[0], t * p.force[1])) for p in loads]
        res = newton(f, q, lam, scaled, tol, max_iter)
        total += res.iterations
        if not res.converged:
            raise JassyError(
                f"static solve: Newton did not converge at load step {k}/{load_steps} "
                f"(last step {res.step:.3g}); use more load_steps"
            )
        q, lam = res.q, res.lam
    res.iterations = total
    return res
