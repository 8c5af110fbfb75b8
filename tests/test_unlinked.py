"""jassy.unlinked: a kernel called through its entry point runs its own compiled code (the
result of the Python function), is not linked into the caller, refuses an entry point of
other types, and passes the callee's exception on."""

from typing import NamedTuple

import numba as nb
import numpy as np
import pytest

from jassy.unlinked import Entry, call_apart, entry


class Rows(NamedTuple):
    a: np.ndarray
    b: np.ndarray


@nb.njit(_nrt=False)
def weighted_sum(rows, k, x):
    """sum(a x + b) + k; a ValueError for a negative k."""
    if k < 0:
        raise ValueError("weighted_sum: k must be >= 0")
    total = 0.0
    for i in range(rows.a.shape[0]):
        total += rows.a[i] * x + rows.b[i]
    return total + k


@nb.njit(_nrt=False)
def summed(rows, where, n):
    total = 0.0
    for k in range(n):
        total += call_apart(where, (rows, k, 1.5), nb.float64)
    return total


ROWS = Rows(np.linspace(0.0, 1.0, 7), np.arange(7.0))


def test_the_call_returns_the_kernels_result():
    where = entry(weighted_sum, ROWS, np.int64(0), 1.5)
    expected = sum(float(np.sum(ROWS.a * 1.5 + ROWS.b)) + k for k in range(5))
    assert summed(ROWS, where, 5) == pytest.approx(expected, rel=1e-15)


def test_the_callee_is_not_linked_into_the_caller():
    where = entry(weighted_sum, ROWS, np.int64(0), 1.5)
    summed(ROWS, where, 1)
    (signature,) = summed.signatures
    callee_name = weighted_sum.overloads[weighted_sum.signatures[0]].fndesc.llvm_func_name
    caller_ir = summed.inspect_llvm(signature)
    assert f"@{callee_name}(" not in caller_ir and f'@"{callee_name}"(' not in caller_ir
    assert "inttoptr" in caller_ir
    callee_library = weighted_sum.overloads[weighted_sum.signatures[0]].library
    assert callee_library not in summed.overloads[signature].library._linking_libraries


def test_an_entry_of_other_types_is_refused():
    where = entry(weighted_sum, ROWS, np.int64(0), 1.5)
    with pytest.raises(RuntimeError, match="other types"):
        summed(ROWS, Entry(where.address, where.types + 1), 1)
    float_rows = entry(weighted_sum, ROWS, 0.0, 1.5)  # k as a float: another compiled function
    with pytest.raises(RuntimeError, match="other types"):
        summed(ROWS, float_rows, 1)


def test_the_callees_exception_is_passed_on():
    where = entry(weighted_sum, ROWS, np.int64(0), 1.5)

    @nb.njit(_nrt=False)
    def negative(rows, where):
        return call_apart(where, (rows, -1, 1.0), nb.float64)

    with pytest.raises(ValueError, match="k must be >= 0"):
        negative(ROWS, where)


#: Rows's name and member types with its fields in the other order: the same numba type name.
SwappedRows = NamedTuple("Rows", [("b", np.ndarray), ("a", np.ndarray)])  # noqa: UP014 (named Rows)


def test_a_record_of_other_field_names_is_refused():
    """Two NamedTuples whose numba type names agree (same class name, same member types) but
    whose fields differ: the call refuses the other one's entry."""
    swapped = SwappedRows(ROWS.b, ROWS.a)
    assert str(nb.typeof(swapped)) == str(nb.typeof(ROWS))
    where = entry(weighted_sum, ROWS, np.int64(0), 1.5)

    @nb.njit(_nrt=False)
    def swapped_call(rows, where):
        return call_apart(where, (rows, 0, 1.5), nb.float64)

    with pytest.raises(RuntimeError, match="other types"):
        swapped_call(swapped, where)
    assert swapped_call(ROWS, where) == pytest.approx(float(np.sum(ROWS.a * 1.5 + ROWS.b)), rel=1e-15)


def test_only_an_entry_is_called():
    """A tuple that is not an Entry does not type as the callee's address."""

    @nb.njit(_nrt=False)
    def with_tuple(rows):
        return call_apart((1.5, 3), (rows, 0, 1.5), nb.float64)

    with pytest.raises(nb.core.errors.TypingError):
        with_tuple(ROWS)
