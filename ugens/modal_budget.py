"""Compiled parts of anytime synthesis for ModalBank: importance, ranking, the kept set.

A budgeted bank keeps its modes in their internal order and computes only the kept ones:
their rows are gathered into a compact bank (the same row layout, so the same kernels run
on it, at a cost proportional to the kept modes) and scattered back when the kept set or
the coefficients change. Modes outside the kept set hold zero state.

Importance of mode k for the coming budget period (see jassy.anytime):

    I_k = w_k (max(A_k^2, u_k S(f_k) G_k) + u_k sum_j J_j^2 + E_k)

A_k^2 = (y1^2 - c1 y1 y2 + c2 y2^2) / sin^2 theta: the squared amplitude of the
decaying sine through the last two state samples; u_k = (g fs)^2 / (R^2 sin^2 theta) the
squared amplitude per unit impulse (N s) at the bank's current location; S the force's
power spectral density at the mode's frequency (N^2/Hz); G_k = (1 - e^{-2 d tau}) / (2 d)
the build-up of a steady force over the horizon tau (s); J_j the impulses scheduled at the
current location and E_k the squared amplitudes of impacts scheduled elsewhere.
"""

from __future__ import annotations

import numba as nb
import numpy as np

#: Rows of a compact bank: c1, c2, g, d, y1, y2 (as ModalBank.bank), then the ramp's
#: per-sample increments and targets of c1, c2, g, d.
COMPACT_ROWS = 14


@nb.njit(cache=True)
def gather_kept(bank, delta, target, kept, count, compact):
    """Copy the rows of modes ``kept[:count]`` into ``compact[:, :count]`` (bank rows
    0-5, delta rows 6-9, target rows 10-13); its further columns become silent modes."""
    compact[:, count:] = 0.0
    for j in range(count):
        k = kept[j]
        for r in range(6):
            compact[r, j] = bank[r, k]
        for r in range(4):
            compact[6 + r, j] = delta[r, k]
            compact[10 + r, j] = target[r, k]


@nb.njit(cache=True)
def scatter_kept(compact, kept, count, bank):
    """Write the coefficients and state of the compact bank back to modes ``kept[:count]``."""
    for j in range(count):
        k = kept[j]
        for r in range(6):
            bank[r, k] = compact[r, j]


@nb.njit(cache=True)
def centred_power(force):
    """Mean square of ``force`` about its mean (a steady load makes no sound), N^2."""
    n = force.size
    mean = 0.0
    for i in range(n):
        mean += force[i]
    mean /= n
    total = 0.0
    for i in range(n):
        f = force[i] - mean
        total += f * f
    return total / n


@nb.njit(fastmath=True, cache=True)
def mode_importance(
    compact, kept, count, target_gain, delta_gain, ramp_left, sin2, inv, sample_rate, spectrum, bins,
    flat_psd, growth, kick_here_now, kick_here_next, elsewhere_now, elsewhere_next, decay_period, weights,
    kept_mask, faded, bonus, floor2, scores,
):  # fmt: skip
    """Importance of every mode for this period (scores[0]) and the next (scores[1], the
    amplitude decayed by ``decay_period`` = R^(2 period)), and whether it sounds now
    (scores[2]: 1.0 or 0.0). Modes kept and not fading get ``bonus`` (no churn at the
    margin).

    ``spectrum``: the force's PSD per DFT bin (``bins[k]`` the mode's bin); if empty,
    ``flat_psd``: its power spectral density spread flat (0: no force heard).
    ``elsewhere_*``: squared amplitudes of impacts at other locations (empty: none)."""
    n = inv.size
    for k in range(n):
        scores[2, k] = 0.0
    amp2 = np.zeros(n)
    for j in range(count):
        k = kept[j]
        y1 = compact[4, j]
        y2 = compact[5, j]
        a = (y1 * y1 - compact[0, j] * y1 * y2 + compact[1, j] * y2 * y2) / sin2[k]
        if a > 0.0:
            amp2[k] = a
            if a > floor2:
                scores[2, k] = 1.0
    binned = spectrum.size > 0
    has_now = elsewhere_now.size > 0
    has_next = elsewhere_next.size > 0
    for k in range(n):
        g = (target_gain[k] - ramp_left * delta_gain[k]) * sample_rate
        unit2 = g * g * inv[k]
        s = spectrum[bins[k]] if binned else flat_psd
        forced = unit2 * s * growth[k]
        now = max(amp2[k], forced) + unit2 * kick_here_now
        later = max(amp2[k] * decay_period[k], forced) + unit2 * kick_here_next
        if has_now:
            now += elsewhere_now[k]
        if has_next:
            later += elsewhere_next[k]
        w = weights[k]
        if kept_mask[k] and not faded[k]:
            now *= bonus
        scores[0, k] = w * now
        scores[1, k] = w * later


@nb.njit(cache=True)
def apply_kept(
    keep, fade, kept_mask, faded, bank, target, delta, fresh, ramp_left, shrink, kept, compact, count
):
    """Make ``keep`` | ``fade`` the computed set; return its size (its modes, ascending, in
    ``kept``), or -1 if nothing changes (same set, no fades then or now). bank rows: c1,
    c2, g, d, y1, y2 (ModalBank.bank); ``compact[:, :count]``: the kept modes' rows, written
    back to ``bank`` first if the set changes.

    Modes back from a fade take their fresh design (their ramp is lost); entering modes
    take the coefficients their ramp has reached (target - left * delta); fading modes
    decay by ``shrink`` per sample (amplitude) and hear nothing; silenced modes hold zero
    state (their coefficients keep following ramps virtually)."""
    n = keep.size
    same = True
    for k in range(n):
        if fade[k] or faded[k] or keep[k] != kept_mask[k]:
            same = False
            break
    if same:
        return -1
    scatter_kept(compact, kept, count, bank)
    coef = bank[:4]
    count = 0
    for k in range(n):
        if faded[k]:
            for r in range(4):
                target[r, k] = fresh[r, k]
                delta[r, k] = 0.0
        if keep[k]:
            if not kept_mask[k] or faded[k]:
                for r in range(4):
                    coef[r, k] = target[r, k] - ramp_left * delta[r, k]
        elif fade[k]:
            coef[0, k] *= shrink
            coef[1, k] *= shrink * shrink
            coef[2, k] = 0.0
            coef[3, k] = 0.0
            for r in range(4):
                target[r, k] = coef[r, k]
                delta[r, k] = 0.0
        else:
            bank[4, k] = 0.0
            bank[5, k] = 0.0
        faded[k] = fade[k]
        kept_mask[k] = keep[k] or fade[k]
        if kept_mask[k]:
            kept[count] = k
            count += 1
    return count
