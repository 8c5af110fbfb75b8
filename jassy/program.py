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
jassy.engines.callback) and offline, on the callback's code path (one compiled call per run
of frames, jassy.engines.program_offline: no Python per block or per event).

Ugens with a kernel here: :data:`PROGRAM_UGENS`. A graph holding any other node, a feedback
delay, an anytime budget or a contact that follows physics curves keeps the per-node Python
path; :func:`why_not_compiled` says why. In a program a ModalBank's parameter events split
the graph's sub-block at their frame (the split its own ``process`` makes inline), which
leaves every other node's output unchanged: their kernels are sample by sample.
"""

from __future__ import annotations

from typing import NamedTuple

import numba as nb
import numpy as np
from numba.core import types
from numba.np.unsafe.ndarray import to_fixed_tuple

from jassy import anytime_rank, jit, params
from jassy.graph import Graph
from jassy.jit import address, call_void, drop_stale_cache, void_pointer
from jassy.params import RAMP_NEXT, RAMP_SAMPLES, ramp_fill
from ugens import (
    cells,
    filters,
    impact,
    kernels,
    mix,
    modal,
    modal_f32,
    modal_meta,
    noise,
    pressure,
    radiation,
    scrape,
    tonal_level,
)
from ugens.filters import Biquad, biquad, biquad_ramp, design_biquad
from ugens.impact import ImpactForce, render_pulses
from ugens.mix import Gain, Mixer, Multiply, accumulate, multiply, scale, scale_ramp
from ugens.modal import ModalBank, Ramp, bank_step, resonate_ramp
from ugens.modal_meta import ACTIVE, ALLOWED, RAMP_LEFT
from ugens.pressure import SoundPressure, sound_pressure
from ugens.radiation import Radiation, radiate
from ugens.scrape import NOISE_CFG_SIZE, ResonantScrape, Scrape, profile_contact, resonant_noise

#: The modules whose kernels the program calls, directly or through another kernel (a change
#: there drops its numba cache): modal.bank_step steps mixed banks with modal_f32's kernels,
#: scrape.resonant_noise reads tonal_level's table, ``kernels`` holds their FASTMATH flags.
KERNEL_MODULES = [anytime_rank, params, cells, filters, impact, kernels, mix, modal, modal_f32, modal_meta,
                  noise, pressure, radiation, scrape, tonal_level]  # fmt: skip
drop_stale_cache(__file__, [jit, *KERNEL_MODULES])

#: int64 slots per node record: a Header, its kind's slots record (zero-padded), and last the
#: address of its kind's compiled function.
RECORD = 16
FUNCTION = RECORD - 1
GAIN, MIXER, MULTIPLY, IMPACT, MODAL, SCRAPE, RESONANT_SCRAPE, BIQUAD, RADIATION = range(1, 10)
SOUND_PRESSURE = 10


class Header(NamedTuple):
    """The first slots of every node record."""

    kind: int  #: GAIN .. SOUND_PRESSURE
    out: int  #: the output buffer
    size: int  #: its length (the node's max_block)


#: Slots of the Header; a kind's slots follow it.
HEADER = len(Header._fields)
#: Slots a kind's record may use (between the Header and the FUNCTION slot).
KIND_SLOTS = FUNCTION - HEADER

# The kinds' slots records. In the table an array is its address, an int itself; the
# comments give the arrays' float64 lengths (size: the header's).


class GainSlots(NamedTuple):
    input: int  #: (size,)
    ramp: int  #: the gain's ramp (4,)
    gains: int  #: per-sample gains while it ramps (size,)


class MixerSlots(NamedTuple):
    count: int  #: inputs
    sources: int  #: int64 addresses of the inputs' buffers (count,)
    gains: int  #: (count,)


class MultiplySlots(NamedTuple):
    a: int  #: (size,)
    b: int  #: (size,)


class ImpactSlots(NamedTuple):
    pulses: int  #: pulse table (capacity, 3)
    capacity: int  #: its rows
    count: int  #: int64 pulses queued (1,)


class ModalSlots(NamedTuple):
    input: int  #: force (size,)
    bank: int  #: rows c1, c2, g, d, y1, y2 (6, modes)
    modes: int  #: modes in the bank
    delta: int  #: per-sample coefficient steps of a ramp (4, modes)
    target: int  #: the ramp's target coefficients (4, modes)
    meta: int  #: int64 [active modes, ramp samples left, allowed modes] (3,)
    last: int  #: the force sample before the sub-block (1,)
    floor: int  #: silent-mode floor (1,)


class ScrapeSlots(NamedTuple):
    force_ramp: int  #: (4,)
    speed_ramp: int  #: (4,)
    forces: int  #: (size,)
    speeds: int  #: (size,)
    profile: int  #: (length,)
    length: int  #: profile points
    state: int  #: (4,)
    coef: int  #: (5,)
    cfg: int  #: a ProfileConfig (9,)


class ResonantScrapeSlots(NamedTuple):
    force_ramp: int  #: (4,)
    speed_ramp: int  #: (4,)
    forces: int  #: (size,)
    speeds: int  #: (size,)
    rng: int  #: uint64 (1,)
    state: int  #: (8,)
    cfg: int  #: a NoiseConfig and the level table (NOISE_CFG_SIZE,)


class BiquadSlots(NamedTuple):
    input: int  #: (size,)
    freq_ramp: int  #: (4,)
    q_ramp: int  #: (4,)
    freqs: int  #: (size,)
    qs: int  #: (size,)
    coef: int  #: (5,)
    state: int  #: (2,)
    setup: int  #: [mode, 1/fs] (2,): BIQUAD_MODE, BIQUAD_PERIOD


#: Fields of a Biquad's setup array (BiquadSlots.setup): the filter mode, 1/fs (s).
BIQUAD_MODE, BIQUAD_PERIOD = 0, 1


class RadiationSlots(NamedTuple):
    input: int  #: (size,)
    coef: int  #: (4,)
    state: int  #: (3,)


class SoundPressureSlots(NamedTuple):
    input: int  #: (size,)
    coef: int  #: (3,)
    state: int  #: (3,)
    setup: int  #: (3,)


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


@nb.njit(cache=True, nogil=True, inline="always")
def header(prog, base):
    """The Header of the record at prog[base]."""
    return Header(prog[base], prog[base + 1], prog[base + 2])


@nb.njit(cache=True, nogil=True, inline="always")
def kind_slots(prog, base):
    """The KIND_SLOTS slots after the Header of the record at prog[base], as a tuple: its
    kind's record is the tuple's first fields (``ModalSlots(*kind_slots(prog, base)[:8])``;
    a wrong count does not compile)."""
    return to_fixed_tuple(prog[base + HEADER : base + FUNCTION], KIND_SLOTS)


# One function per node kind, compiled (as a C-callable function) only when a program holds
# that kind: a graph compiles the kernels it uses, not every kind's. Each reads its record
# from the table at address ``table`` (see Program), for frames start .. start + n - 1.


def _gain(table, base, start, n):
    prog = _i64(table, base + RECORD)
    _, out_at, size = header(prog, base)
    gain = GainSlots(*kind_slots(prog, base)[:3])
    out = _f64(out_at, size)
    x = _f64(gain.input, size)
    ramp = _f64(gain.ramp, 4)
    if ramp[RAMP_SAMPLES] == 0:
        scale(x, out, n, ramp[RAMP_NEXT])
    else:
        gains = _f64(gain.gains, size)
        ramp_fill(ramp, gains, n)
        scale_ramp(x, out, n, gains)


def _mixer(table, base, start, n):
    prog = _i64(table, base + RECORD)
    _, out_at, size = header(prog, base)
    mixer = MixerSlots(*kind_slots(prog, base)[:3])
    out = _f64(out_at, size)
    m = mixer.count
    sources = _i64(mixer.sources, m)
    gains = _f64(mixer.gains, m)
    scale(_f64(sources[0], size), out, n, gains[0])
    for j in range(1, m):
        accumulate(_f64(sources[j], size), out, n, gains[j])


def _multiply(table, base, start, n):
    prog = _i64(table, base + RECORD)
    _, out, size = header(prog, base)
    product = MultiplySlots(*kind_slots(prog, base)[:2])
    multiply(_f64(product.a, size), _f64(product.b, size), _f64(out, size), n)


def _impact(table, base, start, n):
    prog = _i64(table, base + RECORD)
    _, out, size = header(prog, base)
    impact_ = ImpactSlots(*kind_slots(prog, base)[:3])
    pulses = _f64_rows(impact_.pulses, impact_.capacity, 3)
    count = _i64(impact_.count, 1)
    count[0] = render_pulses(_f64(out, size), start, n, pulses, count[0])


def _modal(table, base, start, n):
    prog = _i64(table, base + RECORD)
    _, out_at, size = header(prog, base)
    bank_ = ModalSlots(*kind_slots(prog, base)[:8])
    out = _f64(out_at, size)
    k = bank_.modes
    force = _f64(bank_.input, size)
    bank = _f64_rows(bank_.bank, 6, k)
    meta = _i64(bank_.meta, 3)
    last = _f64(bank_.last, 1)
    if meta[RAMP_LEFT] > 0:
        meta[ACTIVE] = meta[ALLOWED]
        delta = _f64_rows(bank_.delta, 4, k)
        target = _f64_rows(bank_.target, 4, k)
        ramp = Ramp(bank[:4], delta, target)
        meta[RAMP_LEFT] = resonate_ramp(
            force, out, n, ramp, bank[4], bank[5], meta[RAMP_LEFT], meta[ACTIVE], last
        )
    else:
        bank_step(force, out, start, n, bank, meta, _f64(bank_.floor, 1)[0], last)


def _scrape(table, base, start, n):
    prog = _i64(table, base + RECORD)
    _, out, size = header(prog, base)
    needle = ScrapeSlots(*kind_slots(prog, base)[:9])
    forces = _f64(needle.forces, size)
    speeds = _f64(needle.speeds, size)
    ramp_fill(_f64(needle.force_ramp, 4), forces, n)
    ramp_fill(_f64(needle.speed_ramp, 4), speeds, n)
    profile_contact(
        _f64(out, size),
        n,
        forces,
        speeds,
        _f64(needle.profile, needle.length),
        _f64(needle.state, 4),
        _f64(needle.coef, 5),
        _f64(needle.cfg, 9),
    )


def _resonant_scrape(table, base, start, n):
    prog = _i64(table, base + RECORD)
    _, out, size = header(prog, base)
    noisy = ResonantScrapeSlots(*kind_slots(prog, base)[:7])
    forces = _f64(noisy.forces, size)
    speeds = _f64(noisy.speeds, size)
    ramp_fill(_f64(noisy.force_ramp, 4), forces, n)
    ramp_fill(_f64(noisy.speed_ramp, 4), speeds, n)
    resonant_noise(
        _f64(out, size),
        n,
        forces,
        speeds,
        _u64(noisy.rng, 1),
        _f64(noisy.state, 8),
        _f64(noisy.cfg, NOISE_CFG_SIZE),
    )


def _biquad(table, base, start, n):
    prog = _i64(table, base + RECORD)
    _, out_at, size = header(prog, base)
    filt = BiquadSlots(*kind_slots(prog, base)[:8])
    out = _f64(out_at, size)
    x = _f64(filt.input, size)
    freq = _f64(filt.freq_ramp, 4)
    q = _f64(filt.q_ramp, 4)
    coef = _f64(filt.coef, 5)
    state = _f64(filt.state, 2)
    setup = _f64(filt.setup, 2)
    mode = int(setup[BIQUAD_MODE])
    if freq[RAMP_SAMPLES] == 0 and q[RAMP_SAMPLES] == 0:
        biquad(x, out, n, coef, state)
    else:
        freqs = _f64(filt.freqs, size)
        qs = _f64(filt.qs, size)
        ramp_fill(freq, freqs, n)
        ramp_fill(q, qs, n)
        biquad_ramp(x, out, n, mode, freqs, qs, setup[BIQUAD_PERIOD], coef, state)
        # the ramps just ended: coefficients for the targets
        if freq[RAMP_SAMPLES] == 0 and q[RAMP_SAMPLES] == 0:
            design_biquad(mode, freq[RAMP_NEXT], q[RAMP_NEXT], setup[BIQUAD_PERIOD], coef)


def _radiation(table, base, start, n):
    prog = _i64(table, base + RECORD)
    _, out, size = header(prog, base)
    rad = RadiationSlots(*kind_slots(prog, base)[:3])
    radiate(_f64(rad.input, size), _f64(out, size), n, _f64(rad.coef, 4), _f64(rad.state, 3))


def _sound_pressure(table, base, start, n):
    prog = _i64(table, base + RECORD)
    _, out, size = header(prog, base)
    sp = SoundPressureSlots(*kind_slots(prog, base)[:4])
    x = _f64(sp.input, size)
    sound_pressure(x, _f64(out, size), n, _f64(sp.coef, 3), _f64(sp.state, 3), _f64(sp.setup, 3))


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


@nb.njit(cache=True, nogil=True, inline="always")  # inlined, as callback.apply_event
def run_program(prog, start, n):
    """Run every node of the program, in order, for frames start .. start + n - 1."""
    table = prog.ctypes.data
    for i in range(prog[0]):
        base = 1 + i * RECORD
        call_void(prog[base + FUNCTION], table, base, start, n)


@nb.njit(cache=True, nogil=True)
def run_blocks(prog, bus, rows, out, offset, start, count, block):
    """``count`` whole blocks from frame ``start``; output channel r of each block goes to
    out[r, offset + ...] from bus row rows[r]: the program alone, without events or an
    output stage (``jassy bench modal`` times it against the bare kernel)."""
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
    if graph.budget is not None and any(node.supports_budget for node in graph.order):  # (prepared or not)
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
        if isinstance(node, ModalBank) and node.values["precision"] == "mixed":
            return f"node {node.name!r} runs in mixed precision (its float32 split has no program kernel)"
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
        self._slots: dict[int, NamedTuple] = {}
        self._impacts: list[tuple[int, ImpactForce]] = []
        for i, node in enumerate(graph.order):
            if isinstance(node, ModalBank):
                node.inline_events = False  # its events split the sub-block (see the module doc)
            if isinstance(node, ImpactForce):
                self._impacts.append((i, node))
            self._write(i, node)

    def _write(self, i: int, node) -> None:
        slots = self._node_slots(node)
        base = 1 + i * RECORD
        record = self.table[base : base + RECORD]
        record[:] = 0
        record[:HEADER] = Header(PROGRAM_UGENS[type(node)], address(node.out), node.max_block)
        record[FUNCTION] = node_function_address(record[0])
        for j, value in enumerate(slots):
            record[HEADER + j] = address(value) if isinstance(value, np.ndarray) else value
        self._arrays[i] = [node.out, *(a for a in slots if isinstance(a, np.ndarray))]
        self._slots[i] = slots

    @staticmethod
    def _node_slots(node) -> NamedTuple:
        """The kind's slots record of ``node`` (arrays, written by address, and ints)."""
        if isinstance(node, Gain):
            return GainSlots(node.sources["input"].out, node.gain.ramp, node.gains)
        if isinstance(node, Mixer):
            names = node.input_names()
            sources = np.array([address(node.sources[k].out) for k in names], dtype=np.int64)
            gains = np.array([g for _, g in node._terms], dtype=np.float64)
            return MixerSlots(len(names), sources, gains)
        if isinstance(node, Multiply):
            return MultiplySlots(node.sources["a"].out, node.sources["b"].out)
        if isinstance(node, ImpactForce):
            return ImpactSlots(node.pulses, node.pulses.shape[0], node.count)
        if isinstance(node, ModalBank):
            return ModalSlots(
                input=node.sources["input"].out,
                bank=node.bank,
                modes=node.bank.shape[1],
                delta=node.delta,
                target=node.target,
                meta=node.meta,
                last=node.last,
                floor=np.array([node._floor]),
            )
        if isinstance(node, Scrape):
            prof = np.ascontiguousarray(node.prof, dtype=np.float64)
            node.prof = prof
            return ScrapeSlots(
                force_ramp=node._force.ramp,
                speed_ramp=node._speed.ramp,
                forces=node._forces,
                speeds=node._speeds,
                profile=prof,
                length=prof.size,
                state=node.state,
                coef=node.coef,
                cfg=node.cfg,
            )
        if isinstance(node, Radiation):
            return RadiationSlots(node.sources["input"].out, node.coef, node.state)
        if isinstance(node, SoundPressure):
            return SoundPressureSlots(node.sources["input"].out, node.coef, node.state, node.setup)
        if isinstance(node, Biquad):
            return BiquadSlots(
                input=node.sources["input"].out,
                freq_ramp=node.freq.ramp,
                q_ramp=node.q.ramp,
                freqs=node._freqs,
                qs=node._qs,
                coef=node.coef,
                state=node.state,
                setup=np.array([float(node.mode), 1.0 / node.sample_rate]),
            )
        if isinstance(node, ResonantScrape):
            return ResonantScrapeSlots(
                force_ramp=node._force.ramp,
                speed_ramp=node._speed.ramp,
                forces=node._forces,
                speeds=node._speeds,
                rng=node.rng,
                state=node.state,
                cfg=node.cfg,
            )
        raise ValueError(f"{node.type_name}: no program kernel")

    def sync(self) -> None:
        """Re-point the records of ImpactForce nodes whose pulse table grew (a strike may
        reallocate it)."""
        for i, node in self._impacts:
            if self._slots[i].pulses is not node.pulses:
                self._write(i, node)

    def run(self, start: int, n: int) -> None:
        """Run the graph for frames start .. start + n - 1 (outputs in the nodes' buffers)."""
        run_program(self.table, start, n)
