"""A cold render's compile units (run by :func:`jassy.forked_compile.compile_on_two_cores`).

:func:`graph_units` gives the units of the graph of a
:class:`jassy.engines.offline.OfflineEngine`. For a graph that runs as a program: one per
kind of node the program holds (its node function with every kernel it calls), the heaviest
first, a modal bank's pole design, the render loop's two stages (event application and the
output stage: C functions the loop calls through their addresses, so each compiles on its
own) and last the render loop itself, compiled for its argument types without running (it
needs neither the graph nor the stages compiled). For a graph rendered node by node: a copy
of one node of each kind, fed by silence, prepared and run for a block and once more after
each kind of parameter change the score makes to it (a modal bank first: its pole design and
span kernel), the strike kernels and a stand-in render of a silent tap through an engine with
the same options (the block loop's and the output stage's kernels). :func:`program_cached`
says whether a graph's program functions are compiled already (``jassy render`` renders a
patch node by node until they are: the same bits, for a fraction of the compiling).
"""

from __future__ import annotations

import copy
import warnings
from collections.abc import Callable, Sequence
from functools import partial
from typing import NamedTuple

import numpy as np
from numba import config as nb_config

from jassy.forked_compile import cache_holds, running_units

#: Set once numba's cache was found filled (:func:`kernels_cached`).
_cache_found = False


def graph_units(graph, engine_options: dict, score: Sequence = ()) -> list[Callable[[], object]]:
    """Compile units of a render of ``graph`` through ``score`` by an OfflineEngine built
    with ``engine_options`` (its keyword arguments): empty unless numba's cache is still empty
    (:func:`kernels_cached`). Ordered so that the two ends meet with about half the work
    each: this process starts with the modal kernels (the largest unit), the helper with
    the engine's own kernels."""
    if running_units():
        return []
    return _units(graph, engine_options, score)


def compile_graph(graph, engine_options: dict, score: Sequence = (), part: slice = slice(None)) -> None:
    """Run the units of :func:`graph_units` in ``part`` (all by default) here, one after the
    other (nothing on a filled cache): for a compile unit that builds its graph itself, e.g.
    in a forked helper, since building some graphs starts threads (pyfftw's cache) that would
    keep a helper from being forked. Parts let two such units share a graph's units."""
    for unit in _units(graph, engine_options, score)[part]:
        unit()


def _units(graph, engine_options: dict, score: Sequence) -> list[Callable[[], object]]:
    """The units of :func:`graph_units`, whether or not units run now."""
    if graph.budget is not None or nb_config.DISABLE_JIT or kernels_cached():
        return []  # with the JIT off (NUMBA_DISABLE_JIT) nothing compiles
    from jassy import program

    if engine_options.get("program", True) and program.why_not_compiled(graph) is None:
        return _program_units(graph)
    return _node_units(graph, engine_options, score)


def _program_units(graph) -> list[Callable[[], object]]:
    """Units of a graph that runs as a program: its node functions, the modal bank at the
    front, then the output stage, the strike and pole-design kernels, event application and
    the render loop."""
    from jassy import program
    from jassy.engines import callback
    from ugens.impact import ImpactForce
    from ugens.modal import ModalBank

    kinds = sorted(dict.fromkeys(type(node) for node in graph.order), key=lambda kind: kind is not ModalBank)
    nodes = [partial(program.node_function_address, program.PROGRAM_UGENS[kind]) for kind in kinds]
    units: list[Callable[[], object]] = [*nodes[:1], callback.output_stage_address, *nodes[1:]]
    if ModalBank in kinds:
        units.append(_compile_pole_design)
    if ImpactForce in kinds:
        units.append(_compile_strike_records)
    return [*units, callback.next_cut_address, _compile_render_loop]


def _node_units(graph, engine_options: dict, score: Sequence) -> list[Callable[[], object]]:
    """Units of a graph rendered node by node: one node of each kind processed alone (a
    modal bank first) with the parameter changes the score makes to its kind, the strike
    kernels (with the pulse table's growth) and a stand-in render through an engine with
    the same options."""
    from ugens.impact import ImpactForce
    from ugens.modal import ModalBank

    kinds = {type(node): node for node in reversed(graph.order)}  # the first node of each kind
    firsts = sorted(kinds.values(), key=lambda node: not isinstance(node, ModalBank))
    changes = _score_changes(graph, score)
    rate, block = float(engine_options["sample_rate"]), engine_options["block"]
    units: list[Callable[[], object]] = [
        partial(_process_alone, node, rate, block, changes.get(type(node), [])) for node in firsts
    ]
    if ImpactForce in kinds:
        units.append(partial(_compile_strike_records, grow=True))
    return [*units, partial(_render_stand_in, bool(graph.haptic), engine_options)]


class Change(NamedTuple):
    """A parameter change of a score's ``set`` event: new values by name, whether it jumps,
    its ramp (s, or None for the node's own smoothing)."""

    values: dict
    jump: bool
    ramp: float | None


