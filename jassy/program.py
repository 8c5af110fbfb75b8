"""A patch graph compiled into one numba function: the graph's *program*.

:class:`Program` turns a prepared graph's topological order into an int64 table with one
record per node: its kind, the address of its kind's compiled node function, and the
addresses and sizes of its output buffer, its inputs' buffers and its own state arrays. One
numba function, :func:`run_program`, walks the table and calls each node's function, which
runs the node's kernel on the node's own arrays for a sub-block. Node functions are compiled
per kind when a program first holds that kind, so a first render compiles only the kernels
of the kinds its graph uses. They call the same kernels, on the same arrays, as the ugens'
``process`` (so the same output bits). Because the table holds raw addresses, the same
function runs inside the PortAudio callback (a ``@cfunc`` that never takes the GIL, see
jassy.callback) and offline, where :func:`run_blocks` renders every whole block up to the
next event in one call (no Python per block).

Ugens with a kernel here: :data:`PROGRAM_UGENS`. A graph holding any other node, a feedback
delay, an anytime budget or a contact that follows physics curves keeps the per-node Python
path; :func:`why_not_compiled` says why. In a program a ModalBank's parameter events split
the graph's sub-block at their frame (the split its own ``process`` makes inline), which
leaves every other node's output unchanged: their kernels are sample by sample.
"""

from __future__ import annotations

import numba as nb
import numpy as np
from llvmlite import ir as llvmir
from numba.core import cgutils, types
from numba.extending import intrinsic

from jassy import params
from jassy.graph import Graph
from jassy.jit import drop_stale_cache
from jassy.params import ramp_fill
from ugens import cells, filters, impact, mix, modal, noise, pressure, radiation, scrape
from ugens.filters import Biquad, biquad, biquad_ramp, design_biquad
from ugens.impact import ImpactForce, render_pulses
from ugens.mix import Gain, Mixer, Multiply, accumulate, multiply, scale, scale_ramp
from ugens.modal import ModalBank, bank_step, resonate_ramp
from ugens.pressure import SoundPressure, sound_pressure
from ugens.radiation import Radiation, radiate
from ugens.scrape import ResonantScrape, Scrape, profile_contact, resonant_noise

#: The modules whose kernels the program calls (a change there drops its numba cache).
KERNEL_MODULES = [params, cells, filters, impact, mix, modal, noise, pressure, radiation, scrape]
drop_stale_cache(__file__, KERNEL_MODULES)

#: int64 slots per node record; the last holds the address of its kind's compiled function.
RECORD = 16
FUNCTION = RECORD - 1
GAIN, MIXER, MULTIPLY, IMPACT, MODAL, SCRAPE, RESONANT_SCRAPE, BIQUAD, RADIATION = range(1, 10)
SOUND_PRESSURE = 10
#: Ugen classes with a kernel in the program, by kind.
PROGRAM_UGENS = {
    Gain: GAIN,
    Mixer: MIXER,
    Multiply: MULTIPLY,
    ImpactForce: IMPACT,
    ModalBank: MODAL,
    Scrape: SCRAPE,
    ResonantScrape: RESONANT_SCRAPE,
    Biquad: BIQUAD,
    Radiation: RADIATION,
    SoundPressure: SOUND_PRESSURE,
}


@intrinsic
def void_pointer(typingctx, address):
    """The int64 ``address`` as a ``void *`` (for numba.carray)."""
    sig = types.voidptr(types.int64)

    def codegen(context, builder, signature, args):
        return builder.inttoptr(args[0], cgutils.voidptr_t)

    return sig, codegen


# The array views below are inlined into the program: called with literal sizes they would
# otherwise be compiled once per size.
@nb.njit(cache=True, nogil=True, inline="always")
def _f64(address, size):
    return nb.carray(void_pointer(address), (size,), np.float64)


@nb.njit(cache=True, nogil=True, inline="always")
def _f64_rows(address, rows, size):
    return nb.carray(void_pointer(address), (rows, size), np.float64)


@nb.njit(cache=True, nogil=True, inline="always")
def _i64(address, size):
    return nb.carray(void_pointer(address), (size,), np.int64)


@nb.njit(cache=True, nogil=True, inline="always")
def _u64(address, size):
    return nb.carray(void_pointer(address), (size,), np.uint64)


