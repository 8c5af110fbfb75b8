"""physics.rigid.record_ref: a record read and written through a reference in compiled code
gives what the record itself gives (checked against the record's own arrays and values, in
kernels inlined at numba's level and in kernels called with the reference)."""

from typing import NamedTuple

import numba as nb
import numpy as np
import pytest
from numba.core import errors
from numba.extending import overload

from physics.rigid import record_ref
from physics.rigid.record_ref import RecordRef, RefExample, deref, ref


class Inner(NamedTuple):
    table: np.ndarray
    flags: np.ndarray


class Record(NamedTuple):
    a: np.ndarray
    b: np.ndarray
    rows: np.ndarray
    inner: Inner
    count: int
    scale: float


def _record(seed: int = 0) -> Record:
    rng = np.random.default_rng(seed)
    return Record(
        rng.normal(size=(4, 3)),
        np.zeros((4, 3)),
        np.array([2, 0], np.int64),
        Inner(rng.normal(size=(2, 2, 5)), np.array([True, False, True])),
        7,
        0.25,
    )


@nb.njit(_nrt=False)
def _fields_through_ref(record):
    r = ref(record)
    return (
        r.a[3, 2],
        r.a.shape[0],
        r.rows[1],
        r.inner.table[1, 0, 4],
        r.inner.flags[2],
        r.count,
        r.scale,
        deref(r).a[0, 1],
    )


def test_fields_read_through_a_ref_are_the_records():
    record = _record()
    got = _fields_through_ref(record)
    want = (
        record.a[3, 2],
        4,
        0,
        record.inner.table[1, 0, 4],
        True,
        7,
        0.25,
        record.a[0, 1],
    )
    assert got == want


def _times_scale(r, value):
    """value * r.scale."""
    return value * r.scale


@overload(_times_scale, inline="always")
def _times_scale_compiled(r, value):
    return _times_scale


@nb.njit(inline="always")
def _scaled_rows(r, s):
    """b[i] = a[i] * s * scale for the rows listed in r.rows (inlined at numba's level, with
    an overload inlined there too: numba then eliminates dead code)."""
    for j in range(r.rows.shape[0]):
        i = r.rows[j]
        for x in range(3):
            r.b[i, x] = _times_scale(r, r.a[i, x] * s)


@nb.njit(_nrt=False)
def _write_inlined(record, s):
    r, inner = ref(record), ref(record.inner)
    _scaled_rows(r, s + inner.table.shape[0] - 2)


@nb.njit(_nrt=False)
def _scaled_rows_called(r, s):
    _scaled_rows(r, s)


@nb.njit(_nrt=False)
def _write_called(record, s):
    _scaled_rows_called(ref(record), s)


@nb.njit(_nrt=False)
def _write_inlined_by_attribute(record, s):
    _scaled_rows(record_ref.ref(record), s)


@pytest.mark.parametrize("kernel", [_write_inlined, _write_called, _write_inlined_by_attribute])
def test_writes_through_a_ref_reach_the_arrays(kernel):
    """In a kernel inlined at numba's level (where numba's dead code elimination dropped these
    writes while it took a ref for new memory: ``ref`` called by name and through its module,
    which numba's alias analysis names differently) and in a kernel given the ref."""
    record = _record(1)
    kernel(record, 3.0)
    want = np.zeros((4, 3))
    want[[2, 0]] = record.a[[2, 0]] * 3.0 * 0.25
    np.testing.assert_array_equal(record.b, want)


@nb.njit(_nrt=False)
def _sum_through_ref(record):
    return ref(record).table.sum()


@nb.njit
def _last_use(n):
    record = Inner(np.arange(n * 1.0), np.zeros(3, np.bool_))  # arrays owned by numba alone
    r = ref(record)  # the record's last use: numba may free its arrays after this line
    return r.table.sum()


def test_a_ref_is_refused_in_a_kernel_that_counts_references():
    """With reference counting numba frees the record's arrays after its last use (here the
    ref call) and reads through the ref would see freed memory: such a kernel does not compile,
    also after the same record type was ref'd in a kernel without reference counting (numba
    types an intrinsic once per argument types)."""
    assert _sum_through_ref(Inner(np.arange(1000.0), np.zeros(3, np.bool_))) == 999 * 1000 / 2
    with pytest.raises(errors.NumbaError, match="_nrt=False"):
        _last_use(1000)


def test_an_example_ref_types_as_a_ref_of_the_records_type():
    record = _record()
    assert nb.typeof(RefExample(record)) == RecordRef(nb.typeof(record))
    signature = (RecordRef(nb.typeof(record)), nb.float64)
    _scaled_rows_called.compile(signature)
    assert signature in _scaled_rows_called.signatures


@nb.njit(_nrt=False)
def _inner_total(inner_ref):
    total = 0.0
    for i in range(inner_ref.table.shape[0]):
        for j in range(inner_ref.table.shape[2]):
            total += inner_ref.table[i, 1, j]
    inner_ref.flags[1] = True
    return total


@nb.njit(_nrt=False)
def _through_field_ref(record):
    return _inner_total(record_ref.field_ref(ref(record), "inner"))


def test_a_field_ref_reads_and_writes_the_nested_records_arrays():
    """field_ref(ref, "inner"): a reference to the nested record (passed to another kernel),
    reading its arrays' values and writing into them."""
    record = _record(3)
    expected = float(record.inner.table[:, 1, :].sum())
    assert _through_field_ref(record) == pytest.approx(expected, rel=1e-15)
    assert record.inner.flags[1]
