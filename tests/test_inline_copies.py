"""jassy.inline_copies: numba's inliner hands over fresh translations, skips the untouched
copy numba's passes discard, copies a callee's scope once per IR copy, and the compiled code
is the same as with numba's own copies (two copies, one scope copy per block)."""

import copy
import inspect
import subprocess
import sys

import pytest
from numba.core import inline_closurecall, ir
from numba.core.compiler import run_frontend

from jassy import inline_copies


def _branchy(x, n):
    """Many blocks and variables: loops and branches, as the rigid kernels' helpers have."""
    total = 0.0
    for i in range(n):
        if x > i:
            total += x * i
        elif x < -i:
            total -= x
        else:
            for j in range(i):
                total += j * 0.5
    while total > 100.0:
        total *= 0.5
    return total


def test_the_blocks_of_one_copy_share_one_scope_equal_to_numbas_copies():
    source = run_frontend(_branchy)
    assert len(source.blocks) > 5
    copies = inline_copies.ScopeSharingCopies()
    with copies.sharing():
        shared = {label: copies.deepcopy(block) for label, block in source.blocks.items()}
    numbas = {label: copy.deepcopy(block) for label, block in source.blocks.items()}
    assert shared == numbas  # same statements (numba's IR equality ignores loc and scope)
    scopes = {id(block.scope) for block in shared.values()}
    assert len(scopes) == 1 and id(source.blocks[0].scope) not in scopes
    assert len({id(block.scope) for block in numbas.values()}) == len(numbas)  # numba: one per block
    scope = next(iter(shared.values())).scope
    assert list(scope.localvars._con) == list(numbas[0].scope.localvars._con)
    for label, block in shared.items():  # new statements, every variable in the scope copy
        assert all(new is not old for new, old in zip(block.body, source.blocks[label].body, strict=True))
        assert all(var.scope is scope for stmt in block.body for var in stmt.list_vars())


def test_copied_locations_share_their_cached_source_lines():
    source = run_frontend(_branchy)
    block = source.blocks[0]
    for statement in block.body:
        statement.loc.get_lines()  # numba caches them when it formats a message
    copies = inline_copies.ScopeSharingCopies()
    with copies.sharing():
        copied = copies.deepcopy(block)
    numbas = copy.deepcopy(block)
    assert copied == numbas
    for new, mine, old in zip(copied.body, numbas.body, block.body, strict=True):
        assert new.loc is not old.loc and new.loc == old.loc  # a copy, at the same place
        assert new.loc.lines is old.loc.lines and len(old.loc.lines) > 10  # one list, not copied
        assert mine.loc.lines == old.loc.lines and mine.loc.lines is not old.loc.lines


def test_outside_a_sharing_context_it_is_numbas_deepcopy():
    source = run_frontend(_branchy)
    copies = inline_copies.ScopeSharingCopies()
    copied = [copies.deepcopy(block) for block in source.blocks.values()]
    assert len({id(block.scope) for block in copied}) == len(copied)
    assert copies.copy is copy.copy  # the rest of the copy module passes through


def test_handed_over_blocks_are_the_working_copy_and_the_untouched_copy_is_made_unless_discarded():
    source = run_frontend(_branchy)
    copies = inline_copies.ScopeSharingCopies()
    for discarded in (True, False):
        with copies.sharing(handed_over=source.blocks.values(), discarded=discarded):
            working = {label: copies.deepcopy(block) for label, block in source.blocks.items()}
            untouched = {label: copies.deepcopy(block) for label, block in working.items()}
        assert all(working[label] is block for label, block in source.blocks.items())
        if discarded:
            assert all(untouched[label] is block for label, block in working.items())
        else:  # an independent copy, equal statement for statement
            assert untouched == working and not any(untouched[k] is working[k] for k in working)
            assert {id(block.scope) for block in untouched.values()} == {id(untouched[0].scope)}
            assert untouched[0].scope is not source.blocks[0].scope


def test_a_copied_working_copy_is_copied_once_more_only_if_not_discarded():
    source = run_frontend(_branchy)
    copies = inline_copies.ScopeSharingCopies()
    for discarded in (True, False):
        with copies.sharing(discarded=discarded):
            working = {label: copies.deepcopy(block) for label, block in source.blocks.items()}
            untouched = {label: copies.deepcopy(block) for label, block in working.items()}
        assert working == untouched and not any(working[k] is source.blocks[k] for k in working)
        assert all((untouched[k] is working[k]) == discarded for k in working)