# One function per node kind, compiled (as a C-callable function) only when a program holds
# that kind: a graph compiles the kernels it uses, not every kind's. Each reads its record
# from the table at address ``table`` (see Program), for frames start .. start + n - 1.


def _gain(table, base, start, n):  # [input, ramp, per-sample gains]
    prog = _i64(table, base + RECORD)
    size = prog[base + 2]
    out = _f64(prog[base + 1], size)
    x = _f64(prog[base + 3], size)
    ramp = _f64(prog[base + 4], 4)
    if ramp[3] == 0:
        scale(x, out, n, ramp[0])
    else:
        gains = _f64(prog[base + 5], size)
        ramp_fill(ramp, gains, n)
        scale_ramp(x, out, n, gains)


def _mixer(table, base, start, n):  # [count, input addresses, gains]
    prog = _i64(table, base + RECORD)
    size = prog[base + 2]
    out = _f64(prog[base + 1], size)
    m = prog[base + 3]
    sources = _i64(prog[base + 4], m)
    gains = _f64(prog[base + 5], m)
    scale(_f64(sources[0], size), out, n, gains[0])
    for j in range(1, m):
        accumulate(_f64(sources[j], size), out, n, gains[j])


def _multiply(table, base, start, n):  # [a, b]
    prog = _i64(table, base + RECORD)
    size = prog[base + 2]
    multiply(_f64(prog[base + 3], size), _f64(prog[base + 4], size), _f64(prog[base + 1], size), n)


def _impact(table, base, start, n):  # [pulses, pulse capacity, count]
    prog = _i64(table, base + RECORD)
    out = _f64(prog[base + 1], prog[base + 2])
    pulses = _f64_rows(prog[base + 3], prog[base + 4], 3)
    count = _i64(prog[base + 5], 1)
    count[0] = render_pulses(out, start, n, pulses, count[0])


def _modal(table, base, start, n):  # [input, bank, modes, delta, target, meta, last, floor]
    prog = _i64(table, base + RECORD)
    size = prog[base + 2]
    out = _f64(prog[base + 1], size)
    k = prog[base + 5]
    force = _f64(prog[base + 3], size)
    bank = _f64_rows(prog[base + 4], 6, k)
    meta = _i64(prog[base + 8], 3)
    last = _f64(prog[base + 9], 1)
    if meta[1] > 0:  # ramping
        meta[0] = meta[2]
        delta = _f64_rows(prog[base + 6], 4, k)
        target = _f64_rows(prog[base + 7], 4, k)
        meta[1] = resonate_ramp(
            force, out, n, bank[:4], bank[4], bank[5], delta, target, meta[1], meta[0], last
        )
    else:
        bank_step(force, out, start, n, bank, meta, _f64(prog[base + 10], 1)[0], last)


def _scrape(
    table, base, start, n
):  # [force ramp, speed ramp, forces, speeds, profile, length, state, coef, cfg]
    prog = _i64(table, base + RECORD)
    size = prog[base + 2]
    forces = _f64(prog[base + 5], size)
    speeds = _f64(prog[base + 6], size)
    ramp_fill(_f64(prog[base + 3], 4), forces, n)
    ramp_fill(_f64(prog[base + 4], 4), speeds, n)
    profile_contact(
        _f64(prog[base + 1], size),
        n,
        forces,
        speeds,
        _f64(prog[base + 7], prog[base + 8]),
        _f64(prog[base + 9], 4),
        _f64(prog[base + 10], 5),
        _f64(prog[base + 11], 9),
    )


def _resonant_scrape(table, base, start, n):  # [force ramp, speed ramp, forces, speeds, rng, state, cfg]
    prog = _i64(table, base + RECORD)
    size = prog[base + 2]
    forces = _f64(prog[base + 5], size)
    speeds = _f64(prog[base + 6], size)
    ramp_fill(_f64(prog[base + 3], 4), forces, n)
    ramp_fill(_f64(prog[base + 4], 4), speeds, n)
    resonant_noise(
        _f64(prog[base + 1], size),
        n,
        forces,
        speeds,
        _u64(prog[base + 7], 1),
        _f64(prog[base + 8], 8),
        _f64(prog[base + 9], 10),
    )


