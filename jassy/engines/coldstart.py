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
(its node function with every kernel it calls), the heaviest first, then a modal bank's pole
design, and last a small stand-in render (a silent tap) that compiles the engine's own
kernels (the program's render loop, and event application and the output stage, which the loop
calls through their addresses: compiled once each, not again inside every loop that calls them).
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
#: True while units run (here, or in the helper): a unit that builds an engine (the stand-in)
#: neither forks a helper nor asks for units of its own.
_running_units = False


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
    (:func:`kernels_cached`) and the graph runs as a program."""
    from jassy import program
    from ugens.impact import ImpactForce
    from ugens.modal import ModalBank, direct_ratio

    if _running_units or graph.budget is not None or not engine_options.get("program", True):
        return []
    if kernels_cached():
        return []
    if program.why_not_compiled(graph) is not None:
        return []
    kinds = [type(node) for node in graph.order]
    # the heaviest kind first (this process starts there); the stand-in holds a tap alone
    order = sorted(dict.fromkeys(kinds), key=lambda kind: kind is not ModalBank)
    stand_in = ImpactForce in kinds
    units: list[Callable[[], object]] = [
        partial(program.node_function_address, program.PROGRAM_UGENS[kind])
        for kind in order
        if not (stand_in and kind is ImpactForce)
    ]
    if ModalBank in kinds:  # its pole design, compiled when a bank is prepared
        units.append(partial(direct_ratio, np.array([440.0]), np.array([1.0]), 48000.0, "band"))
    if stand_in:
        units.append(partial(_render_stand_in, bool(graph.haptic), engine_options))
    return units


def _render_stand_in(haptic: bool, engine_options: dict) -> None:
    """Render three blocks of a silent tap through an engine with the same options: the same
    kernel types as the real render's block loop, event application and output stage. (It
    holds no other kind and plays no event, which leaves the most to this process: the
    render loop is the largest unit.)"""
    from jassy.engines.offline import OfflineEngine
    from jassy.graph import Graph
    from ugens.impact import ImpactForce

    tap = ImpactForce(name="tap", duration=0.0008)
    engine = OfflineEngine(Graph(tap, haptic=tap if haptic else None), [], **engine_options)
    engine.render(3 * engine_options["block"] / engine_options["sample_rate"])


def kernels_cached() -> bool:
    """Whether numba's cache already holds the output stage's limiter, which every render
    calls (False on a fresh install, or after the cache was removed)."""
    from jassy.safety import limit

    try:
        return os.path.exists(limit._cache._cache_file._index_path)
    except AttributeError:  # a numba without this cache layout: say nothing
        return True
