"""A cold render's kernels compiled on two cores.

On a fresh install the first render compiles every numba kernel it calls, one after the
other (0.1-1 s of CPU each, almost all of it numba's typing and lowering in Python, which
one process cannot spread over cores). Kernels that do not call each other can be compiled
in different processes, and numba's cache (``cache=True``) carries them from one to the
other. :func:`compile_on_two_cores` takes a list of compile units (callables that compile,
or load, some kernels), forks one helper process and works through the list from both ends:
this process from the front, the helper from the back, each claiming a unit (in memory the
two share) before it runs it, until they meet. Then it waits for the helper and returns;
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

:func:`graph_units` gives the units of the graph of a
:class:`jassy.engines.offline.OfflineEngine`: one per kind of node the graph's program holds
(its node function with every kernel it calls), the heaviest first, a modal bank's pole
design, the render loop's two stages (event application and the output stage: C functions
the loop calls through their addresses, so each compiles on its own) and last the render
loop itself, compiled for its argument types without running (it needs neither the graph
nor the stages compiled). Before the fork this process compiles one trivial function, so
that numba's one-off set-up (typing and target contexts, LLVM) is inherited by the helper
instead of being done again there.
"""

from __future__ import annotations

import mmap
import multiprocessing
import os
import threading
from collections.abc import Callable, Sequence
from functools import partial

import numpy as np

#: Claim marks of a unit in the shared memory.
FREE, MINE, HELPERS = 0, 1, 2
#: True while units run (here, or in the helper): a unit that builds an engine neither forks
#: a helper nor asks for units of its own.
_running_units = False
#: Set once numba's cache was found filled (:func:`kernels_cached`).
_cache_found = False


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
    global _running_units
    if not may_fork_helper(units):
        return False
    _set_up_numba()
    claims = mmap.mmap(-1, len(units))  # anonymous and shared: the helper sees these bytes
    claims[0] = MINE  # this process starts at the front, the helper at the back
    pid = os.fork()
    if pid == 0:
        _help(units, claims)  # never returns
    _running_units = True
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
        os.waitpid(pid, 0)
        claims.close()
        _running_units = False
    return True


def _set_up_numba() -> None:
    """Compile one trivial function (not cached): numba's one-off set-up of a process, about
    0.35 s of CPU, done once before the fork instead of in both processes."""
    import numba

    numba.njit(lambda values: values[0] + 1.0)(np.zeros(1))


def _help(units: Sequence[Callable[[], object]], claims: mmap.mmap) -> None:
    """The helper process: units from the back while they are free, silently; then exit."""
    global _running_units
    _running_units = True
    try:
        quiet = os.open(os.devnull, os.O_WRONLY)
        os.dup2(quiet, 1)
        os.dup2(quiet, 2)
        for i in reversed(range(len(units))):
            if claims[i] != FREE:
                break
            claims[i] = HELPERS
            units[i]()
    except BaseException:  # noqa: BLE001 - the caller compiles whatever is missing
        pass
    finally:
        os._exit(0)


def graph_units(graph, engine_options: dict) -> list[Callable[[], object]]:
    """Compile units of a render of ``graph`` by an OfflineEngine built with
    ``engine_options`` (its keyword arguments): empty unless numba's cache is still empty
    (:func:`kernels_cached`) and the graph runs as a program. Ordered so that the two ends
    meet with about half the work each: this process starts with the modal node function
    (the largest unit) and the output stage, the helper with the render loop and event
    application."""
    if _running_units or graph.budget is not None or not engine_options.get("program", True):
        return []
    if kernels_cached():
        return []
    from jassy import program
    from jassy.engines import callback
    from ugens.impact import ImpactForce
    from ugens.modal import ModalBank, direct_ratio

    if program.why_not_compiled(graph) is not None:
        return []
    kinds = sorted(dict.fromkeys(type(node) for node in graph.order), key=lambda kind: kind is not ModalBank)
    nodes = [partial(program.node_function_address, program.PROGRAM_UGENS[kind]) for kind in kinds]
    units: list[Callable[[], object]] = [*nodes[:1], callback.output_stage_address, *nodes[1:]]
    if ModalBank in kinds:  # its pole design, compiled when a bank is prepared
        units.append(partial(direct_ratio, np.array([440.0]), np.array([1.0]), 48000.0, "band"))
    if ImpactForce in kinds:
        units.append(_compile_strike_records)
    return [*units, callback.next_cut_address, _compile_render_loop]


def _compile_strike_records() -> None:
    """Compile the kernels that translating a strike into an event record calls from Python
    (its pulse's amplitude, the growth of the tap's pulse table)."""
    from ugens.cells import pulse_amplitude, with_room

    pulse_amplitude(1.0, 48000.0, 0.5, 2.0)
    with_room(np.zeros((1, 3)), 1)


def _compile_render_loop() -> None:
    """Compile the offline render loop (jassy.engines.program_offline.render_planar, with the
    program runner and the channel delays it calls) for the argument types the engine passes,
    without running it."""
    from jassy.engines.callback import CONTROL
    from jassy.engines.program_offline import render_planar
    from jassy.haptics import ChannelDelay
    from jassy.jit import specialise

    delay = ChannelDelay(np.zeros(1, dtype=np.int64))
    control = np.zeros(CONTROL, dtype=np.int64)
    out = np.zeros((1, 1))
    specialise(render_planar, control, out, 0, 0, delay.active, delay.history, delay.delays, delay.pos)


def kernels_cached() -> bool:
    """Whether numba's cache already holds the output stage's limiter, which every render
    calls (False on a fresh install, or after the cache was removed). Once found, the
    answer is kept for the process (no file check per render)."""
    global _cache_found
    if _cache_found:
        return True
    from jassy.safety import limit

    try:
        _cache_found = os.path.exists(limit._cache._cache_file._index_path)
    except AttributeError:  # a numba without this cache layout: say nothing
        _cache_found = True
    return _cache_found