def _biquad(table, base, start, n):  # [input, freq ramp, q ramp, freqs, qs, coef, state, (mode, 1/fs)]
    prog = _i64(table, base + RECORD)
    size = prog[base + 2]
    out = _f64(prog[base + 1], size)
    x = _f64(prog[base + 3], size)
    freq = _f64(prog[base + 4], 4)
    q = _f64(prog[base + 5], 4)
    coef = _f64(prog[base + 8], 5)
    state = _f64(prog[base + 9], 2)
    setup = _f64(prog[base + 10], 2)
    mode = int(setup[0])
    if freq[3] == 0 and q[3] == 0:
        biquad(x, out, n, coef, state)
    else:
        freqs = _f64(prog[base + 6], size)
        qs = _f64(prog[base + 7], size)
        ramp_fill(freq, freqs, n)
        ramp_fill(q, qs, n)
        biquad_ramp(x, out, n, mode, freqs, qs, setup[1], coef, state)
        if freq[3] == 0 and q[3] == 0:  # the ramps just ended: coefficients for the targets
            design_biquad(mode, freq[0], q[0], setup[1], coef)


def _radiation(table, base, start, n):  # [input, coef, state]
    prog = _i64(table, base + RECORD)
    size = prog[base + 2]
    radiate(
        _f64(prog[base + 3], size),
        _f64(prog[base + 1], size),
        n,
        _f64(prog[base + 4], 4),
        _f64(prog[base + 5], 3),
    )


def _sound_pressure(table, base, start, n):  # [input, coef, state, setup]
    prog = _i64(table, base + RECORD)
    size = prog[base + 2]
    x = _f64(prog[base + 3], size)
    out = _f64(prog[base + 1], size)
    sound_pressure(x, out, n, _f64(prog[base + 4], 3), _f64(prog[base + 5], 3), _f64(prog[base + 6], 3))


#: Each kind's node function, by kind.
NODE_FUNCTIONS = {
    GAIN: _gain,
    MIXER: _mixer,
    MULTIPLY: _multiply,
    IMPACT: _impact,
    MODAL: _modal,
    SCRAPE: _scrape,
    RESONANT_SCRAPE: _resonant_scrape,
    BIQUAD: _biquad,
    RADIATION: _radiation,
    SOUND_PRESSURE: _sound_pressure,
}
#: The C signature of a compiled node function: (table address, record start, start, n).
NODE_SIGNATURE = types.void(types.int64, types.int64, types.int64, types.int64)
_compiled_nodes: dict[int, object] = {}


def node_function_address(kind: int) -> int:
    """The address of kind's compiled node function (compiled, or loaded from numba's cache,
    on first use)."""
    compiled = _compiled_nodes.get(kind)
    if compiled is None:
        compiled = nb.cfunc(NODE_SIGNATURE, cache=True, nogil=True)(NODE_FUNCTIONS[kind])
        _compiled_nodes[kind] = compiled
    return compiled.address


@intrinsic
def call_node(typingctx, function, table, base, start, n):
    """Call the compiled node function at address ``function`` (see NODE_SIGNATURE)."""
    sig = types.void(types.int64, types.int64, types.int64, types.int64, types.int64)

    def codegen(context, builder, signature, args):
        i64 = llvmir.IntType(64)
        pointer = builder.inttoptr(args[0], llvmir.FunctionType(llvmir.VoidType(), [i64] * 4).as_pointer())
        builder.call(pointer, args[1:])
        return context.get_dummy_value()

    return sig, codegen


@nb.njit(cache=True, nogil=True)
def run_program(prog, start, n):
    """Run every node of the program, in order, for frames start .. start + n - 1."""
    table = prog.ctypes.data
    for i in range(prog[0]):
        base = 1 + i * RECORD
        call_node(prog[base + FUNCTION], table, base, start, n)


@nb.njit(cache=True, nogil=True)
def run_blocks(prog, bus, rows, out, offset, start, count, block):
    """``count`` whole blocks from frame ``start``; output channel r of each block goes to
    out[r, offset + ...] from bus row rows[r]."""
    for b in range(count):
        run_program(prog, start + b * block, block)
        at = offset + b * block
        for r in range(rows.shape[0]):
            src = bus[rows[r]]
            dst = out[r]
            for i in range(block):
                dst[at + i] = src[i]


