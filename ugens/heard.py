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

#: Rows of a heard coefficient array (6, K): the transition [[PHI11, PHI12], [PHI21, PHI22]]
#: of (q, p) and the force gains G_Q, G_P (c0 .. c5 above; the first six rows of
#: ugens.nonlinear_impact.ModeSteps).
PHI11, PHI12, PHI21, PHI22, G_Q, G_P = 0, 1, 2, 3, 4, 5
#: Rows of a mode state array (2, K): the two states q and p.
STATE_Q, STATE_P = 0, 1


@nb.njit(fastmath=FASTMATH, cache=True)
def heard_run(force, out, n, coef, state):
    """n samples: force (N) per sample in, heard displacement out; coef (6, K), state (2, K)."""
    k_modes = state.shape[1]
    for i in range(n):
        f = force[i]
        total = 0.0
        for k in range(k_modes):
            q, p = state_step(
                coef[PHI11, k],
                coef[PHI12, k],
                coef[PHI21, k],
                coef[PHI22, k],
                state[STATE_Q, k],
                state[STATE_P, k],
            )
            q += coef[G_Q, k] * f
            state[STATE_Q, k] = q
            state[STATE_P, k] = p + coef[G_P, k] * f
            total += q
        out[i] = total


def impulse_invariant(c1: np.ndarray, c2: np.ndarray, g: np.ndarray) -> np.ndarray:
    """Coefficients of q[n] = c1 q[n-1] - c2 q[n-2] + g f[n] (state: q[n-1], q[n-2])."""
    coef = np.zeros((6, *np.shape(c1)))
    coef[PHI11] = c1
    coef[PHI12] = -c2
    coef[PHI21] = 1.0
    coef[G_Q] = g
    return coef
