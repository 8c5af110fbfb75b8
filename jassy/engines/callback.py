"""Sound rendered in the audio callback: the graph's program run by the PortAudio callback.

SuperCollider's model: the device's callback (a numba ``@cfunc``, never the GIL) renders
each buffer itself by running the graph's program (jassy.program) and writes the audio and
haptic channels straight to the device: no ring, so the output latency is the device's.
Python only pushes events into single-producer single-consumer queues, each record stamped
with the frame it applies at, and reads counters, meters and the monitor.

Sub-blocks are cut exactly as the offline scheduler cuts them (block boundaries on the
absolute clock, and the frames of events that are not inline; strikes are inline), and
the output stage is the offline engine's (limiter, haptic force and slew limits), so the
device receives the offline rendering sample for sample.

Event records (float64 x EVENT): [frame, node record, opcode, a, b, c, ...]:

- SET_RAMP: a smoothed parameter's ramp (slot a of the record) moves to b over c samples
  (c < 1: jumps), as :class:`jassy.params.Smoothed`; SET_BIQUAD also redesigns the filter;
- STRIKE: an impact pulse (t0 = a, T = b, amplitude c; see ugens.impact) is added;
- MODAL: a ModalBank's target coefficients are copied from the staging rows at address a
  and approached over b samples (b < 1: jumps), as ``ModalBank._param_changed``.

Python computes what needs the ugens' Python code (pulse amplitudes, modal designs) when it
pushes an event; the callback only copies and steps. Two queues: ``score`` (stamped events
pushed ahead by a feeder thread, in time order) and ``now`` (posted events, applied at the
next sub-block that reaches their frame).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Sequence
from typing import NamedTuple

import numba as nb
import numpy as np
from llvmlite import ir as llvmir
from numba import types
from numba.extending import intrinsic

from jassy import haptics, jit, program, safety
from jassy.engines import hapticframes
from jassy.engines.hapticframes import FLAG_WATCHDOG
from jassy.engines.hapticsender import LOG_COLUMNS, LOG_DAC, LOG_FLAGS, LOG_FRAMES, LOG_START
from jassy.engines.memlock import resident
from jassy.errors import JassyError
from jassy.events import Event
from jassy.graph import Graph
from jassy.haptics import HapticSafety, limit_force
from jassy.jit import address, call_void, drop_stale_cache, void_pointer
from jassy.params import RAMP_NEXT, ramp_to
from jassy.program import (
    BIQUAD_MODE,
    BIQUAD_PERIOD,
    HEADER,
    KERNEL_MODULES,
    RECORD,
    BiquadSlots,
    GainSlots,
    ImpactSlots,
    ModalSlots,
    Program,
    ResonantScrapeSlots,
    ScrapeSlots,
    _f64,
    _f64_rows,
    _i64,
    kind_slots,
    run_program,
    why_not_compiled,
)
from jassy.safety import CEILING, METERED, copy_finite, float_from_bits, limit_metered, release_coefficient
from jassy.scheduler import apply_frame, prepare_score, ramp_seconds, validate_event
from ugens.cells import (
    MIN_PULSE_SAMPLES,
    PULSE_AMPLITUDE,
    PULSE_COLUMNS,
    PULSE_LENGTH,
    PULSE_T0,
    pulse_amplitude,
)
from ugens.filters import Biquad, design_biquad
from ugens.impact import ImpactForce
from ugens.mix import Gain
from ugens.modal import ModalBank
from ugens.modal_meta import RAMP_LEFT
from ugens.scrape import ResonantScrape, Scrape

drop_stale_cache(__file__, [jit, program, safety, haptics, hapticframes, *KERNEL_MODULES])

# control slots (int64)
(
    FRAME,
    CALLBACKS,
    MAX_FRAMES,
    FLAGS,
    XRUNS,
    PLAYED,
    PROGRAM,
    BUS,
    BUS_COUNT,
    ROWS,
    N_ROWS,
    N_AUDIO,
    CHANNELS,
    BLOCK,
    STAGE,
    PARAMS,
    LIMITER,
    HAPTIC_LAST,
    NONFINITE,
    HAPTIC_FLAGS,
    DROPPED,
    MONITOR,
    MONITOR_INDEX,
    MONITOR_CAP,
    LEVELS,
    WATCHDOG,
    FADE_LEFT,
    TAP_LOG,
    TAP_LOG_ROWS,
    TAP_HAPTIC_ROWS,
    TAP_LOGGED,
    PRIORITY,
    REALTIME,
    CLOCK,
    BUSY_MAX_NS,
    BUSY_TOTAL_NS,
    BUFFER_NS,
    BUSY_OVER,
    BUSY_MAX_AT,
    LATE_STRIKES,
    OUTPUT,
    METER,
    NEXT_CUT,
    OUTPUT_STAGE,
) = range(44)
#: Per queue: [records address, capacity, write, read]; the score queue, then the now queue.
QUEUES, QUEUE_SLOTS, N_QUEUES = OUTPUT_STAGE + 1, 4, 2
CONTROL = QUEUES + QUEUE_SLOTS * N_QUEUES
# float64 parameter slots
CEIL, RELEASE, MAX_FORCE, MAX_STEP = range(4)
EVENT = 8
SET_RAMP, SET_BIQUAD, STRIKE, MODAL_TARGET = 1, 2, 3, 4
#: Columns of an event record: the frame it applies at, the node's record in the program
#: table, the opcode, then the opcode's arguments (module docstring), named per opcode below.
EVENT_FRAME, EVENT_NODE, EVENT_OPCODE, EVENT_A, EVENT_B, EVENT_C = range(6)
SET_SLOT, SET_VALUE, SET_SAMPLES = EVENT_A, EVENT_B, EVENT_C  # SET_RAMP, SET_BIQUAD
STRIKE_T0, STRIKE_LENGTH, STRIKE_AMPLITUDE = EVENT_A, EVENT_B, EVENT_C  # STRIKE
MODAL_STAGED, MODAL_SAMPLES = EVENT_A, EVENT_B  # MODAL_TARGET
OUTPUT_UNDERFLOW = 4  # PortAudio's paOutputUnderflow status flag
#: Bits of the OUTPUT slot: the limits the output stage applies.
LIMIT_AUDIO, LIMIT_HAPTIC = 1, 2
#: Impact pulses that may overlap in the callback (the offline table grows instead).
PULSE_CAPACITY = 256
#: Staged modal designs per ModalBank (events of one bank in flight at once).
MODAL_SLOTS = 16
#: How far ahead of the device the feeder pushes score events (s).
HORIZON = 0.25


@nb.njit(cache=True, nogil=True, inline="always")
def program_table(control):
    """The program's int64 table at control[PROGRAM] (its first slot: the node count)."""
    count = _i64(control[PROGRAM], 1)[0]
    return _i64(control[PROGRAM], 1 + count * RECORD)