def why_not_compiled(graph: Graph) -> str | None:
    """Why ``graph`` cannot run as a program (None if it can)."""
    if graph.budget is not None and graph.budgeted:
        return "an anytime mode budget decides between sub-blocks in Python"
    if graph.delays:
        return f"node {graph.delays[0].name!r} is a delay"
    for node in graph.order:
        if type(node) not in PROGRAM_UGENS:
            return f"node {node.name!r} ({node.type_name}) has no program kernel"
        if isinstance(node, (Scrape, ResonantScrape)) and node._curves is not None:
            return f"node {node.name!r} follows contact curves"
        if isinstance(node, ModalBank) and "size" in node.sources:
            return f"node {node.name!r} is retuned by a fragment size input"
    return None


class Program:
    """The program of a prepared graph (see the module docstring); keeps the arrays it
    points to alive. Raises ValueError (with :func:`why_not_compiled`'s reason) if the
    graph cannot run as a program."""

    def __init__(self, graph: Graph):
        reason = why_not_compiled(graph)
        if reason is not None:
            raise ValueError(reason)
        self.graph = graph
        self.table = np.zeros(1 + RECORD * len(graph.order), dtype=np.int64)
        self.table[0] = len(graph.order)
        self._arrays: dict[int, list[np.ndarray]] = {}
        self._impacts: list[tuple[int, ImpactForce]] = []
        for i, node in enumerate(graph.order):
            if isinstance(node, ModalBank):
                node.inline_events = False  # its events split the sub-block (see the module doc)
            if isinstance(node, ImpactForce):
                self._impacts.append((i, node))
            self._write(i, node)

    def _write(self, i: int, node) -> None:
        arrays = self._record_arrays(node)
        base = 1 + i * RECORD
        record = self.table[base : base + RECORD]
        record[:] = 0
        record[0] = PROGRAM_UGENS[type(node)]
        record[2] = node.max_block
        record[FUNCTION] = node_function_address(record[0])
        for j, value in enumerate(arrays, start=1):
            record[j if j == 1 else j + 1] = value.ctypes.data if isinstance(value, np.ndarray) else value
        self._arrays[i] = [a for a in arrays if isinstance(a, np.ndarray)]

    @staticmethod
    def _record_arrays(node) -> list:
        """The output buffer, then the kind's slots (arrays by address, ints as they are)."""
        if isinstance(node, Gain):
            return [node.out, node.sources["input"].out, node.gain.ramp, node.gains]
        if isinstance(node, Mixer):
            names = node.input_names()
            sources = np.array([node.sources[k].out.ctypes.data for k in names], dtype=np.int64)
            gains = np.array([g for _, g in node._terms], dtype=np.float64)
            return [node.out, len(names), sources, gains]
        if isinstance(node, Multiply):
            return [node.out, node.sources["a"].out, node.sources["b"].out]
        if isinstance(node, ImpactForce):
            return [node.out, node.pulses, node.pulses.shape[0], node.count]
        if isinstance(node, ModalBank):
            floor = np.array([node._floor])
            k = node.bank.shape[1]
            inp = node.sources["input"].out
            return [node.out, inp, node.bank, k, node.delta, node.target, node.meta, node.last, floor]
        if isinstance(node, Scrape):
            prof = np.ascontiguousarray(node.prof, dtype=np.float64)
            node.prof = prof
            return [
                node.out,
                node._force.ramp,
                node._speed.ramp,
                node._forces,
                node._speeds,
                prof,
                prof.size,
                node.state,
                node.coef,
                node.cfg,
            ]
        if isinstance(node, Radiation):
            return [node.out, node.sources["input"].out, node.coef, node.state]
        if isinstance(node, SoundPressure):
            return [node.out, node.sources["input"].out, node.coef, node.state, node.setup]
        if isinstance(node, Biquad):
            setup = np.array([float(node.mode), 1.0 / node.sample_rate])
            ramps = [node.freq.ramp, node.q.ramp, node._freqs, node._qs]
            return [node.out, node.sources["input"].out, *ramps, node.coef, node.state, setup]
        if isinstance(node, ResonantScrape):
            controls = [node._force.ramp, node._speed.ramp, node._forces, node._speeds]
            return [node.out, *controls, node.rng, node.state, node.cfg]
        raise ValueError(f"{node.type_name}: no program kernel")

    def sync(self) -> None:
        """Re-point the records of ImpactForce nodes whose pulse table grew (a strike may
        reallocate it)."""
        for i, node in self._impacts:
            if self._arrays[i][1] is not node.pulses:
                self._write(i, node)

    def run(self, start: int, n: int) -> None:
        """Run the graph for frames start .. start + n - 1 (outputs in the nodes' buffers)."""
        run_program(self.table, start, n)
