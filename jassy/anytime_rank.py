"""Ranking of a mode budget, compiled: the modes to compute and to fade out per period."""

from __future__ import annotations

import numba as nb
import numpy as np


@nb.njit(cache=True)
def top_mask(score, limit, keep):
    """keep[k] = True for the ``limit`` highest positive scores (ties broken by index)."""
    n = score.size
    positive = 0
    for k in range(n):
        keep[k] = score[k] > 0.0
        if keep[k]:
            positive += 1
    if positive <= limit:
        return
    threshold = np.partition(score, n - limit)[n - limit]
    taken = 0
    for k in range(n):
        keep[k] = score[k] > threshold
        if keep[k]:
            taken += 1
    for k in range(n):
        if taken >= limit:
            break
        if score[k] == threshold:
            keep[k] = True
            taken += 1


@nb.njit(cache=True)
def rank_modes(scores, limit, keep, fade, later_top):
    """The modes to compute for this period (``keep``) and, among them, those to fade out
    (``fade``: kept now, not among the top of the next period, and sounding)."""
    top_mask(scores[0], limit, keep)
    top_mask(scores[1], limit, later_top)
    any_fade = False
    for k in range(keep.size):
        f = keep[k] and not later_top[k] and scores[2, k] > 0.0
        fade[k] = f
        if f:
            keep[k] = False
            any_fade = True
    return any_fade