# Inlined here and below (numba IR): a kernel of its own compiles once more, and LLVM then
# optimises its linked copy again in each caller (on a cold render, ~0.3 s of CPU each).
@nb.njit(cache=True, nogil=True, inline="always")
def apply_event(prog, ev, control):
    """Apply one event record (see the module docstring) to the program's arrays."""
    base = int(ev[EVENT_NODE])
    op = int(ev[EVENT_OPCODE])
    if op in (SET_RAMP, SET_BIQUAD):
        ramp = _f64(prog[base + int(ev[SET_SLOT])], 4)
        ramp_to(ramp, ev[SET_VALUE], int(ev[SET_SAMPLES]))
        if op == SET_BIQUAD:
            filt = BiquadSlots(*kind_slots(prog, base)[:8])
            setup = _f64(filt.setup, 2)
            freq = _f64(filt.freq_ramp, 4)
            q = _f64(filt.q_ramp, 4)
            design_biquad(
                int(setup[BIQUAD_MODE]),
                freq[RAMP_NEXT],
                q[RAMP_NEXT],
                setup[BIQUAD_PERIOD],
                _f64(filt.coef, 5),
            )
    elif op == STRIKE:
        impact = ImpactSlots(*kind_slots(prog, base)[:3])
        pulses = _f64_rows(impact.pulses, impact.capacity, PULSE_COLUMNS)
        count = _i64(impact.count, 1)
        c = count[0]
        if c < pulses.shape[0]:
            pulses[c, PULSE_T0] = ev[STRIKE_T0]
            pulses[c, PULSE_LENGTH] = ev[STRIKE_LENGTH]
            pulses[c, PULSE_AMPLITUDE] = ev[STRIKE_AMPLITUDE]
            count[0] = c + 1
        else:
            control[DROPPED] += 1
    elif op == MODAL_TARGET:
        modal = ModalSlots(*kind_slots(prog, base)[:8])
        k = modal.modes
        bank = _f64_rows(modal.bank, 6, k)
        delta = _f64_rows(modal.delta, 4, k)
        target = _f64_rows(modal.target, 4, k)
        meta = _i64(modal.meta, 3)
        staged = _f64_rows(int(ev[MODAL_STAGED]), 4, k)
        m = int(ev[MODAL_SAMPLES])
        for r in range(4):
            for j in range(k):
                target[r, j] = staged[r, j]
        if m < 1:
            for r in range(4):
                for j in range(k):
                    bank[r, j] = target[r, j]
            meta[RAMP_LEFT] = 0
        else:
            for r in range(4):
                for j in range(k):
                    delta[r, j] = (target[r, j] - bank[r, j]) / m
            meta[RAMP_LEFT] = m


@nb.njit(cache=True, nogil=True, inline="always")
def _next_cut(control, queue_index, pos, stop, prog):
    """Apply the due records of one queue (frame <= pos, and strikes before ``stop``);
    return the frame of its first record left before ``stop`` (``stop`` if none)."""
    slot = QUEUES + QUEUE_SLOTS * queue_index
    cap = control[slot + 1]
    records = _f64_rows(control[slot], cap, EVENT)
    w = control[slot + 2]
    r = control[slot + 3]
    while r < w:
        ev = records[r % cap]
        frame = int(ev[EVENT_FRAME])
        if frame <= pos or (frame < stop and int(ev[EVENT_OPCODE]) == STRIKE):
            if frame < pos and int(ev[EVENT_OPCODE]) == STRIKE:
                # stamped with a frame already played (its poster was preempted between
                # reading the frame and pushing): the whole pulse starts now instead of
                # being cut or lost; a whole-frame shift keeps its fractional onset
                ev[STRIKE_T0] += pos - frame
                control[LATE_STRIKES] += 1
            apply_event(prog, ev, control)
            r += 1
        else:
            if frame < stop:
                stop = frame
            break
    control[slot + 3] = r
    return stop