def _kernel_helper(x):
    total = 0.0
    for i in range(3):
        if x > i:
            total += x
    return total


def _kernel_caller(x):
    return _kernel_helper(x) + 1.0


def _inline_the_helper():
    """Inline ``_kernel_helper`` into ``_kernel_caller``'s IR through numba's InlineWorker,
    called from here (not from numba's passes), counting the blocks deep-copied."""
    from numba.core.compiler import Flags
    from numba.core.registry import cpu_target

    caller_ir = run_frontend(_kernel_caller)
    (block, i) = next(
        (block, i)
        for block in caller_ir.blocks.values()
        for i, stmt in enumerate(block.body)
        if isinstance(stmt, ir.Assign)
        and isinstance(stmt.value, ir.Expr)
        and stmt.value.op == "call"
        and getattr(caller_ir.get_definition(stmt.value.func), "name", None) == "_kernel_helper"
    )
    worker = inline_closurecall.InlineWorker(
        cpu_target.typing_context, cpu_target.target_context, {}, object(), Flags(),
        validator=inline_closurecall.callee_ir_validator,
    )  # fmt: skip
    return worker.inline_function(caller_ir, block, i, _kernel_helper)


@pytest.fixture
def copied(monkeypatch):
    """The blocks the installed inliner copies from now on (jassy installs it when numba
    first compiles: one compile here)."""
    import numba as nb

    import jassy  # noqa: F401

    nb.njit(lambda x: x + 1)(1)
    blocks = []
    copy_block = inline_copies.ScopeSharingCopies._copied
    monkeypatch.setattr(
        inline_copies.ScopeSharingCopies,
        "_copied",
        staticmethod(lambda b, run: blocks.append(b) or copy_block(b, run)),
    )
    return blocks


def test_another_caller_gets_an_untouched_copy_apart_from_the_inlined_blocks(copied):
    untouched, _, _, inlined = _inline_the_helper()
    assert len(copied) == len(untouched.blocks) > 3  # the untouched copy only: the working one handed over
    inlined_ids = {id(block) for _, block in inlined}
    assert not any(id(block) in inlined_ids for block in untouched.blocks.values())
    assert all(
        block.scope is untouched.blocks[min(untouched.blocks)].scope for block in untouched.blocks.values()
    )


def test_numbas_inlining_pass_copies_no_block_of_a_fresh_translation(copied):
    import numba as nb

    helper = nb.njit(inline="always")(_kernel_helper)
    kernel = nb.njit(lambda x: helper(x) + 1.0)
    assert kernel(2.5) == _kernel_caller(2.5) == 8.5
    assert copied == []  # numba's pass discards the untouched copy; the translation is handed over


def test_numbas_passes_are_recognised_as_discarding_the_untouched_copy():
    from numba.core.typed_passes import InlineOverloads
    from numba.core.untyped_passes import InlineInlinables

    assert inline_copies.discards_first_result(InlineInlinables._do_work, "inline_function")
    assert inline_copies.discards_first_result(InlineOverloads._run_inliner, "inline_ir")
    assert inline_copies.numbas_callers() is not None

    def reads_it(worker):
        original, _, _, blocks = worker.inline_ir(1, 2)
        return original

    def reads_underscore(worker):
        _, _, _, blocks = worker.inline_ir(1, 2)
        return _

    def keeps_the_tuple(worker):
        return worker.inline_ir(1, 2)

    for caller in (reads_it, reads_underscore, keeps_the_tuple):
        assert not inline_copies.discards_first_result(caller, "inline_ir")


def test_passes_shaped_otherwise_always_get_the_untouched_copy(monkeypatch):
    from numba.core.untyped_passes import InlineInlinables

    def do_work_reading_it(self, state, work_list, block, i, expr, inline_worker):
        original, _, _, new_blocks = inline_worker.inline_function(state.func_ir, block, i, expr)
        return original

    monkeypatch.setattr(InlineInlinables, "_do_work", do_work_reading_it)
    assert inline_copies.numbas_callers() is None


def test_an_inline_function_shaped_otherwise_keeps_numbas_copies(monkeypatch):
    def inline_function_of_another_numba(self, caller_ir, block, i, function, arg_typs=None):
        callee_ir = self.run_frontend_and_cache(function)
        return self.inline_ir(
            caller_ir, block, i, callee_ir, function.__code__.co_freevars, arg_typs=arg_typs
        )

    monkeypatch.setattr(inline_closurecall, "copy", copy)  # as before an install
    monkeypatch.setattr(inline_closurecall.InlineWorker, "inline_function", inline_function_of_another_numba)
    assert not inline_copies.shaped_as_expected()


