"""jassy.inline_copies: numba's inliner copies a callee's scope once per IR copy, and the
compiled code is the same as with numba's own copies (one scope copy per block)."""

import copy
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

@nb.njit(inline="always")
def helper(x, n):
    total = 0.0
    for i in range(n):
        if x > i:
            total += x * i
        elif x < -i:
            total -= x
        else:
            for j in range(i):
                total += j * 0.5
    return total

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
            [sys.executable, "-c", _COMPILE, changes],
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
