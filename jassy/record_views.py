"""Records of arrays handed to compiled code by address: one int64 array (a handle)
instead of the records themselves.

numba unboxes every array of a record argument at every call (about half a microsecond
each), so a kernel taking a few records of a dozen arrays each pays 10-20 us per call
before it starts: more than the work of a short sub-block. A handle lists, per field of
each record in order, FIELD int64 slots: an array's address and its (up to two) extents,
or an integer's value. Compiled code rebuilds the arrays as views (:func:`float_row`,
:func:`float_table`, ...). The arrays must stay alive and in place while the handle is
used (their owners keep them); a handle is rebuilt when one of them is replaced.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from jassy import jit
from jassy.jit import address, drop_stale_cache, void_pointer

drop_stale_cache(__file__, [jit])  # its views hold copies of jit.void_pointer's code

#: int64 slots per field of a handle: address (or an integer's value), then two extents.
FIELD = 3


def handle(*records) -> np.ndarray:
    """The handle of ``records`` (NamedTuples, or tuples, of C-contiguous arrays of at
    most two dimensions and integers), fields in order."""
    slots = []
    for record in records:
        for value in record:
            if isinstance(value, np.ndarray):
                if not value.flags.c_contiguous or value.ndim > 2:
                    raise ValueError(
                        f"handle: a C-contiguous array of at most 2 dimensions, got {value.shape}"
                    )
                slots += [address(value), *value.shape, *(1,) * (2 - value.ndim)]
            else:
                slots += [int(value), 0, 0]
    return np.array(slots, dtype=np.int64)


@nb.njit(inline="always", cache=True)
def float_row(a, i):
    """The 1-D float64 array of the field at slot ``i`` of handle ``a``."""
    return nb.carray(void_pointer(a[i]), (a[i + 1],), np.float64)


@nb.njit(inline="always", cache=True)
def float_table(a, i):
    """The 2-D float64 array of the field at slot ``i`` of handle ``a``."""
    return nb.carray(void_pointer(a[i]), (a[i + 1], a[i + 2]), np.float64)


@nb.njit(inline="always", cache=True)
def float32_table(a, i):
    """The 2-D float32 array of the field at slot ``i`` of handle ``a``."""
    return nb.carray(void_pointer(a[i]), (a[i + 1], a[i + 2]), np.float32)


@nb.njit(inline="always", cache=True)
def int_row(a, i):
    """The 1-D int64 array of the field at slot ``i`` of handle ``a``."""
    return nb.carray(void_pointer(a[i]), (a[i + 1],), np.int64)


@nb.njit(inline="always", cache=True)
def int_table(a, i):
    """The 2-D int64 array of the field at slot ``i`` of handle ``a``."""
    return nb.carray(void_pointer(a[i]), (a[i + 1], a[i + 2]), np.int64)


@nb.njit(inline="always", cache=True)
def bool_row(a, i):
    """The 1-D bool array of the field at slot ``i`` of handle ``a``."""
    return nb.carray(void_pointer(a[i]), (a[i + 1],), np.bool_)