def _score_changes(graph, score: Sequence) -> dict[type, list[Change]]:
    """Per kind of node, one Change of each shape (the keys it sets, jump or not, with a
    ramp or not) among the score's ``set`` events on nodes of that kind."""
    shapes: dict[type, dict[tuple, Change]] = {}
    for event in score:
        node = graph.nodes.get(event.node) if event.action == "set" else None
        if node is not None:
            shape = (tuple(sorted(event.args)), bool(event.jump), event.ramp is None)
            kind = shapes.setdefault(type(node), {})
            kind.setdefault(shape, Change(dict(event.args), bool(event.jump), event.ramp))
    return {kind: list(found.values()) for kind, found in shapes.items()}


class _Silence:
    """A silent input for :func:`_process_alone`: an output buffer of zeros."""

    def __init__(self, block: int):
        self.out = np.zeros(block)
        self.extra: dict[str, np.ndarray] = {}


def _process_alone(node, sample_rate: float, block: int, changes: Sequence[Change] = ()) -> None:
    """Compile the kernels ``node`` calls by preparing a copy of it fed by silence and
    processing a block, then a block after each of ``changes`` (applied at that block's
    first frame, as the scheduler applies a score's events): the same kernels, for the same
    argument types, as the render (a modal bank: its pole design and its span kernel; a
    ramped change: the ramp's kernels). The node itself is not touched. A node that cannot
    run alone (an input it reads more of than its output) is left to the render, which
    compiles its kernels as it meets them."""
    silence = {id(source): _Silence(block) for source in node.sources.values()}
    try:
        with warnings.catch_warnings(), np.errstate(all="ignore"):  # silence may be out of range
            warnings.simplefilter("ignore")
            _run_alone(copy.deepcopy(node, silence), sample_rate, block, changes)
    except Exception:  # noqa: BLE001 - compiling ahead is an optimisation; the render reports errors
        pass


def _run_alone(alone, sample_rate: float, block: int, changes: Sequence[Change]) -> None:
    """Prepare node ``alone`` and process a block, then a block after each change."""
    alone.prepare(sample_rate, block)
    alone.process(0, block)
    for i, change in enumerate(changes, start=1):
        for key, value in change.values.items():
            if alone.inline_events:
                alone.set_param_at(i * block, key, value, change.jump, change.ramp)
            else:
                alone.set_param(key, value, jump=change.jump, ramp=change.ramp)
        alone.process(i * block, block)


def _compile_pole_design() -> None:
    """Compile a modal bank's pole design (ugens.modal_retune.pole_rows, with the
    ``"band"`` direct ratio), which preparing a bank runs."""
    from ugens.modal import direct_ratio

    direct_ratio(np.array([440.0]), np.array([1.0]), 48000.0, "band")


def _render_stand_in(haptic: bool, engine_options: dict) -> None:
    """Render three blocks of a silent tap node by node through an engine with the same
    options: the block loop's and the output stage's kernels, for the types of the real
    render (the tap's pulses too)."""
    from jassy.engines.offline import OfflineEngine
    from jassy.graph import Graph
    from ugens.impact import ImpactForce

    tap = ImpactForce(name="tap", duration=0.0008)
    options = {**engine_options, "program": False}
    engine = OfflineEngine(Graph(tap, haptic=tap if haptic else None), [], **options)
    engine.render(3 * options["block"] / options["sample_rate"])


def _compile_strike_records(grow: bool = False) -> None:
    """Compile the kernels that translating a strike calls from Python: its pulse's
    amplitude and the growth of the tap's pulse table (as an event record for the program;
    with ``grow``, the table's row appended as ImpactForce.add_pulse does node by node)."""
    from ugens.cells import PULSE_COLUMNS, append_pulse, pulse_amplitude, with_room

    pulse_amplitude(1.0, 48000.0, 0.5, 2.0)
    with_room(np.zeros((1, 3)), 1)
    if grow:
        append_pulse(np.zeros((1, PULSE_COLUMNS)), 0, 0.5, 2.0, 1.0)


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


def program_cached(graph) -> bool:
    """Whether numba's cache holds every function a render of ``graph`` as a program compiles
    (and a render node by node does not): its node kinds' node functions, event application,
    the output stage and the offline render loop (jassy.engines.program_offline.render_planar).
    A render as a program would then load them instead of compiling them. False for a graph
    that cannot run as a program."""
    from jassy import program
    from jassy.engines import callback
    from jassy.engines.program_offline import render_planar

    if program.why_not_compiled(graph) is not None:
        return False
    kinds = {program.PROGRAM_UGENS[type(node)] for node in graph.order}
    functions = [program.NODE_FUNCTIONS[kind] for kind in sorted(kinds)]
    stages = [callback._next_cut_entry, callback._output_stage, render_planar]
    return all(cache_holds(function) for function in [*functions, *stages])


def kernels_cached() -> bool:
    """Whether numba's cache already holds the output stage's limiter, which every program
    render compiles (inside the compiled output stage, limiter on or off), or the output
    scan every node-by-node render calls (False on a fresh install, or after the cache was
    removed). Once found, the answer is kept for the process (no file check per render)."""
    global _cache_found
    if _cache_found:
        return True
    from jassy.safety import limit, scan_chunk

    # a numba without this cache layout: say nothing
    _cache_found = cache_holds(limit) or cache_holds(scan_chunk)
    return _cache_found
