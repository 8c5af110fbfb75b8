"""Offline rendering of a program graph on the device callback's code path.

The score's events become the callback's event records (jassy.engines.callback.EventRecords) and
one compiled call, :func:`render_planar`, renders a run of frames: per sub-block it applies
the records due, runs the program and passes the output through the callback's output
stage (jassy.engines.callback.sub_block: NaN/Inf to 0, limiter and its meter, haptic limits), then
the per-channel offsets, and writes the result's rows. No Python runs per block or per
translated event; the sub-blocks, and so the output bits, are those of the node-by-node
scheduler (jassy.scheduler).

A run ends early after a sub-block that produced NaN/Inf (the engine then resets the nodes
that hold them), and before an event whose effect depends on the state at its frame (a
ModalBank's pole jump: freq_scale or decay_scale without a ramp, which keeps each ringing
mode's phase) or that has no record: the scheduler dispatches those in Python, as before.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from jassy import haptics, jit, program, safety
from jassy.engines import callback
from jassy.engines.callback import (
    BLOCK,
    EVENT_NODE,
    EVENT_OPCODE,
    FRAME,
    HAPTIC_FLAGS,
    LIMIT_AUDIO,
    LIMIT_HAPTIC,
    NONFINITE,
    STRIKE,
    ProgramRun,
    _event_not_supported,
    apply_due,
    program_table,
    sub_block,
)
from jassy.events import Event
from jassy.graph import Graph
from jassy.haptics import ChannelDelay, HapticSafety, delay_channels
from jassy.jit import address, drop_stale_cache, prefetch_for_write
from jassy.program import KERNEL_MODULES
from jassy.safety import CEILING, LimiterMeter
from jassy.scheduler import Scheduler, apply_frame, ramp_seconds
from ugens.cells import with_room
from ugens.impact import ImpactForce
from ugens.modal import ModalBank

drop_stale_cache(__file__, [callback, haptics, jit, program, safety, *KERNEL_MODULES])

#: Bytes of staged modal designs after which translation waits for the render to apply them.
DESIGN_BYTES = 1 << 24

#: Bytes of a cache line (x86-64, most arm64).
LINE_BYTES = 64

#: Records the event queues start with: the score queue grows as translation needs
#: (:meth:`OfflineProgram._push`), and no live event is posted offline. (The device
#: callback's 4096-record queues, 256 kB each, cost 80 us per render to map and unmap.)
QUEUE_RECORDS = 64

#: ModalBank parameters whose jump moves the poles: applied in Python at their frame (the
#: ringing modes keep their phase, which needs the state there).
POLE_KEYS = ("freq_scale", "decay_scale")


@nb.njit(cache=True, nogil=True, inline="always")  # inlined, as callback.apply_event
def prefetch_rows(out, at, m):
    """Ask for the cache lines of out[:, at : at + m] (float64 rows) ahead of their writes."""
    start = out.ctypes.data + at * out.itemsize
    for r in range(out.shape[0]):
        row = start + r * out.strides[0]
        for offset in range(0, m * out.itemsize, LINE_BYTES):
            prefetch_for_write(row + offset)


@nb.njit(cache=True, nogil=True)
def render_planar(control, out, offset, frames, delayed, history, delays, delay_pos):
    """Render up to ``frames`` frames from control[FRAME] through the output stage into
    out[:, offset:] (float64 rows: audio, then haptic), with the per-channel delays if
    ``delayed`` (jassy.haptics.delay_channels); return the frames rendered: fewer if a
    sub-block produced NaN/Inf (it is rendered, its NaN/Inf zeroed).

    The result's cache lines of each sub-block are asked for before its program runs, so
    that its output stage does not wait for them."""
    prog = program_table(control)
    block = control[BLOCK]
    nonfinite = control[NONFINITE]
    begin = control[FRAME]
    pos = begin
    end = begin + frames
    while pos < end:
        at = offset + pos - begin
        prefetch_rows(out, at, min(block, end - pos))
        stop = sub_block(control, prog, pos, end, out, at)
        if delayed:
            delay_channels(out[:, at:], stop - pos, history, delays, delay_pos)
        pos = stop
        if control[NONFINITE] != nonfinite:
            break
    control[FRAME] = pos
    return pos - begin


class OfflineProgram(ProgramRun):
    """A program graph's offline renderer: the scheduler's events translated into records
    run by run, each run one compiled call (see the module docstring). Build it before the
    graph's Scheduler (the program decides which events split sub-blocks), then
    :meth:`attach` the scheduler."""

    def __init__(
        self,
        graph: Graph,
        sample_rate: float,
        block: int,
        limiter: bool,
        release: float,
        meter: LimiterMeter,
        haptic_safety: HapticSafety | None,
        delay: ChannelDelay,
    ):
        safety = haptic_safety or HapticSafety()
        params = [CEILING, release, safety.max_force, safety.step(sample_rate)]
        output = (LIMIT_AUDIO if limiter else 0) | (LIMIT_HAPTIC if haptic_safety is not None else 0)
        super().__init__(graph, sample_rate, block, params, output, QUEUE_RECORDS, meter.state)
        self.delay = delay
        self.scheduler: Scheduler | None = None
        self._designs: list[np.ndarray] = []  # staged designs, kept until applied
        self._strikes: dict[int, int] = {}  # strikes queued since the queue last drained, per node
        self._impacts = {self._bases[n.name]: n for n in graph.order if isinstance(n, ImpactForce)}

    def attach(self, scheduler: Scheduler) -> None:
        self.scheduler = scheduler

    def stage_design(self, node: ModalBank) -> int:
        """A new design is a new array (ModalBank._design): keep it until applied."""
        self._designs.append(node._fresh)
        return address(node._fresh)

    def translatable(self, event: Event) -> bool:
        """Whether ``event`` has records that apply it as the scheduler's dispatch does."""
        graph = self.graph
        if _event_not_supported(graph, event) is not None:
            return False
        node = graph.nodes[event.node]
        if event.action != "set":
            if event.args.get("location") is None:
                return True
            return all(isinstance(t, ModalBank) for t in graph.location_targets(event.node))
        if isinstance(node, ModalBank) and any(key in POLE_KEYS for key in event.args):
            return not event.jump and self._event_ramp_samples(node, event) >= 1
        return True

    def _event_ramp_samples(self, node, event: Event) -> int:
        """The samples a set event ramps over, as :meth:`records` computes them."""
        rate = self.sample_rate
        return self._ramp_samples(node, ramp_seconds(event, apply_frame(event.time * rate), rate))

    def _translate(self, end: int, ahead: int) -> tuple[int, bool]:
        """Queue the records of the scheduler's next events applied before frame ``ahead``
        (>= ``end``), up to the first that is not translatable or until the staged designs
        reach DESIGN_BYTES. Returns (the frame of the first event left before ``end``, else
        ``end``; whether that event is left for Python)."""
        sched = self.scheduler
        queue = self.score_queue
        if queue.read == queue.write:  # drained: start the ring afresh, free the staged designs
            self.control[queue.slot + 2] = self.control[queue.slot + 3] = 0
            self._designs.clear()
            self._strikes.clear()
        left = sched.next_event
        if left == len(sched.events) or sched.apply_frames[left] >= ahead:
            return end, False  # nothing to translate
        records = []
        strikes = self._strikes
        frames, events = sched.apply_frames, sched.events
        stop, python = end, False
        staged = sum(design.nbytes for design in self._designs)
        while sched.next_event < len(events) and frames[sched.next_event] < ahead:
            i = sched.next_event
            python = not self.translatable(events[i])
            if python or staged > DESIGN_BYTES:
                stop = min(end, frames[i])
                break
            designs_before = len(self._designs)
            for record in self.records(events[i], sched.sample_times[i], queue):
                records.append(record)
                if record[EVENT_OPCODE] == STRIKE:
                    node = int(record[EVENT_NODE])
                    strikes[node] = strikes.get(node, 0) + 1
            staged += sum(design.nbytes for design in self._designs[designs_before:])
            sched.next_event += 1
        if records:
            self._push(records)
        for base, count in strikes.items():
            node = self._impacts[base]
            if int(node.count[0]) + count <= node.pulses.shape[0]:
                continue  # room enough (a compiled call from here costs ~15 us, caches cold)
            grown = with_room(node.pulses, int(node.count[0]) + count)
            if grown is not node.pulses:
                node.pulses = grown
                self.program.sync()
        return stop, python and stop < end

    def _push(self, records: list[list[float]]) -> None:
        """Append records to the score queue, growing its ring if they do not fit."""
        queue, control = self.score_queue, self.control
        w, r = queue.write, queue.read
        cap = queue.records.shape[0]
        if w - r + len(records) > cap:
            size = cap
            while w - r + len(records) > size:
                size *= 2
            grown = np.zeros((size, queue.records.shape[1]))
            for j in range(r, w):
                grown[j - r] = queue.records[j % cap]
            queue.records = grown
            control[queue.slot] = address(grown)
            control[queue.slot + 1] = size
            control[queue.slot + 2], control[queue.slot + 3] = w - r, 0
            w, cap = w - r, size
        for j, record in enumerate(records):
            queue.records[(w + j) % cap, : len(record)] = record
        control[queue.slot + 2] = w + len(records)

    def render(self, out: np.ndarray, offset: int, n: int, ahead: int = 0) -> tuple[int, int]:
        """Render up to ``n`` frames into out[:, offset:], dispatching in Python the events
        that have no record at their frames; the events of the next ``max(n, ahead)``
        frames are translated now. Returns (frames rendered, haptic flags); fewer frames
        than ``n`` if a sub-block produced NaN/Inf."""
        sched, control, delay = self.scheduler, self.control, self.delay
        control[HAPTIC_FLAGS] = 0
        done = 0
        while done < n:
            pos = sched.frame
            end = pos + n - done
            stop, python = self._translate(end, pos + max(n - done, ahead - done))
            if stop > pos:
                control[FRAME] = pos
                got = render_planar(
                    control,
                    out,
                    offset + done,
                    stop - pos,
                    delay.active,
                    delay.history,
                    delay.delays,
                    delay.pos,
                )
                sched.frame = pos + got
                done += got
                if got < stop - pos:
                    break
                continue
            apply_due(control, pos)  # an event at this frame was left untranslated
            if python:
                sched._dispatch_due(pos, 1 << 62)
                self.program.sync()
        return done, int(control[HAPTIC_FLAGS])
