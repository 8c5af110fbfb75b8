"""Zeroed arrays carved out of one buffer, with their slots of a handle
(jassy.record_views) known as they are made.

Asking numpy for an array's address costs about a microsecond (jassy.jit.address),
and allocating a record's dozen arrays one by one, then listing them in a handle, tens
of microseconds of Python: a mode budget pays that at the start of every render. Arrays
carved from one buffer have the buffer's address plus their offsets.
"""

from __future__ import annotations

import itertools
import math
from typing import NamedTuple

import numpy as np

from jassy.jit import address

#: Bytes between the starts of two arrays of a buffer (a cache line).
LINE = 64

#: The dtypes of packed arrays (dtype objects: an array over a buffer is made fastest
#: from one).
FLOAT, INT, BOOL = np.dtype(np.float64), np.dtype(np.int64), np.dtype(np.bool_)


class Packed(NamedTuple):
    """Arrays of one buffer, in the order asked for, and each one's handle slots
    (address, first extent, second extent or 1)."""

    arrays: list[np.ndarray]
    slots: list[tuple[int, int, int]]


def packed_zeros(fields) -> Packed:
    """Zeroed C-contiguous arrays of ``fields`` ((shape, dtype) pairs: one or two
    dimensions, a dtype object such as :data:`FLOAT`) in one buffer, each starting on a
    64-byte cache line (the float64 mode loops' vector loads then never straddle lines)."""
    sizes = [-(-max(math.prod(shape) * dtype.itemsize, 1) // LINE) * LINE for shape, dtype in fields]
    offsets = list(itertools.accumulate(sizes, initial=0))
    raw = np.zeros(offsets.pop() + LINE, dtype=np.uint8)
    at = address(raw)
    skip = -at % LINE
    base = at + skip
    arrays = [
        np.ndarray(shape, dtype, raw, skip + to) for (shape, dtype), to in zip(fields, offsets, strict=True)
    ]
    slots = [
        (base + to, shape[0], shape[1] if len(shape) > 1 else 1)
        for (shape, _), to in zip(fields, offsets, strict=True)
    ]
    return Packed(arrays, slots)


def handle_of(slots) -> np.ndarray:
    """The handle (jassy.record_views) of ``slots``: each field's three int64 slots, in
    order (numpy reads a flat iterator ~3x faster than nested tuples)."""
    return np.fromiter(itertools.chain.from_iterable(slots), dtype=np.int64, count=3 * len(slots))
