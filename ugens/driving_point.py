"""A contact on a resonator that gives way: the resonator's driving-point modes at the
contact, stepped one sample at a time so a contact law can be solved with no delay.

Each mode follows ModalBank's recursion y[n] = c1 y[n-1] - c2 y[n-2] + g f[n] with
driving-point gains g = a R sin(theta) / fs >= 0 (a: ModalModel.driving_at, m per N s), so
the contact displacement x[n] = sum_k y_k[n] = X + G f[n]: X the modes' free motion
(:func:`free_motion`), G = sum_k g_k (m/N) what this sample's force adds. A contact law
f(x) is solved for f from these two numbers, and :func:`settle` then commits the sample.
Used by Friction (bristle friction) and the rolling forces (a contact spring: :func:`press`
for the micro-impacts, :func:`roll_over` for the rolling contact filter).
"""

from __future__ import annotations

import numba as nb
import numpy as np

from jassy.jit import drop_stale_cache
from jassy.modal_model import ModalModel
from ugens import cells, kernels, modal
from ugens.cells import two_pole
from ugens.kernels import FASTMATH
from ugens.modal import design

# its cache holds copies of their kernels and constants
drop_stale_cache(__file__, [cells, kernels, modal])

#: Rows of the modes array: recursion coefficients, driving-point gains, two past outputs.
MODE_ROWS = 5


def driving_point_modes(model: ModalModel, location, sample_rate: float, modes: np.ndarray) -> float:
    """Write the model's modes at ``location`` into rows c1, c2, g of ``modes``
    (MODE_ROWS, K); the past outputs (rows y1, y2) are kept. Returns G = sum_k g_k (m/N)."""
    c1, c2, s = design(model.frequencies, model.decays, sample_rate)
    modes[0] = c1
    modes[1] = c2
    modes[2] = s / sample_rate * model.driving_at(location)
    return float(np.sum(modes[2]))


def move_contact(modes: np.ndarray, gains_before: np.ndarray) -> tuple[float, float]:
    """Carry the surface's motion to a new contact: ``modes`` holds the new driving-point
    gains (row g), ``gains_before`` the old ones. Mode k's output at the contact is
    phi_k(p) q_k (q_k its modal displacement, phi_k its shape at the contact p, g_k ~
    phi_k^2), so the modes keep q_k and their past outputs are rescaled by
    |phi_k(new) / phi_k(old)| = sqrt(g_new / g_old) (0 where g_old = 0: q_k is not seen
    there). The shapes' signs are not in the gains (taken as kept). Keeping the outputs
    instead would hand the new contact a mode whose gain fell from g_old to g_new with
    g_old / g_new times its energy. Returns the change of the contact displacement in the
    last two samples (m)."""
    before = float(np.sum(modes[3])), float(np.sum(modes[4]))
    ratio = np.zeros_like(gains_before)
    np.divide(modes[2], gains_before, out=ratio, where=gains_before > 0.0)
    modes[3:] *= np.sqrt(ratio)
    return float(np.sum(modes[3])) - before[0], float(np.sum(modes[4])) - before[1]


@nb.njit(inline="always", cache=True)
def free_motion(modes, scratch, drive):
    """The contact displacement X (m) this sample would have under the force ``drive`` (N)
    alone; scratch[k] gets each mode's share."""
    c1 = modes[0]
    c2 = modes[1]
    g = modes[2]
    y1 = modes[3]
    y2 = modes[4]
    x = 0.0
    for k in range(c1.shape[0]):
        h = two_pole(c1[k], c2[k], y1[k], y2[k], g[k] * drive)
        scratch[k] = h
        x += h
    return x


@nb.njit(inline="always", cache=True)
def settle(modes, scratch, force):
    """Commit the sample: each mode's output is its free share plus g times ``force`` (N)."""
    g = modes[2]
    y1 = modes[3]
    y2 = modes[4]
    for k in range(g.shape[0]):
        y2[k] = y1[k]
        y1[k] = scratch[k] + g[k] * force


@nb.njit(inline="always", cache=True)
def press(modes, scratch, free, drive, stiffness, gain_sum):
    """One sample of a force ``drive`` (N) delivered through a contact spring of
    ``stiffness`` k (N/m; 0 while the ball is off the surface) to a surface that gives
    way: returns f = drive - k x, x the surface's displacement at the contact under f,
    and commits the sample (:func:`settle`).

    modes: the surface's driving-point modes (:func:`driving_point_modes`), gain_sum their
    G; ``free`` = X, this sample's :func:`free_motion` (scratch holds its shares); x = X +
    G f, solved exactly, f = (drive - k X) / (1 + k G) (no delay in the loop). The
    open-loop force is k times the height the ball would ride over a rigid surface; the
    surface's motion takes k x off it.
    """
    f = (drive - stiffness * free) / (1.0 + stiffness * gain_sum)
    settle(modes, scratch, f)
    return f


@nb.njit(fastmath=FASTMATH, cache=True)
def roll_over(out, loads, n, modes, scratch, ball, contact, inv_height, ball_gain, gain_sum):
    """The contact filter of rolling: a ball of mass m on a contact spring k (N/m) with a
    dashpot c (N s/m) rides over a roughness r (m) on a surface that gives way. out[:n]
    holds r / inv_height and is replaced by the dynamic contact force F (N) on the surface;
    while loads[i] <= 0 (the ball lifted off) there is no contact (F = 0) and the ball is
    held on the surface (y = r - x: no compression, moving with it), so contact returns
    without the drift of a ball moving on at its last speed. F is linear: the spring may
    pull (loads[i] + F < 0) where a real ball would hop.

    F = k d + c d', d = r - y - x the spring's compression: y the ball's rise, m y'' = F,
    stepped as the surface's modes are (impulse invariance: y[n] = 2 y[n-1] - y[n-2] +
    ball_gain F[n], ball_gain = 1 / (m fs^2)); x = X + G F the surface's displacement
    (gain_sum G); d' = (d[n] - d[n-1]) fs. contact = [k, c, fs]; ball = [y1, y2, d1].
    Solved per sample without delay: with K = k + c fs, F = (K (r - Y - X) - c fs d1) /
    (1 + K (ball_gain + G)), Y the ball's free rise. In the frequency domain (c = 0)
    F = r / (1/k - 1/(m w^2) + alpha(w)), alpha the surface's driving-point receptance:
    the rolling-noise contact filter (Remington, JASA 81, 1987; Thompson, *Railway Noise
    and Vibration*, 2009, ch. 5): below the contact resonance sqrt(k / m) the ball
    follows the roughness (F ~ m w^2 r), at a strong resonance of the surface the surface
    follows it (F ~ r / alpha).
    """
    k = contact[0]
    damping = contact[1] * contact[2]
    stiff = k + damping
    y1 = ball[0]
    y2 = ball[1]
    d1 = ball[2]
    compliance = 1.0 + stiff * (ball_gain + gain_sum)
    for i in range(n):
        x = free_motion(modes, scratch, 0.0)
        if loads[i] > 0.0:
            y = 2.0 * y1 - y2
            free = out[i] * inv_height - y - x
            f = (stiff * free - damping * d1) / compliance
            settle(modes, scratch, f)
            y2 = y1
            y1 = y + ball_gain * f
            d1 = free - (ball_gain + gain_sum) * f
        else:  # lifted: the ball follows the surface, to return without compression
            f = 0.0
            settle(modes, scratch, f)
            y2 = y1
            y1 = out[i] * inv_height - x
            d1 = 0.0
        out[i] = f
    ball[0] = y1
    ball[1] = y2
    ball[2] = d1