def test_installed_by_jassy_at_the_first_compile():
    import numba as nb

    import jassy  # noqa: F401 (installs it when numba first compiles)

    nb.njit(lambda x: x + 1)(1)
    assert isinstance(inline_closurecall.copy, inline_copies.ScopeSharingCopies)
    assert inline_closurecall.InlineWorker.inline_ir.shares_scope_copies
    assert inline_copies.install()  # a second install changes nothing


def test_an_inliner_shaped_otherwise_keeps_numbas_copies(monkeypatch):
    monkeypatch.setattr(inline_closurecall, "copy", object())  # not the copy module
    assert not inline_copies.shaped_as_expected()
    monkeypatch.setattr(ir.Block, "__init__", lambda self, scope, loc: setattr(self, "scopes", [scope]))
    monkeypatch.setattr(inline_closurecall, "copy", copy)
    assert not inline_copies.shaped_as_expected()


def test_an_inliner_whose_stand_in_block_cannot_be_made_keeps_numbas_copies(monkeypatch):
    """numba's ir.Scope taking other arguments makes the probe fail: not installed, no error."""

    def scope_of_another_numba(*args, **kwargs):
        raise TypeError("Scope() missing 1 required positional argument: 'kind'")

    monkeypatch.setattr(inline_closurecall, "copy", copy)  # as before an install
    monkeypatch.setattr(ir, "Scope", scope_of_another_numba)
    assert not inline_copies.shaped_as_expected()


def test_an_installer_that_raises_leaves_numba_as_it_is_and_the_next_runs():
    from jassy.jit import _InstallAtFirstCompile

    ran = []

    def raising():
        raise TypeError("numba shaped otherwise")

    listener = _InstallAtFirstCompile(raising, lambda: ran.append(True))
    listener.on_start(None)  # numba's first compile goes on
    assert ran == [True]


_COMPILE = """
import hashlib, sys
import jassy
from numba.core import event
assert "numba.core.inline_closurecall" not in sys.modules  # a warm process does not import it
if sys.argv[1] == "numba":  # numba's own copies and typing: nothing installed
    for listener in event._registered["numba:compile"]:
        if hasattr(listener, "installers"):
            listener.installers = ()
import numba as nb

BRANCHY_SOURCE
helper = nb.njit(inline="always")(_branchy)

@nb.njit(inline="always")
def middle(x, n):
    return helper(x, n) + helper(-x, n + 1)

@nb.njit
def kernel(x, n):
    return middle(x, n) * middle(x + 1.0, n)

kernel(1.5, 7)
from numba.core import inline_closurecall
from numba.core.types import functions
installed = hasattr(inline_closurecall.InlineWorker.inline_ir, "shares_scope_copies")
assert installed == hasattr(functions.BaseFunction.get_call_type, "numbas") == (sys.argv[1] == "jassy")
(signature,) = kernel.signatures
ir_text = kernel.inspect_llvm(signature)
print(len(ir_text), hashlib.sha256(ir_text.encode()).hexdigest())
"""


@pytest.mark.timeout(120)
def test_a_kernel_with_nested_inlined_helpers_compiles_to_the_same_llvm_ir(tmp_path):
    """The same kernel compiled in two fresh processes, with jassy's changes to numba's
    compile pipeline (shared scope copies, remembered typing: jassy.remembered_typing) and
    without: the same LLVM IR, character for character (the hash seed fixed: numba spells
    the fastmath flags in mangled names in set order)."""
    found = []
    for changes in ("jassy", "numba"):
        run = subprocess.run(
            [sys.executable, "-c", _COMPILE.replace("BRANCHY_SOURCE", inspect.getsource(_branchy)), changes],
            capture_output=True,
            text=True,
            timeout=110,
            env={**_python_env(), "NUMBA_CACHE_DIR": str(tmp_path), "PYTHONHASHSEED": "0"},
        )
        assert run.returncode == 0, run.stderr
        found.append(run.stdout.split())
    assert int(found[0][0]) > 1000
    assert found[0] == found[1]


def _python_env():
    import os

    return {k: v for k, v in os.environ.items() if k.startswith("PYTHON") or k in ("HOME", "PATH")}