def _next_cut_entry(control_address, queue_index, pos, stop):
    """:func:`_next_cut` for the program of the control slots at ``control_address``."""
    control = nb.carray(void_pointer(control_address), (CONTROL,), np.int64)
    prog = program_table(control)
    return _next_cut(control, queue_index, pos, stop, prog)


def _output_stage(control_address, dst_address, row_stride, m):
    """The output stage of ``m`` frames of the bus rows into the float64 destination rows at
    ``dst_address`` (``row_stride`` elements apart): NaN/Inf to 0 (counted in NONFINITE), the
    audio limiter and its meter (LIMIT_AUDIO), the haptic force and slew limits
    (LIMIT_HAPTIC) and the final fade of the haptic rows."""
    control = nb.carray(void_pointer(control_address), (CONTROL,), np.int64)
    block = control[BLOCK]
    rows_n = control[N_ROWS]
    na = control[N_AUDIO]
    rows = _i64(control[ROWS], rows_n)
    par = _f64(control[PARAMS], 4)
    bus_bits = nb.carray(void_pointer(control[BUS]), (control[BUS_COUNT], block), np.int64)
    dst_bits = nb.carray(void_pointer(dst_address), (rows_n, row_stride), np.int64)
    top = 0
    for c in range(rows_n):
        bad, magnitude = copy_finite(bus_bits[rows[c]], dst_bits[c, :], m)
        control[NONFINITE] += bad
        if c < na:
            top = max(top, magnitude)
    out = nb.carray(void_pointer(dst_address), (rows_n, row_stride), np.float64)[:, :m]
    if control[OUTPUT] & LIMIT_AUDIO:
        meter = _f64(control[METER], METERED + 1)
        peak = float_from_bits(top)
        limit_metered(out[:na], m, _f64(control[LIMITER], 1), par[CEIL], par[RELEASE], peak, meter)
    nh = rows_n - na
    if nh > 0:
        if control[OUTPUT] & LIMIT_HAPTIC:
            last = _f64(control[HAPTIC_LAST], nh)
            control[HAPTIC_FLAGS] |= limit_force(out[na:], m, last, par[MAX_FORCE], par[MAX_STEP])
        left = control[FADE_LEFT]
        if left >= 0:  # the run ends: forces fade linearly to zero over the watchdog time
            window = control[WATCHDOG]
            for i in range(m):
                w = max(left - i, 0) / window
                for c in range(na, rows_n):
                    out[c, i] *= w
            control[FADE_LEFT] = max(left - m, 0)


#: C signatures of the render loop's stages, compiled apart and called through their
#: addresses (control[NEXT_CUT], control[OUTPUT_STAGE]): each compiles once, in any process,
#: instead of being linked into, and optimised again in, every render loop that calls it.
NEXT_CUT_SIGNATURE = types.int64(types.int64, types.int64, types.int64, types.int64)
OUTPUT_STAGE_SIGNATURE = types.void(types.int64, types.int64, types.int64, types.int64)
_compiled_stages: dict[str, object] = {}


def next_cut_address() -> int:
    """The address of the compiled event application of one queue (:func:`_next_cut`)."""
    return _stage_address("next_cut", NEXT_CUT_SIGNATURE, _next_cut_entry)


def output_stage_address() -> int:
    """The address of the compiled output stage (:func:`_output_stage`)."""
    return _stage_address("output_stage", OUTPUT_STAGE_SIGNATURE, _output_stage)


def _stage_address(name: str, signature, function) -> int:
    """A stage compiled as a C function (or loaded from numba's cache) on first use."""
    compiled = _compiled_stages.get(name)
    if compiled is None:
        compiled = nb.cfunc(signature, cache=True, nogil=True)(function)
        _compiled_stages[name] = compiled
    return compiled.address


@intrinsic
def call_next_cut(typingctx, function, control_address, queue_index, pos, stop):
    """Call the compiled :func:`_next_cut_entry` at address ``function``."""
    sig = types.int64(types.int64, types.int64, types.int64, types.int64, types.int64)

    def codegen(context, builder, signature, args):
        i64 = llvmir.IntType(64)
        pointer = builder.inttoptr(args[0], llvmir.FunctionType(i64, [i64] * 4).as_pointer())
        return builder.call(pointer, args[1:])

    return sig, codegen


@nb.njit(cache=True, nogil=True)
def apply_due(control, pos):
    """Apply the score queue's records due at frame ``pos`` (before a Python event there)."""
    call_next_cut(control[NEXT_CUT], control.ctypes.data, 0, pos, pos)


