"""numba's inliner (``inline="always"``) without the IR copies nobody reads.

To inline a callee numba copies its IR twice with ``copy.deepcopy``, one block at a time: a
working copy it renames into the caller, and an untouched copy it returns, which numba's own
inlining passes discard. For a function inlined by ``inline="always"`` the IR it copies was
translated for this one inline a moment before and is read by nothing else. In a first
``jassy render wok`` these copies were the largest single cost of numba's own Python work.
Here, while numba's inliner runs:

* the blocks of a freshly translated callee are handed over as they are (no working copy);
* the untouched copy is skipped (its blocks are the working copy's) when the caller is one
  of numba's two inlining passes, which store it in ``_`` and never read it (checked in
  their bytecode at install); any other caller gets its independent copy;
* each block still copied is deep-copied on its own, but the blocks of one copy share one
  copy of the function's variable scope (each block's copy used to copy the whole scope:
  blocks x variables objects), as the blocks they are copied from share theirs, and the
  statements' cached source lines (a list numba takes from ``linecache`` and only reads)
  are shared, not copied.

The working IR holds the same statements, variables and names either way: numba reads a
copied IR's scope through its first block only (to rename the callee's variables into the
caller, and for SSA), and renames every variable of the callee's scope into the caller's.
Installed by :mod:`jassy.jit` when numba first compiles in a process (importing numba's
inliner costs ~0.15 s, which a process that only loads cached kernels does not pay); left
out, with numba's behaviour kept, if numba's inliner or its callers are not shaped as
expected (see :func:`install`).

Checked against numba 0.68.1's ``numba/core/inline_closurecall.py``
(``InlineWorker.inline_ir`` and its inner ``copy_ir``, which copies the callee's IR block by
block with ``copy.deepcopy``, twice; ``InlineWorker.inline_function``, which translates the
callee and passes it to ``inline_ir``), ``numba/core/untyped_passes.py``
(``InlineInlinables._do_work``), ``numba/core/typed_passes.py``
(``InlineOverloads._run_inliner``) and ``numba/core/ir.py`` (``Block``, ``Scope``).
"""

from __future__ import annotations

import copy
import dis
import sys
from collections.abc import Callable, Iterable
from contextlib import contextmanager
from typing import NamedTuple

from numba.core import ir


class ScopeCopy(NamedTuple):
    """A scope and its one copy for the blocks of an IR copy; the source is kept so that its
    id (the table's key) is not reused while the table lives."""

    source: ir.Scope
    copy: ir.Scope


class InlineCopies(NamedTuple):
    """What one run of numba's inliner copies, by block id: the handed-over blocks (not
    copied: a fresh translation), the working copy's blocks (the handed-over ones included),
    whether the untouched copy is discarded, and one scope copy per source scope."""

    handed_over: dict[int, ir.Block]
    working: dict[int, ir.Block]
    discarded: bool
    scopes: dict[int, ScopeCopy]


class ScopeSharingCopies:
    """Stands in for the ``copy`` module inside ``numba.core.inline_closurecall``.

    Outside :meth:`sharing` (and for anything but a whole block) it is ``copy`` itself. While
    sharing, ``deepcopy(block)`` returns a handed-over block as it is the first time (the
    working copy), a working copy's block as it is if the untouched copy is discarded, and
    otherwise deep-copies the block with its scope replaced by one copy of that scope per
    source scope, made at its first block, and its statements' cached source lines kept as
    they are."""

    def __init__(self):
        self.run: InlineCopies | None = None

    def __getattr__(self, name):
        return getattr(copy, name)

    def deepcopy(self, value, memo=None):
        run = self.run
        if run is None or memo is not None or type(value) is not ir.Block:
            return copy.deepcopy(value, memo)
        key = id(value)
        if key in run.working:  # asked for the untouched copy
            return value if run.discarded else self._copied(value, run)
        if key in run.handed_over:  # asked for the working copy of a fresh translation
            run.working[key] = value
            return value
        copied = self._copied(value, run)
        run.working[id(copied)] = copied
        return copied

    @staticmethod
    def _copied(block: ir.Block, run: InlineCopies) -> ir.Block:
        source = block.scope
        found = run.scopes.get(id(source))
        if found is None:
            found = run.scopes[id(source)] = ScopeCopy(source, copy.deepcopy(source))
        memo = {id(source): found.copy}
        for statement in block.body:  # a location's cached source lines: shared, not copied
            lines = getattr(statement.loc, "lines", None)
            if lines is not None:
                memo[id(lines)] = lines
        return copy.deepcopy(block, memo)

    @contextmanager
    def sharing(self, handed_over: Iterable[ir.Block] = (), discarded: bool = False):
        """One run of numba's inliner: share scope copies among the blocks copied inside this
        context, hand over ``handed_over`` as the working copy, skip the untouched copy if
        ``discarded`` (nestable: an inner context has its own tables)."""
        outer = self.run
        self.run = InlineCopies({id(block): block for block in handed_over}, {}, discarded, {})
        try:
            yield
        finally:
            self.run = outer


