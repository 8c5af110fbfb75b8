"""jassy.jit.specialise: the typed entry point, remembered by a cheap key of the argument types."""

import numba as nb
import numpy as np

from jassy.jit import specialise


@nb.njit(cache=True)
def _total(x, scale, parts):
    return x.sum() * scale + parts[0].sum()


def _numba_entry(*args):
    return _total.overloads[tuple(nb.typeof(a) for a in args)].entry_point


def test_each_argument_type_gets_numbas_own_entry_point():
    a = np.arange(6.0)
    cases = [
        (a, 2.0, (a,)),  # C-contiguous float64, float, tuple of one array
        (a[::2], 2.0, (a,)),  # strided: layout A
        (a.reshape(2, 3).T.copy().T, 2.0, (a,)),  # 2-D F-contiguous
        (np.arange(6), 3, (a,)),  # int64 array, int
        (a, 2.0, (a[::3],)),  # the tuple's array strided
    ]
    read_only = a.copy()
    read_only.flags.writeable = False
    cases.append((read_only, 2.0, (a,)))
    entries = []
    for args in cases:
        entry = specialise(_total, *args)
        assert entry is _numba_entry(*args)  # found by numba's typing on first use
        assert specialise(_total, *args) is entry  # remembered
        assert entry(*args) == _total.py_func(*args)
        entries.append(entry)
    assert len({id(e) for e in entries}) == len(cases)  # every type its own entry point


def test_arguments_without_a_cheap_key_still_get_their_entry_point():
    a = np.arange(4.0)
    entry = specialise(_total, a, np.float64(2.0), (a,))  # a numpy scalar: typed by numba each time
    assert entry(a, np.float64(2.0), (a,)) == 18.0  # 6 * 2 + 6
