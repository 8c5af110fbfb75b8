"""Broad phase: the pairs of bodies whose bounding boxes overlap, by sweep and prune.

The boxes are sorted on x and swept once, keeping the boxes still open (Baraff, "Dynamic
simulation of non-penetrating rigid bodies", 1992, sec. 7.2). The pair buffer, the sorted
copies of the boxes and the open list live in a :func:`new_sweep` scratch kept for a whole run,
so a sweep allocates nothing but the sort's order.
"""

from __future__ import annotations

import numba as nb
import numpy as np


@nb.njit(cache=True)
def new_sweep(n):
    """Scratch of a sweep over n bodies: (pairs (P, 2) grown as needed, sorted lows (n, 3),
    sorted highs (n, 3), sorted body indices (n,), open list (n,))."""
    return (
        np.empty((max(16, 8 * n), 2), np.int64),
        np.empty((n, 3)),
        np.empty((n, 3)),
        np.empty(n, np.int64),
        np.empty(n, np.int64),
    )


@nb.njit(cache=True)
def sweep_pairs(lo, hi, movable, scratch):
    """(pairs (count, 2) (i < j) whose boxes [lo, hi] overlap and of which at least one is
    movable, in sweep order: by the later box's rank on x, then the earlier's; the scratch,
    with a larger pair buffer if it had to grow). O(n log n + open boxes)."""
    pairs, slo, shi, body, active = scratch
    n = lo.shape[0]
    order = np.argsort(lo[:, 0])
    for k in range(n):
        i = order[k]
        body[k] = i
        for x in range(3):
            slo[k, x] = lo[i, x]
            shi[k, x] = hi[i, x]
    count = 0
    n_active = 0
    for k in range(n):
        i = body[k]
        lx, ly, lz, hy, hz = slo[k, 0], slo[k, 1], slo[k, 2], shi[k, 1], shi[k, 2]
        keep = 0
        for e in range(n_active):
            m = active[e]
            if shi[m, 0] < lx:
                continue  # closed: every later box starts further on
            active[keep] = m
            keep += 1
            if shi[m, 1] >= ly and hy >= slo[m, 1] and shi[m, 2] >= lz and hz >= slo[m, 2]:
                j = body[m]
                if movable[i] or movable[j]:
                    if count == pairs.shape[0]:
                        grown = np.empty((2 * count, 2), np.int64)
                        grown[:count] = pairs
                        pairs = grown
                    pairs[count, 0] = min(i, j)
                    pairs[count, 1] = max(i, j)
                    count += 1
        n_active = keep
        active[n_active] = k
        n_active += 1
    return pairs[:count], (pairs, slo, shi, body, active)