def discards_first_result(function: Callable, callee: str) -> bool:
    """Whether ``function`` names ``callee`` once, its next call is that call, whose result
    is unpacked into four names, the first ``_``, and ``_`` is never read (numba's inlining
    passes: ``_, _, _, new_blocks = inline_worker.inline_ir(...)``)."""
    instructions = list(dis.get_instructions(function))
    named = [k for k, ins in enumerate(instructions) if ins.argval == callee]
    if len(named) != 1 or any(ins.opname.startswith("LOAD") and ins.argval == "_" for ins in instructions):
        return False
    after = instructions[named[0] + 1 :]
    call = next((k for k, ins in enumerate(after) if ins.opname.startswith("CALL")), None)
    if call is None or call + 2 >= len(after):
        return False
    unpack, first = after[call + 1], after[call + 2]
    return (
        unpack.opname == "UNPACK_SEQUENCE"
        and unpack.arg == 4
        and first.opname.startswith("STORE")
        and first.argval == "_"
    )


class Callers(NamedTuple):
    """numba's inlining passes' functions that call the inliner and discard its untouched
    copy, by code object: ``InlineInlinables._do_work`` (through ``inline_function``) and
    ``InlineOverloads._run_inliner`` (``inline_ir`` directly)."""

    inlinables: object
    overloads: object


def numbas_callers() -> Callers | None:
    """numba's inlining passes' code objects, if each calls the inliner once and discards
    the untouched copy; None otherwise (the untouched copy is then always made)."""
    try:
        from numba.core.typed_passes import InlineOverloads
        from numba.core.untyped_passes import InlineInlinables

        do_work, run_inliner = InlineInlinables._do_work, InlineOverloads._run_inliner
        if discards_first_result(do_work, "inline_function") and discards_first_result(
            run_inliner, "inline_ir"
        ):
            return Callers(do_work.__code__, run_inliner.__code__)
    except Exception:  # noqa: BLE001 (any other shape: numba's copies)
        pass
    return None


#: The names ``InlineWorker.inline_function`` reads in numba 0.68.1: it translates the
#: function (``run_untyped_passes``) and inlines that IR (``inline_ir``), nothing else.
INLINE_FUNCTION_NAMES = ("run_untyped_passes", "__code__", "co_freevars", "inline_ir")


def shaped_as_expected() -> bool:
    """Whether numba's inliner copies IR as this module expects: the module's ``copy`` is the
    ``copy`` module (used only by ``InlineWorker.inline_ir``'s block copies), ``inline_ir``
    copies through an inner ``copy_ir``, ``inline_function`` only translates and inlines,
    and blocks have the ``scope, body, loc`` attributes, with ``scope`` the function's
    :class:`numba.core.ir.Scope` (False too if the inliner's module is missing or the
    stand-in block cannot be made)."""
    try:
        from numba.core import inline_closurecall

        worker = getattr(inline_closurecall, "InlineWorker", None)
        if getattr(inline_closurecall, "copy", None) is not copy or worker is None:
            return False
        inline_ir, inline_function = worker.inline_ir, worker.inline_function
        inner = {getattr(c, "co_name", None) for c in inline_ir.__code__.co_consts}
        if "copy_ir" not in inner or inline_function.__code__.co_names != INLINE_FUNCTION_NAMES:
            return False
        scope = ir.Scope(None, ir.Loc("stand-in", 1))
        block = ir.Block(scope, ir.Loc("stand-in", 1))
    except Exception:  # noqa: BLE001 (any other shape: keep numba's behaviour)
        return False
    return set(vars(block)) == {"scope", "body", "loc"} and hasattr(scope, "localvars")


def install() -> bool:
    """Make numba's inliner hand over fresh translations, skip the untouched copy its own
    passes discard and share scope copies; True if installed (now or before), False if
    numba's inliner is shaped otherwise (numba's own copies stay). If numba's passes are
    shaped otherwise only the untouched copy is always made."""
    try:
        from numba.core import inline_closurecall
    except ImportError:  # moved in this numba
        return False
    worker = getattr(inline_closurecall, "InlineWorker", None)
    if getattr(getattr(worker, "inline_ir", None), "shares_scope_copies", False):
        return True
    if not shaped_as_expected():
        return False
    copies, callers = ScopeSharingCopies(), numbas_callers()
    inline_ir = worker.inline_ir

    def inline_ir_sharing_scope_copies(self, *args, **kwargs):
        discarded = callers is not None and sys._getframe(1).f_code is callers.overloads
        with copies.sharing(discarded=discarded):
            return inline_ir(self, *args, **kwargs)

    def inline_function_handing_over(self, caller_ir, block, i, function, arg_typs=None):
        if type(self).inline_ir is not inline_ir_sharing_scope_copies:  # a subclass's own
            return self.inline_ir(caller_ir, block, i, self.run_untyped_passes(function),
                                  function.__code__.co_freevars, arg_typs=arg_typs)  # fmt: skip
        callee_ir = self.run_untyped_passes(function)
        discarded = callers is not None and sys._getframe(1).f_code is callers.inlinables
        with copies.sharing(handed_over=callee_ir.blocks.values(), discarded=discarded):
            return inline_ir(
                self, caller_ir, block, i, callee_ir, function.__code__.co_freevars, arg_typs=arg_typs
            )

    inline_ir_sharing_scope_copies.shares_scope_copies = True
    inline_closurecall.copy = copies
    worker.inline_ir = inline_ir_sharing_scope_copies
    worker.inline_function = inline_function_handing_over
    return True
