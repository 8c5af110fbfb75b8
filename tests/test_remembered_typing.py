"""jassy.remembered_typing: a builtin call's typing remembered per argument types when numba's
plain tables typed it, the same signatures as numba's own typing (the compiled code: the
subprocess test in test_inline_copies)."""

import operator

import numba as nb
import pytest
from numba.core import errors, types
from numba.core.registry import cpu_target
from numba.core.types import functions

from jassy import remembered_typing


@pytest.fixture(scope="module")
def context():
    nb.njit(lambda x: x * 2.0)(1.0)  # a first compile installs it (jassy.jit)
    assert remembered_typing.install()
    typing_context = cpu_target.typing_context
    typing_context.refresh()
    return typing_context


def _resolve(context, function, *args):
    function_type = context.resolve_value_type(function)
    first = function_type.get_call_type(context, args, {})
    again = function_type.get_call_type(context, args, {})
    numbas = functions.BaseFunction.get_call_type.numbas(function_type, context, args, {})
    return first, again, numbas


def test_plain_table_typings_are_remembered_and_equal_numbas(context):
    matrix = types.Array(types.float64, 2, "C")
    cases = [
        (operator.mul, types.float64, types.float64),
        (operator.add, types.int64, types.literal(1)),
        (operator.getitem, matrix, types.UniTuple(types.int64, 2)),
        (operator.le, types.float64, types.float64),
        (bool, types.boolean),
    ]
    for function, *args in cases:
        first, again, numbas = _resolve(context, function, *args)
        assert again is first  # remembered
        assert first == numbas and first.return_type == numbas.return_type


def test_overload_typings_are_typed_again(context):
    first, again, numbas = _resolve(context, len, types.unicode_type)  # an @overload in numba
    assert first.return_type == types.intp and first == again == numbas
    assert again is not first  # not remembered: numba types it again


def test_failures_are_raised_again(context):
    function_type = context.resolve_value_type(operator.mul)
    for _ in range(2):
        with pytest.raises(errors.TypingError):
            function_type.get_call_type(context, (types.float64, types.unicode_type), {})


def test_numba_shaped_otherwise_keeps_its_typing(monkeypatch):
    monkeypatch.setattr(functions, "BaseFunction", None)
    assert not remembered_typing.shaped_as_expected()
    assert not remembered_typing.install()


def test_a_numba_without_get_local_target_imports_jassy_and_keeps_its_typing(monkeypatch):
    """numba.core.target_extension.get_local_target moved: jassy still imports, and typing is
    left as numba's (the probe fails, install says no)."""
    import importlib

    from numba.core import target_extension

    monkeypatch.delattr(target_extension, "get_local_target")
    importlib.reload(remembered_typing)
    assert not remembered_typing.shaped_as_expected()
