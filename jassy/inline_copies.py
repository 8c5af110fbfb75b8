"""numba's inliner (``inline="always"``) copying a callee's variable scope once per IR copy.

To inline a callee numba copies its IR twice (a working copy it renames into the caller,
and an untouched one it returns), each with ``copy.deepcopy`` of one block at a time. Every
block refers to the function's one variable scope, so each block's copy also copies that
scope with every variable of the function: blocks x variables objects per copy. A large
callee that holds its own inlined helpers has hundreds of blocks and thousands of
variables, and in a first ``jassy render wok`` these copies were the largest single cost
of numba's own Python work. Here each block is still deep-copied on its own, but the
blocks of one IR copy share one copy of the scope (made the same way, by
``copy.deepcopy``), as the blocks of the IR they are copied from share theirs. A statement's
source location may hold its file's source lines (a list numba caches from ``linecache``
and only reads, to format messages); the copied locations share that list instead of
copying it, item by item, per block.

The copies hold the same statements, variables and names: numba reads a copied IR's scope
through its first block only (to rename the callee's variables into the caller, and for
SSA), and that block's scope is a copy of the same scope either way. Installed by
:mod:`jassy.jit` when numba first compiles in a process (importing numba's inliner costs
~0.15 s, which a process that only loads cached kernels does not pay); left out, with
numba's behaviour kept, if numba's inliner is not shaped as expected (see :func:`install`).

Checked against numba 0.68.1's ``numba/core/inline_closurecall.py``
(``InlineWorker.inline_ir`` and its inner ``copy_ir``, which copies the callee's IR block by
block with ``copy.deepcopy``, twice) and ``numba/core/ir.py`` (``Block``, ``Scope``).
"""

from __future__ import annotations

import copy
from contextlib import contextmanager
from typing import NamedTuple

from numba.core import ir


class ScopeCopy(NamedTuple):
    """A scope and its one copy for the blocks of an IR copy; the source is kept so that its
    id (the table's key) is not reused while the table lives."""

    source: ir.Scope
    copy: ir.Scope


class ScopeSharingCopies:
    """Stands in for the ``copy`` module inside ``numba.core.inline_closurecall``.

    Outside :meth:`sharing` (and for anything but a whole block) it is ``copy`` itself. While
    sharing, ``deepcopy(block)`` deep-copies the block with its scope replaced by one copy of
    that scope per source scope, made at its first block, and its statements' cached source
    lines kept as they are."""

    def __init__(self):
        self.scopes: dict[int, ScopeCopy] | None = None

    def __getattr__(self, name):
        return getattr(copy, name)

    def deepcopy(self, value, memo=None):
        if self.scopes is None or memo is not None or type(value) is not ir.Block:
            return copy.deepcopy(value, memo)
        source = value.scope
        found = self.scopes.get(id(source))
        if found is None:
            found = self.scopes[id(source)] = ScopeCopy(source, copy.deepcopy(source))
        memo = {id(source): found.copy}
        for statement in value.body:  # a location's cached source lines: shared, not copied
            lines = getattr(statement.loc, "lines", None)
            if lines is not None:
                memo[id(lines)] = lines
        return copy.deepcopy(value, memo)

    @contextmanager
    def sharing(self):
        """Share scope copies among the blocks copied inside this context (nestable: an
        inner context has its own table)."""
        outer, self.scopes = self.scopes, {}
        try:
            yield
        finally:
            self.scopes = outer


def shaped_as_expected() -> bool:
    """Whether numba's inliner copies IR as this module expects: the module's ``copy`` is the
    ``copy`` module (used only by ``InlineWorker.inline_ir``'s block copies) and blocks have
    the ``scope, body, loc`` attributes, with ``scope`` the function's :class:`numba.core.ir.Scope`
    (False too if the inliner's module is missing or the stand-in block cannot be made)."""
    try:
        from numba.core import inline_closurecall

        worker = getattr(inline_closurecall, "InlineWorker", None)
        if getattr(inline_closurecall, "copy", None) is not copy or worker is None:
            return False
        if not callable(getattr(worker, "inline_ir", None)):
            return False
        scope = ir.Scope(None, ir.Loc("stand-in", 1))
        block = ir.Block(scope, ir.Loc("stand-in", 1))
    except Exception:  # noqa: BLE001 (any other shape: keep numba's behaviour)
        return False
    return set(vars(block)) == {"scope", "body", "loc"} and hasattr(scope, "localvars")


def install() -> bool:
    """Make ``InlineWorker.inline_ir`` copy blocks with shared scope copies; True if installed
    (now or before), False if numba's inliner is shaped otherwise (numba's own copies stay)."""
    try:
        from numba.core import inline_closurecall
    except ImportError:  # moved in this numba
        return False
    worker = getattr(inline_closurecall, "InlineWorker", None)
    if getattr(getattr(worker, "inline_ir", None), "shares_scope_copies", False):
        return True
    if not shaped_as_expected():
        return False
    copies = ScopeSharingCopies()
    inline_ir = worker.inline_ir

    def inline_ir_sharing_scope_copies(self, *args, **kwargs):
        with copies.sharing():
            return inline_ir(self, *args, **kwargs)

    inline_ir_sharing_scope_copies.shares_scope_copies = True
    inline_closurecall.copy = copies
    worker.inline_ir = inline_ir_sharing_scope_copies
    return True
