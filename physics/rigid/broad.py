"""Broad phase: the pairs of bodies whose bounding boxes overlap, by sweep and prune.

The boxes are sorted on x and swept once, keeping the boxes still open (Baraff, "Dynamic
simulation of non-penetrating rigid bodies", 1992, sec. 7.2). The pair buffer, the sort's
order and stack, the sorted copies of the boxes and the open list live in a :class:`Sweep`
kept for a whole run: a sweep allocates nothing (it is compiled without reference counting),
and a pair buffer too small for the pairs is grown by the caller (:func:`sweep_pairs` counts
them all).
"""

from __future__ import annotations

from typing import NamedTuple

import numba as nb
import numpy as np

SMALL_SORT = 15  # partitions shorter than this are insertion-sorted
SORT_STACK = 100  # deepest partition stack (each push halves at least: 2^100 boxes)


class Sweep(NamedTuple):
    """A sweep's scratch over n bodies (new_sweep)."""

    pairs: np.ndarray  # (P, 2) overlapping pairs found, i < j
    order: np.ndarray  # (n,) the bodies by their boxes' low x
    stack: np.ndarray  # (SORT_STACK, 2) the sort's pending partitions (first, last)
    slo: np.ndarray  # (n, 3) lows in sweep order, m
    shi: np.ndarray  # (n, 3) highs in sweep order, m
    open: np.ndarray  # (n,) ranks of the boxes still open


def new_sweep(n: int, pairs: int = 0) -> Sweep:
    """Scratch of a sweep over n bodies with room for ``pairs`` pairs (default 8 n, at least 16)."""
    return Sweep(
        np.empty((max(16, 8 * n, pairs), 2), np.int64),
        np.empty(n, np.int64),
        np.empty((SORT_STACK, 2), np.int64),
        np.empty((n, 3)),
        np.empty((n, 3)),
        np.empty(n, np.int64),
    )


@nb.njit(cache=True, inline="always")
def _before(a, b):
    """a sorts before b: a < b, NaN last (NumPy's order)."""
    return a < b or (np.isnan(b) and not np.isnan(a))


@nb.njit(cache=True, _nrt=False)
def _insertion_sort(key, order, low, high):
    """order[low:high + 1] sorted by key (inclusive bounds)."""
    for i in range(low + 1, high + 1):
        k = order[i]
        v = key[k]
        j = i
        while j > low and _before(v, key[order[j - 1]]):
            order[j] = order[j - 1]
            j -= 1
        order[j] = k


@nb.njit(cache=True, _nrt=False)
def _partition(key, order, low, high):
    """Partition order[low:high + 1] about the median of its first, middle and last keys;
    returns the pivot's final place."""
    mid = (low + high) >> 1
    if _before(key[order[mid]], key[order[low]]):
        order[low], order[mid] = order[mid], order[low]
    if _before(key[order[high]], key[order[mid]]):
        order[high], order[mid] = order[mid], order[high]
    if _before(key[order[mid]], key[order[low]]):
        order[low], order[mid] = order[mid], order[low]
    pivot = key[order[mid]]
    order[high], order[mid] = order[mid], order[high]
    i = low
    j = high - 1
    while True:
        while i < high and _before(key[order[i]], pivot):
            i += 1
        while j >= low and _before(pivot, key[order[j]]):
            j -= 1
        if i >= j:
            break
        order[i], order[j] = order[j], order[i]
        i += 1
        j -= 1
    order[i], order[high] = order[high], order[i]
    return i


@nb.njit(cache=True, _nrt=False)
def sort_order(key, order, stack):
    """order: the indices of key sorted by key (the permutation np.argsort's default quicksort
    gives under numba, equal keys included: the same median-of-three quicksort with insertion
    sort below SMALL_SORT), in place, with the partition stack ``stack`` (SORT_STACK, 2)."""
    n = key.shape[0]
    for i in range(n):
        order[i] = i
    if n < 2:
        return
    stack[0, 0], stack[0, 1] = 0, n - 1
    depth = 1
    while depth > 0:
        depth -= 1
        low, high = stack[depth, 0], stack[depth, 1]
        while high - low >= SMALL_SORT:
            i = _partition(key, order, low, high)
            if high - i > i - low:  # push the larger side, go on with the smaller
                if high > i:
                    stack[depth, 0], stack[depth, 1] = i + 1, high
                    depth += 1
                high = i - 1
            else:
                if i > low:
                    stack[depth, 0], stack[depth, 1] = low, i - 1
                    depth += 1
                low = i + 1
        _insertion_sort(key, order, low, high)


@nb.njit(cache=True, _nrt=False)
def sweep_pairs(lo, hi, movable, sweep):
    """How many pairs (i < j) have overlapping boxes [lo, hi] with at least one of them
    movable; the first sweep.pairs.shape[0] of them are written to sweep.pairs, in sweep
    order: by the later box's rank on x, then the earlier's. A count above the buffer's rows
    means the buffer must grow and the sweep be done again. O(n log n + open boxes)."""
    pairs, order, slo, shi, active = sweep.pairs, sweep.order, sweep.slo, sweep.shi, sweep.open
    n = lo.shape[0]
    sort_order(lo[:, 0], order, sweep.stack)
    for k in range(n):
        i = order[k]
        for x in range(3):
            slo[k, x] = lo[i, x]
            shi[k, x] = hi[i, x]
    room = pairs.shape[0]
    count = 0
    n_active = 0
    for k in range(n):
        i = order[k]
        lx, ly, lz, hy, hz = slo[k, 0], slo[k, 1], slo[k, 2], shi[k, 1], shi[k, 2]
        keep = 0
        for e in range(n_active):
            m = active[e]
            if shi[m, 0] < lx:
                continue  # closed: every later box starts further on
            active[keep] = m
            keep += 1
            if shi[m, 1] >= ly and hy >= slo[m, 1] and shi[m, 2] >= lz and hz >= slo[m, 2]:
                j = order[m]
                if movable[i] or movable[j]:
                    if count < room:
                        pairs[count, 0] = min(i, j)
                        pairs[count, 1] = max(i, j)
                    count += 1
        n_active = keep
        active[n_active] = k
        n_active += 1
    return count
