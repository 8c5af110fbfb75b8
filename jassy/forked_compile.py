"""Kernels compiled on two cores: a forked helper shares a cold start's compile units.

On a fresh install the first render compiles every numba kernel it calls, one after the
other (0.1-1 s of CPU each, almost all of it numba's typing and lowering in Python, which
one process cannot spread over cores). Kernels that do not call each other can be compiled
in different processes, and numba's cache (``cache=True``) carries them from one to the
other. :func:`compile_on_two_cores` takes a list of compile units (callables that compile,
or load, some kernels), forks one helper process and works through the list from both ends:
this process from the front, the helper from the back, each claiming a unit (in memory the
two share) before it runs it and passing over units the other has claimed, until none is
left. Then it waits for the helper and returns;
what the caller does next loads the helper's kernels from the cache instead of compiling
them.

The helper is forked only where that is safe and can help: a POSIX ``fork``, a single
thread in this process (``fork`` copies only the calling thread, so a lock held by another
one would stay held in the helper), more than one usable core, at least two units, numba's
JIT enabled, and not in a worker of ``multiprocessing`` (already one of several processes).
The helper writes only numba's cache files, which numba writes to a temporary name and
renames (jassy.jit locks the folder around numba's index update); it prints nothing,
ignores its own errors (this process then compiles what is missing) and leaves with
``os._exit``; this process always reaps it.

Before the fork this process compiles one trivial function, so that numba's one-off set-up
(typing and target contexts, LLVM) is inherited by the helper instead of being done again
there. The single-thread check (``threading.active_count()``) sees only threads started by
Python's threading module, not native threads a C library started on its own: those are not
checked.

The units of an offline render are listed by :func:`jassy.engines.coldstart.graph_units`,
those of the rigid step by :func:`physics.rigid.step_units.step_units`.
"""

from __future__ import annotations

import contextlib
import mmap
import multiprocessing
import os
import pickle
import threading
from collections.abc import Callable, Sequence
from typing import NamedTuple

import numpy as np

#: Claim marks of a unit in the shared memory (one byte a unit); DONE: the helper has finished
#: the unit (compiled, or given up on it).
FREE, MINE, HELPERS, DONE = 0, 1, 2, 3
#: True while units run (here, or in the helper): a unit that builds an engine neither forks
#: a helper nor asks for units of its own.
_running_units = False


class _Helper(NamedTuple):
    """The forked helper of the units running now: its process id and the claim marks."""

    pid: int
    claims: mmap.mmap


#: The helper while units run in this process (None in the helper itself, or with no helper).
_helper: _Helper | None = None


def may_fork_helper(units: Sequence[Callable[[], object]]) -> bool:
    """Whether :func:`compile_on_two_cores` would fork a helper for ``units`` here and now."""
    if _running_units or len(units) < 2 or not hasattr(os, "fork"):
        return False
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
    if threading.active_count() != 1 or cores < 2:
        return False
    if multiprocessing.parent_process() is not None:  # already one of several workers
        return False
    from numba.core import config

    return not config.DISABLE_JIT


def compile_on_two_cores(units: Sequence[Callable[[], object]]) -> bool:
    """Run every unit once, here and in a forked helper from the list's two ends (see the
    module docstring); False (and the units left to the caller's own code) if no helper
    may be forked. An exception of a unit run here propagates after the helper is reaped."""
    global _running_units, _helper
    if not may_fork_helper(units):
        return False
    _set_up_numba()
    claims = mmap.mmap(-1, len(units))  # anonymous and shared: the helper sees these bytes
    claims[0] = MINE  # this process starts at the front, the helper at the back
    pid = os.fork()
    if pid == 0:
        _help(units, claims)  # never returns
    _running_units, _helper = True, _Helper(pid, claims)
    try:
        units[0]()
        for i in range(1, len(units)):
            if claims[i] == FREE:
                claims[i] = MINE
                units[i]()
    finally:
        for i in range(len(units)):  # nothing left for the helper: it stops after its unit
            if claims[i] == FREE:
                claims[i] = MINE
        with contextlib.suppress(ChildProcessError):  # reaped already by a SIGCHLD handler of the host
            os.waitpid(pid, 0)
        claims.close()
        _running_units, _helper = False, None
    return True