@nb.njit(cache=True, nogil=True, inline="always")
def sub_block(control, prog, pos, end, dst, at):
    """Render the sub-block from frame ``pos`` into dst[:, at:] (float64 rows: audio, then
    haptic, each row contiguous) and return its end: apply the queued records due there
    (control[NEXT_CUT]), cut at the next block boundary or record frame (at most ``end``),
    run the program, then the output stage (control[OUTPUT_STAGE], :func:`_output_stage`).
    An empty queue is not called."""
    block = control[BLOCK]
    stop = min(end, (pos // block + 1) * block)
    for q in range(N_QUEUES):
        slot = QUEUES + QUEUE_SLOTS * q
        if control[slot + 3] != control[slot + 2]:  # records queued (read != write)
            stop = call_next_cut(control[NEXT_CUT], control.ctypes.data, q, pos, stop)
    m = stop - pos
    run_program(prog, pos, m)
    row_stride = dst.strides[0] // dst.itemsize
    call_void(control[OUTPUT_STAGE], control.ctypes.data, dst.ctypes.data + at * dst.itemsize, row_stride, m)
    return stop


@nb.njit(cache=True, nogil=True)
def render_into(control, out, frames):
    """Render ``frames`` frames of the program into the interleaved float32 ``out``."""
    prog = program_table(control)
    ch = control[CHANNELS]
    stage = _f64_rows(control[STAGE], control[N_ROWS], control[BLOCK])
    levels = _f64(control[LEVELS], max(ch, 1))
    mcap = control[MONITOR_CAP]
    begin = control[FRAME]
    pos = begin
    end = begin + frames
    for c in range(ch):
        levels[c] = 0.0
    while pos < end:
        stop = sub_block(control, prog, pos, end, stage, 0)
        m = stop - pos
        at = pos - begin
        for i in range(m):
            for c in range(ch):
                y = stage[c, i]
                out[(at + i) * ch + c] = y
                if abs(y) > levels[c]:
                    levels[c] = abs(y)
        if mcap > 0:
            mon = _f64_rows(control[MONITOR], mcap, ch)
            index = _i64(control[MONITOR_INDEX], mcap)
            for i in range(m):
                slot = (pos + i) % mcap
                for c in range(ch):
                    mon[slot, c] = stage[c, i]
                index[slot] = pos + i
        pos = stop
    control[FRAME] = end


# libc's scheduler calls, by symbol (so the callback stays cacheable); pid 0 = this thread
_sched_getscheduler = types.ExternalFunction("sched_getscheduler", types.int32(types.int32))
_sched_setscheduler = types.ExternalFunction(
    "sched_setscheduler", types.int32(types.int32, types.int32, types.voidptr)
)
_clock_gettime = types.ExternalFunction("clock_gettime", types.int32(types.int32, types.voidptr))
SCHED_OTHER, SCHED_FIFO, CLOCK_MONOTONIC = 0, 1, 1
#: SCHED_FIFO priority asked for a callback thread the host left at normal priority (a
#: JACK server started without -R); JACK's own real-time clients use 70-95.
CALLBACK_PRIORITY = 40


@nb.njit(cache=True, nogil=True)
def _make_realtime(control):
    """On the first callback: if the host runs it at normal priority, ask for SCHED_FIFO
    (granted with root, CAP_SYS_NICE or an rtprio limit); REALTIME = 1 if it runs real-time."""
    granted = _sched_getscheduler(0) != SCHED_OTHER
    if not granted:
        granted = _sched_setscheduler(0, SCHED_FIFO, void_pointer(control[PRIORITY])) == 0
    control[REALTIME] = 1 if granted else 0


@nb.njit(cache=True, nogil=True)
def _now_ns(control):
    """CLOCK_MONOTONIC in ns (through the timespec at control[CLOCK])."""
    _clock_gettime(CLOCK_MONOTONIC, void_pointer(control[CLOCK]))
    ts = _i64(control[CLOCK], 2)
    return ts[0] * 1_000_000_000 + ts[1]


@nb.njit(cache=True, nogil=True)
def tap_callback(control, out, frames, dac, flags):
    """Log the haptic channels of ``out`` and this callback (first stream frame, frames,
    DAC time, flags) into the stream tap of :mod:`jassy.engines.hapticsender` (addresses in the
    TAP_* slots: the log rows, then the haptic ring)."""
    ch, na = control[CHANNELS], control[N_AUDIO]
    nh = ch - na
    lrows, hrows = control[TAP_LOG_ROWS], control[TAP_HAPTIC_ROWS]
    log = _f64_rows(control[TAP_LOG], lrows, LOG_COLUMNS)
    ring = _f64_rows(control[TAP_LOG] + lrows * LOG_COLUMNS * 8, hrows, max(nh, 1))
    logged = _i64(control[TAP_LOGGED], 1)
    p = control[PLAYED]
    for i in range(frames):
        for c in range(nh):
            ring[(p + i) % hrows, c] = out[i * ch + na + c]
    row = logged[0] % lrows
    log[row, LOG_START] = p
    log[row, LOG_FRAMES] = frames
    log[row, LOG_DAC] = dac
    log[row, LOG_FLAGS] = flags
    logged[0] += 1


#: The C signature of the PortAudio callback :func:`program_callback`.
CALLBACK_SIGNATURE = types.int32(
    types.voidptr, types.voidptr, types.uint64, types.voidptr, types.uint64, types.voidptr
)
_compiled_callback: list = []


def program_callback_address() -> int:
    """The address of :func:`program_callback` compiled as a C function (compiled, or loaded
    from numba's cache, on first use: an offline render, which runs the same render loop
    through jassy.engines.program_offline, never pays for it)."""
    if not _compiled_callback:
        _compiled_callback.append(nb.cfunc(CALLBACK_SIGNATURE, cache=True)(program_callback))
    return _compiled_callback[0].address


def program_callback(inp, out, frames, time_info, status, user):
    """PortAudio callback: render the graph's program for this buffer, count."""
    control = nb.carray(user, (CONTROL,), np.int64)
    if control[CALLBACKS] == 0:
        _make_realtime(control)
    control[CALLBACKS] += 1
    control[FLAGS] |= status
    if status & OUTPUT_UNDERFLOW:
        control[XRUNS] += 1
    if frames > control[MAX_FRAMES]:
        control[MAX_FRAMES] = frames
    o = nb.carray(out, (frames * control[CHANNELS],), np.float32)
    flags_before, fading = control[HAPTIC_FLAGS], control[FADE_LEFT] > 0
    control[HAPTIC_FLAGS] = 0
    began = _now_ns(control)
    render_into(control, o, frames)
    busy = _now_ns(control) - began
    control[BUSY_TOTAL_NS] += busy
    if busy > control[BUSY_MAX_NS]:
        control[BUSY_MAX_NS] = busy
        control[BUSY_MAX_AT] = control[CALLBACKS]
    if busy > control[BUFFER_NS]:
        control[BUSY_OVER] += 1
    if control[TAP_LOG] != 0:  # the haptic samples and this buffer's DAC time, for the UDP sender
        dac = nb.carray(time_info, (3,), np.float64)[2]
        tap_callback(control, o, frames, dac, control[HAPTIC_FLAGS] | (FLAG_WATCHDOG if fading else 0))
    control[HAPTIC_FLAGS] |= flags_before
    control[PLAYED] += frames
    return 0


#: Parameters whose events the callback applies, per ugen class (others: Python only).
_RAMPED = {
    Gain: ("gain",),
    Scrape: ("force", "speed"),
    ResonantScrape: ("force", "speed"),
    Biquad: ("freq", "q"),
}
#: Record slot of each ramped parameter (see jassy.program's records).
_RAMP_SLOT = {
    (node, key): HEADER + slots._fields.index(field)
    for node, slots, key, field in (
        (Gain, GainSlots, "gain", "ramp"),
        (Scrape, ScrapeSlots, "force", "force_ramp"),
        (Scrape, ScrapeSlots, "speed", "speed_ramp"),
        (ResonantScrape, ResonantScrapeSlots, "force", "force_ramp"),
        (ResonantScrape, ResonantScrapeSlots, "speed", "speed_ramp"),
        (Biquad, BiquadSlots, "freq", "freq_ramp"),
        (Biquad, BiquadSlots, "q", "q_ramp"),
    )
}


def why_not_callback(graph: Graph, score: Sequence[Event], offsets_ms: dict | None, haptic_udp) -> str | None:
    """Why ``graph`` and ``score`` cannot be rendered in the callback (None if they can)."""
    reason = why_not_compiled(graph)
    if reason is not None:
        return reason
    if offsets_ms and any(offsets_ms.values()):
        return "per-channel offsets are applied by the ring producer"
    if haptic_udp:
        return "UDP haptic frames without haptic channels on the device are sent by the ring producer"
    for i, event in enumerate(score):
        reason = _event_not_supported(graph, event)
        if reason is not None:
            return f"score[{i}]: {reason}"
    return None


def choose_mode(
    mode: str, graph: Graph, score: Sequence[Event], offsets_ms: dict | None, haptic_udp
) -> tuple[str, str | None]:
    """("callback", None) or ("ring", why) for a requested mode: auto, callback or ring."""
    if mode not in ("auto", "callback", "ring"):
        raise JassyError(f"mode: expected auto, callback or ring, got {mode!r}")
    if mode == "ring":
        return "ring", "asked for"
    reason = why_not_callback(graph, score, offsets_ms, haptic_udp)
    if reason is not None and mode == "callback":
        raise JassyError(f"callback mode: {reason}")
    return ("ring", reason) if reason is not None else ("callback", None)


def _event_not_supported(graph: Graph, event: Event) -> str | None:
    node = graph.nodes.get(event.node)
    if node is None:
        return None  # reported by validation
    if event.action != "set":
        return None if isinstance(node, ImpactForce) else f"action {event.action!r} of {node.type_name}"
    if isinstance(node, (ModalBank, ImpactForce)):
        return None
    allowed = _RAMPED.get(type(node), ())
    for key in event.args:
        if key not in allowed:
            return f"{node.type_name} parameter {key!r} changes only between Python sub-blocks"
    return None


class CallbackStats(NamedTuple):
    """Counters of a callback-mode run."""

    callbacks: int
    xruns: int
    frames_played: int
    max_callback_frames: int
    status_flags: int
    device_latency: float
    dropped: int
    nonfinite: int
    realtime: bool
    busy_max: float  # s: the longest callback (rendering included)
    busy_mean: float  # s
    busy_over: int  # callbacks that took longer than a buffer lasts
    busy_max_at: int  # which callback was the longest (1 = the first)
    late_strikes: int = 0  # strikes that reached the callback after their frame: played at once


class EventQueue:
    """A single-producer single-consumer queue of event records in ``control``'s slots: the
    producer writes the record, then publishes the write position; the callback publishes
    the read position after applying."""

    def __init__(self, control: np.ndarray, index: int, capacity: int):
        self.records = np.zeros((capacity, EVENT))
        self.control = control
        self.slot = QUEUES + QUEUE_SLOTS * index
        control[self.slot] = address(self.records)
        control[self.slot + 1] = capacity

    @property
    def write(self) -> int:
        return int(self.control[self.slot + 2])

    @property
    def read(self) -> int:
        return int(self.control[self.slot + 3])

    def push(self, record: Sequence[float], timeout: float = 1.0) -> int:
        """Append a record (waits while full); returns its position."""
        cap = self.records.shape[0]
        w = self.write
        deadline = time.monotonic() + timeout
        while w - self.read >= cap:
            if time.monotonic() > deadline:
                raise JassyError("callback event queue full: the device stopped taking buffers")
            time.sleep(0.0005)
        self.records[w % cap, : len(record)] = record
        self.control[self.slot + 2] = w + 1
        return w


class EventRecords:
    """Translates validated events into the callback's event records (see the module
    docstring), as the offline scheduler would dispatch them (jassy.scheduler), for a
    prepared graph whose program is built. Translation updates the nodes' parameter
    values in event order; what needs the ugens' Python code (pulse amplitudes, modal
    designs) is computed here, so applying a record only copies and steps."""

    def __init__(self, graph: Graph, sample_rate: float):
        self.graph = graph
        self.sample_rate = float(sample_rate)
        self._bases = {node.name: 1 + i * RECORD for i, node in enumerate(graph.order)}
        self._queue: EventQueue | None = None
        self._pending = 0

    def records(self, event: Event, sample_time: float, queue: EventQueue) -> list[list[float]]:
        """The records that apply a validated event at fractional sample ``sample_time``, as
        the offline scheduler dispatches it (jassy.scheduler.Scheduler._dispatch); they are
        to be pushed, in order, into ``queue``."""
        self._queue = queue
        self._pending = 0
        frame = apply_frame(sample_time)
        node = self.graph.nodes[event.node]
        base = self._bases[event.node]
        out: list[list[float]] = []
        if event.action == "set":
            ramp = ramp_seconds(event, frame, self.sample_rate)
            for key, value in event.args.items():
                out.extend(self._set_records(node, base, frame, key, value, event.jump, ramp))
                self._pending = len(out)
            return out
        location = event.args.get("location")
        if location is not None:
            for target in self.graph.location_targets(event.node):
                base_t = self._bases[target.name]
                out.extend(self._set_records(target, base_t, frame, "location", location, True, None))
                self._pending = len(out)
        tau = event.args.get("duration") or node.values["duration"]
        samples = max(tau * self.sample_rate, MIN_PULSE_SAMPLES)
        amp = pulse_amplitude(float(event.args["impulse"]), float(self.sample_rate), sample_time, samples)
        out.append([frame, base, STRIKE, sample_time, samples, amp])
        return out

    def _ramp_samples(self, node, ramp: float | None) -> int:
        seconds = ramp if ramp is not None else node.values["smooth"]
        return int(round(seconds * self.sample_rate))

    def _set_records(self, node, base, frame, key, value, jump, ramp) -> list[list[float]]:
        node.values[key] = value
        if isinstance(node, ImpactForce):
            return []  # read by the next strikes, computed here
        m = 0 if jump else self._ramp_samples(node, ramp)
        if isinstance(node, ModalBank):
            node._refresh_design_cache()
            return [[frame, base, MODAL_TARGET, self.stage_design(node), m]]
        op = SET_BIQUAD if isinstance(node, Biquad) else SET_RAMP
        return [[frame, base, op, _RAMP_SLOT[(type(node), key)], value, m]]

    def stage_design(self, node: ModalBank) -> int:
        """The address of ``node``'s new design (c1, c2, g, d rows) for a MODAL_TARGET
        record; it must stay unchanged until the record is applied."""
        raise NotImplementedError


class ProgramRun(EventRecords):
    """A prepared graph's program with the control slots, event queues and output-stage
    arrays that :func:`sub_block` reads: the part the device callback and the offline
    engine share. ``params``: [ceiling, limiter release coefficient, max force (N), max
    force step per sample (N)]; ``output``: the LIMIT_* bits; ``meter``: the limiter meter's
    state array (jassy.safety.LimiterMeter.state) to update, a new one if None."""

    def __init__(
        self,
        graph: Graph,
        sample_rate: float,
        block: int,
        params,
        output: int,
        queue_capacity: int = 4096,
        meter: np.ndarray | None = None,
    ):
        super().__init__(graph, sample_rate)
        self.block = int(block)
        self.program = Program(graph)
        self.n_audio = len(graph.audio)
        self.rows = np.ascontiguousarray(graph.bus_rows)
        control = np.zeros(CONTROL, dtype=np.int64)
        self.control = control
        self.params = np.array(params, dtype=np.float64)
        self.stage = np.zeros((self.rows.size, self.block))
        self.limiter = np.ones(1)
        self.haptic_last = np.zeros(max(len(graph.haptic), 1))
        self.meter = np.zeros(METERED + 1) if meter is None else meter
        for slot, array in (
            (PROGRAM, self.program.table),
            (BUS, graph.bus),
            (ROWS, self.rows),
            (STAGE, self.stage),
            (PARAMS, self.params),
            (LIMITER, self.limiter),
            (HAPTIC_LAST, self.haptic_last),
            (METER, self.meter),
        ):
            control[slot] = address(array)
        control[BUS_COUNT] = graph.bus.shape[0]
        control[N_ROWS] = self.rows.size
        control[N_AUDIO] = self.n_audio
        control[BLOCK] = self.block
        control[OUTPUT] = output
        control[FADE_LEFT] = -1
        control[NEXT_CUT] = next_cut_address()
        control[OUTPUT_STAGE] = output_stage_address()
        self.score_queue = EventQueue(control, 0, queue_capacity)
        self.now_queue = EventQueue(control, 1, queue_capacity)

    @property
    def nonfinite(self) -> int:
        """NaN/Inf samples replaced by 0 so far."""
        return int(self.control[NONFINITE])

    def arrays(self) -> list[np.ndarray]:
        """Every array :func:`sub_block` reads or writes."""
        arrays = [array for group in self.program._arrays.values() for array in group]
        arrays += [self.program.table, self.graph.bus, self.rows, self.control, self.stage]
        arrays += [self.params, self.limiter, self.haptic_last, self.meter]
        return arrays + [self.score_queue.records, self.now_queue.records]


class CallbackRenderer(ProgramRun):
    """The graph's program and its event translation, driven by a PortAudio callback.

    Create, then ``open_stream`` (or drive :func:`render_into` directly in tests); events go
    through :meth:`push` (stamped) or :meth:`post` (live input)."""

    def __init__(
        self,
        graph: Graph,
        score: Sequence[Event],
        sample_rate: float,
        block: int,
        haptic_to_card: bool = True,
        haptic_safety: HapticSafety | None = None,
        monitor_seconds: float = 0.0,
        queue_capacity: int = 4096,
    ):
        self.safety = haptic_safety or HapticSafety()
        graph.prepare(float(sample_rate), int(block))
        for node in graph.order:
            if isinstance(node, ImpactForce):  # a fixed table: the callback never allocates
                node.pulses = np.zeros((PULSE_CAPACITY, PULSE_COLUMNS))
        params = [
            CEILING,
            release_coefficient(0.05, sample_rate),
            self.safety.max_force,
            self.safety.step(sample_rate),
        ]
        super().__init__(graph, sample_rate, block, params, LIMIT_AUDIO | LIMIT_HAPTIC, queue_capacity)
        control = self.control
        self.channels = self.n_audio + (len(graph.haptic) if haptic_to_card else 0)
        self.levels = np.zeros(max(self.channels, 1))
        mcap = int(round(monitor_seconds * self.sample_rate))
        self.monitor_signal = np.zeros((max(mcap, 1), max(self.channels, 1)))
        self.monitor_index = np.full(max(mcap, 1), -1, dtype=np.int64)
        for slot, array in (
            (MONITOR, self.monitor_signal),
            (MONITOR_INDEX, self.monitor_index),
            (LEVELS, self.levels),
        ):
            control[slot] = address(array)
        control[CHANNELS] = self.channels
        control[MONITOR_CAP] = mcap
        control[WATCHDOG] = max(1, int(self.safety.watchdog * self.sample_rate))
        self.priority = np.array([CALLBACK_PRIORITY, 0], dtype=np.int32)  # struct sched_param
        control[PRIORITY] = self.priority.ctypes.data
        control[REALTIME] = -1
        self.timespec = np.zeros(2, dtype=np.int64)
        control[CLOCK] = self.timespec.ctypes.data
        control[BUFFER_NS] = int(self.block / self.sample_rate * 1e9)
        self._staging: dict[str, tuple[np.ndarray, list]] = {}
        for node in graph.order:
            if isinstance(node, ModalBank):
                k = node.bank.shape[1]
                self._staging[node.name] = (np.zeros((MODAL_SLOTS, 4, k)), [None] * MODAL_SLOTS)
        self._staged = 0
        self.score = prepare_score(graph, score, self.sample_rate)
        self._next_score = 0
        self._lock = threading.Lock()
        self.late = 0  # posted events whose time had already been played
        self._warm_posts()

    def _warm_posts(self) -> None:
        """Translate (and drop) a silent impact on every ImpactForce node: the first
        translation loads the pulse kernel, milliseconds that would otherwise delay the
        first live tap after the stream starts."""
        for node in self.graph.order:
            if isinstance(node, ImpactForce):
                silent = Event(0.0, node.name, "impact", {"impulse": 0.0})
                self.records(validate_event(self.graph, silent, "warm-up"), 0.0, self.now_queue)

    def memory(self) -> list[np.ndarray]:
        """Every array the callback reads or writes (to keep resident: jassy.engines.memlock)."""
        arrays = self.arrays() + [self.levels, self.monitor_signal, self.monitor_index]
        arrays += [self.priority, self.timespec]
        return arrays + [staging for staging, _ in self._staging.values()]

    # --------------------------------------------------------------- translation
    def frame(self) -> int:
        """The next frame the callback renders."""
        return int(self.control[FRAME])

    def stage_design(self, node: ModalBank) -> int:
        """Copy ``node``'s new design into a free staging slot of its bank (waiting while
        all MODAL_SLOTS are queued); the slot is free again once its record is read."""
        staging, used_by = self._staging[node.name]
        slot = self._staged % MODAL_SLOTS
        self._staged += 1
        deadline = time.monotonic() + 1.0
        while used_by[slot] is not None and used_by[slot][0].read <= used_by[slot][1]:
            if time.monotonic() > deadline:
                raise JassyError("callback: the device stopped taking buffers")
            time.sleep(0.0005)
        staging[slot] = node._fresh
        used_by[slot] = (self._queue, self._queue.write + self._pending)  # free once read
        return staging[slot].ctypes.data

    # --------------------------------------------------------------------- input
    def feed(self, horizon_frames: int) -> None:
        """Push the score events due before frame ``now + horizon_frames``."""
        with self._lock:
            limit_frame = self.frame() + horizon_frames
            while self._next_score < len(self.score):
                event = self.score[self._next_score]
                sample_time = event.time * self.sample_rate
                if sample_time >= limit_frame:
                    break
                for record in self.records(event, sample_time, self.score_queue):
                    self.score_queue.push(record)
                self._next_score += 1

    def post(self, event: Event) -> int:
        """Apply a live event at its time if still ahead, else at the next sub-block; returns
        the frame it was stamped with."""
        event = validate_event(self.graph, event, "posted event")
        reason = _event_not_supported(self.graph, event)
        if reason is not None:
            raise JassyError(f"posted event: {reason} (not in callback mode)")
        with self._lock:
            if 0 < event.time * self.sample_rate < self.frame() - self.block:
                self.late += 1
            sample_time = max(event.time * self.sample_rate, float(self.frame()))
            records = self.records(event, sample_time, self.now_queue)
            for record in records:
                self.now_queue.push(record)
        return int(records[-1][0]) if records else self.frame()

    # ------------------------------------------------------------------- readout
    def stats(self, device_latency: float = 0.0) -> CallbackStats:
        c = self.control
        return CallbackStats(
            int(c[CALLBACKS]),
            int(c[XRUNS]),
            int(c[PLAYED]),
            int(c[MAX_FRAMES]),
            int(c[FLAGS]),
            device_latency,
            int(c[DROPPED]),
            int(c[NONFINITE]),
            bool(c[REALTIME] == 1),
            c[BUSY_MAX_NS] * 1e-9,
            c[BUSY_TOTAL_NS] * 1e-9 / max(int(c[CALLBACKS]), 1),
            int(c[BUSY_OVER]),
            int(c[BUSY_MAX_AT]),
            int(c[LATE_STRIKES]),
        )

    def levels_now(self) -> np.ndarray:
        """Peak |sample| per device channel in the last buffer (meters)."""
        return self.levels[: self.channels].copy()

    def monitor(self) -> tuple[np.ndarray, np.ndarray]:
        """What the device received last: (channels, frames) in playing order and the
        rendered frame of each (the same in callback mode: nothing is rendered ahead)."""
        cap = int(self.control[MONITOR_CAP])
        if not cap:
            raise JassyError("no monitor: create the engine with monitor_seconds > 0")
        played = int(self.control[PLAYED])
        size = min(played, cap)
        order = np.arange(played - size, played) % cap
        signal = self.monitor_signal[order].T.astype(np.float32).astype(np.float64)
        return signal, self.monitor_index[order].copy()

    def end(self) -> None:
        """Start the final fade of the haptic channels (to zero within the watchdog time)."""
        self.control[FADE_LEFT] = self.control[WATCHDOG]

    def faded(self) -> bool:
        return self.control[FADE_LEFT] == 0


class CallbackPlayer:
    """Plays a :class:`CallbackRenderer` on a PortAudio device; a feeder thread pushes the
    score ahead of the device (HORIZON s)."""

    def __init__(self, renderer: CallbackRenderer):
        self.renderer = renderer
        self.stream = None
        self.device_latency = 0.0
        self.resident = (0, 0)  # bytes of the callback's memory locked, only faulted in
        self._stop = threading.Event()
        self._feeder: threading.Thread | None = None
        self._error: BaseException | None = None

    def start(self, device: int | None) -> None:
        from jassy.engines import portaudio

        r = self.renderer
        horizon = int(HORIZON * r.sample_rate)
        r.feed(horizon)
        self.resident = resident(r.memory())
        self.stream = portaudio.OutputStream(
            portaudio.default_output_device() if device is None else device,
            r.channels,
            r.sample_rate,
            r.block,
            program_callback_address(),
            r.control.ctypes.data,
        )
        self.device_latency = self.stream.output_latency
        self.stream.start()
        self._feeder = threading.Thread(target=self._feed, args=(horizon,), name="jassy-feeder", daemon=True)
        self._feeder.start()

    def _feed(self, horizon: int) -> None:
        try:
            while not self._stop.wait(0.01):
                self.renderer.feed(horizon)
        except BaseException as exc:  # reported by stop()
            self._error = exc

    def stop(self) -> None:
        """Fade the forces, stop the feeder and the stream (PortAudio is released)."""
        from jassy.engines import portaudio

        r = self.renderer
        if self.stream is not None:
            r.end()
            deadline = time.monotonic() + 0.5  # a dead device never plays the fade
            while not r.faded() and time.monotonic() < deadline:
                time.sleep(0.001)
        self._stop.set()
        if self._feeder is not None:
            self._feeder.join(timeout=2.0)
        if self.stream is not None:
            self.stream.close()
            self.stream = None
            portaudio.release()
        if self._error is not None:
            raise JassyError(f"callback feeder: {type(self._error).__name__}: {self._error}")
