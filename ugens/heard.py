"""The heard output of a closed-loop contact: its modes driven by the contact force, with
the model's signed strike-to-pickup gains.

A contact ugen (HuntCrossleyImpact, Friction) solves its loop with the driving-point gains
a_k = phi_k(c)^2 / (M_k w_k) (ModalModel.driving: displacement per N s, m/(N s)); what a
pickup at p hears is the same modes driven by the same force with the model's signed gains
b_k (e.g. phi_k(c) phi_k(p) / (M_k w_k), or a velocity's phi_k(c) phi_k(p) / M_k), i.e.
each mode's displacement times b_k / a_k. Being linear in the force, it is computed after the loop,
mode by mode, with the loop's own discretisation: a two-state recursion per mode,

    q' = c0 q + c1 p + c4 f,   p' = c2 q + c3 p + c5 f,   heard = sum_k q'.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from jassy.jit import drop_stale_cache
from ugens import cells
from ugens.cells import state_step
from ugens.kernels import FASTMATH

drop_stale_cache(__file__, [cells])  # its cache holds copies of their kernels


@nb.njit(fastmath=FASTMATH, cache=True)
def heard_run(force, out, n, coef, state):
    """n samples: force (N) per sample in, heard displacement out; coef (6, K), state (2, K)."""
    k_modes = state.shape[1]
    for i in range(n):
        f = force[i]
        total = 0.0
        for k in range(k_modes):
            q, p = state_step(coef[0, k], coef[1, k], coef[2, k], coef[3, k], state[0, k], state[1, k])
            q += coef[4, k] * f
            state[0, k] = q
            state[1, k] = p + coef[5, k] * f
            total += q
        out[i] = total


def impulse_invariant(c1: np.ndarray, c2: np.ndarray, g: np.ndarray) -> np.ndarray:
    """Coefficients of q[n] = c1 q[n-1] - c2 q[n-2] + g f[n] (state: q[n-1], q[n-2])."""
    zero = np.zeros_like(c1)
    return np.array([c1, -c2, np.ones_like(c1), zero, g, zero])