def _set_up_numba() -> None:
    """Compile one trivial function (not cached): numba's one-off set-up of a process, about
    0.35 s of CPU, done once before the fork instead of in both processes."""
    import numba

    numba.njit(lambda values: values[0] + 1.0)(np.zeros(1))


def _help(units: Sequence[Callable[[], object]], claims: mmap.mmap) -> None:
    """The helper process: the free units from the back, silently; then exit."""
    global _running_units
    _running_units = True
    try:
        quiet = os.open(os.devnull, os.O_WRONLY)
        os.dup2(quiet, 1)
        os.dup2(quiet, 2)
        for i in reversed(range(len(units))):
            if claims[i] != FREE:  # taken by this process: the helper goes on past it
                continue
            claims[i] = HELPERS
            try:
                units[i]()
            finally:
                claims[i] = DONE
    except BaseException:  # noqa: BLE001 - the caller compiles whatever is missing
        pass
    finally:
        os._exit(0)


def helper_busy_with(unit: int) -> bool:
    """While units run in this process: whether the helper may still be working on unit
    ``unit`` (an index into the list given to :func:`compile_on_two_cores`, negative from its
    end). False once the helper has finished that unit (compiled or given up: its DONE mark)
    or has ended, and where there is no helper. The helper's exit is asked of the helper's
    process alone (``os.waitid`` on its pid, without reaping it), so other children of this
    process do not count; where os.waitid is missing (macOS before Python 3.13) only the mark
    counts."""
    helper = _helper
    if helper is None or helper.claims.closed:
        return False
    if helper.claims[unit] in (MINE, DONE):  # FREE: the helper takes it next, or ends
        return False
    if not hasattr(os, "waitid"):
        return True
    try:
        return os.waitid(os.P_PID, helper.pid, os.WEXITED | os.WNOHANG | os.WNOWAIT) is None
    except ChildProcessError:  # reaped already (by a SIGCHLD handler of the host)
        return False


def claim(unit: int) -> bool:
    """While units run: claim unit ``unit`` (an index into the list) for this process if
    nobody has taken it yet; True if it is now this process's to run (always, where there
    is no helper: in the helper itself, or with no helper forked)."""
    helper = _helper
    if helper is None or helper.claims.closed:
        return True
    if helper.claims[unit] != FREE:
        return False
    helper.claims[unit] = MINE
    return True


def running_units() -> bool:
    """Whether compile units run now, in this process (a unit must not fork or list units)."""
    return _running_units


def cache_holds(kernel) -> bool:
    """Whether numba's cache holds any compiled version of ``kernel`` (a ``numba.njit``
    dispatcher, or a plain function compiled by ``numba.cfunc``): its index, current for the
    kernel's source, names a data file that exists (numba 0.68's
    ``IndexDataCacheFile.save`` writes the index before the data file, so an index alone
    may name a kernel not yet loadable). False with the JIT off (``NUMBA_DISABLE_JIT``:
    nothing is compiled or cached); True for a numba without this cache layout, so that
    nothing is compiled ahead for it."""
    from numba import config
    from numba.core import caching

    if config.DISABLE_JIT:
        return False
    try:
        cache = kernel._cache if hasattr(kernel, "py_func") else caching.FunctionCache(kernel)
        files = cache._cache_file
        names = files._load_index().values()
        return any(os.path.exists(os.path.join(files._cache_path, name)) for name in names)
    except (AttributeError, RuntimeError):  # RuntimeError: no cache locator for its file
        return True
    except (OSError, EOFError, pickle.UnpicklingError):  # an unreadable index: numba compiles
        return False
