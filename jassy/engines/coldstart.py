"""A cold render's compile units (run by :func:`jassy.forked_compile.compile_on_two_cores`).

:func:`graph_units` gives the units of the graph of a
:class:`jassy.engines.offline.OfflineEngine`: one per kind of node the graph's program holds
(its node function with every kernel it calls), the heaviest first, a modal bank's pole
design, the render loop's two stages (event application and the output stage: C functions
the loop calls through their addresses, so each compiles on its own) and last the render
loop itself, compiled for its argument types without running (it needs neither the graph
nor the stages compiled).
"""

from __future__ import annotations

from collections.abc import Callable
from functools import partial

import numpy as np

from jassy.forked_compile import cache_holds, running_units

#: Set once numba's cache was found filled (:func:`kernels_cached`).
_cache_found = False


def graph_units(graph, engine_options: dict) -> list[Callable[[], object]]:
    """Compile units of a render of ``graph`` by an OfflineEngine built with
    ``engine_options`` (its keyword arguments): empty unless numba's cache is still empty
    (:func:`kernels_cached`) and the graph runs as a program. Ordered so that the two ends
    meet with about half the work each: this process starts with the modal node function
    (the largest unit) and the output stage, the helper with the render loop and event
    application."""
    if running_units() or graph.budget is not None or not engine_options.get("program", True):
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

    _cache_found = cache_holds(limit)  # a numba without this cache layout: say nothing
    return _cache_found
