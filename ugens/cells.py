"""Per-sample cells shared by block and loop kernels (Faust's and STK's small parts).

Each cell is a numba function inlined into its caller (``inline="always"``), so it takes the
caller's fastmath flags and compiles to the same instructions as the code it replaced.

* :func:`raised_cosine`: the 1 - cos contact pulse of JASS's BangForce (van den Doel & Pai,
  "JASS: a Java audio synthesis system for programmers", ICAD 2001);
* :func:`pulse_sum`: its sampled sum, which scales a pulse to an exact impulse;
* :func:`with_room`: a table that doubles its rows when full (pulse tables).
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

#: Shortest contact pulse in samples: a pulse must be sampled at least once.
MIN_PULSE_SAMPLES = 2.0


@nb.njit(inline="always", cache=True)
def raised_cosine(x, T):
    """1 - cos(2 pi x / T): the unit pulse at x samples after its onset, T samples long."""
    return 1.0 - math.cos(2.0 * math.pi * x / T)


@nb.njit(cache=True)
def pulse_sum(t0, T):
    """Sum of (1 - cos(2 pi (n - t0)/T)) over integers t0 < n < t0 + T."""
    s = 0.0
    n = math.floor(t0) + 1
    while n < t0 + T:
        s += raised_cosine(n - t0, T)
        n += 1
    return s


@nb.njit(cache=True)
def with_room(table, rows):
    """``table``, or a zero-padded copy with its row count doubled until ``rows`` rows fit."""
    size = max(table.shape[0], 1)
    if rows <= table.shape[0]:
        return table
    while size < rows:
        size *= 2
    grown = np.zeros((size, table.shape[1]))
    grown[: table.shape[0]] = table
    return grown
