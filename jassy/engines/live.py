"""Live engine: a producer thread renders ahead into a lock-free ring; the sound card
callback is a numba ``@cfunc`` that only copies frames, so it never takes the GIL, never
allocates and never compiles.

Shared memory (one anonymous mmap, laid out by the slot constants below): an int64 header
(positions, counters, control flags), float64 haptic state, float32 interleaved ring
frames, and an optional monitor: a float32 ring where the callback keeps a copy of what it
sent to the device, with an int64 ring of the rendered frame each output frame came from
(-1 for silence inserted on an underrun); tests and benchmarks read the true output from
it. Single producer (``_ring_write`` publishes the write position after the frames) and
single consumer (the callback publishes the read position after reading); positions only
grow, so ``write - read`` is the fill level.

The haptic channels are made safe in the callback itself, the last stage before the
device: |force| clamp, slew-rate limit, and on a stall (ring empty) a linear fade of the
force to zero within the watchdog time (at most 10 ms).
"""

from __future__ import annotations

import gc
import mmap
import multiprocessing
import os
import sys
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numba as nb
import numpy as np
from numba import types

from jassy.engines.callback import PLAYED as CALLBACK_PLAYED
from jassy.engines.callback import (
    TAP_HAPTIC_ROWS,
    TAP_LOG,
    TAP_LOG_ROWS,
    TAP_LOGGED,
    CallbackPlayer,
    CallbackRenderer,
    choose_mode,
)
from jassy.engines.hapticframes import FLAG_CLAMPED, FLAG_SLEW, FLAG_STALLED, FLAG_WATCHDOG, parse_address
from jassy.engines.hapticsender import (
    CLOCK_OFFSET,
    CONTROL_SLOTS,
    DONE,
    LOG_COLUMNS,
    LOG_DAC,
    LOG_FLAGS,
    LOG_FRAMES,
    LOG_START,
    STOP_AT,
    StreamTap,
    child_setup,
    run_sender,
)
from jassy.engines.memlock import resident
from jassy.engines.offline import OfflineEngine
from jassy.errors import JassyError
from jassy.events import Event
from jassy.graph import Graph
from jassy.haptics import HapticSafety
from jassy.scheduler import validate_event
from ugens.impact import ImpactForce

HEADER, STATE, DATA_OFFSET_F32 = 32, 128, 256  # int64 slots, float64 slots, first float32 slot
CAP, CHANNELS, N_AUDIO, WRITE, READ, UNDER_FRAMES, CALLBACKS, UNDER_CALLBACKS, FLAGS = range(9)
WATCHDOG, FADE_LEFT, PLAYED, MONITOR_CAP, MAX_FRAMES, STALLED = range(9, 15)
RUNNING, STOP, PAUSED, LATE, REALTIME, TAKEN_AT = range(15, 21)
DEVICE_CH, TAIL_OFFSET, LOG_ROWS, HAPTIC_ROWS, LOGGED, ENDING, HAPTIC_CH = range(21, 28)
UNDERFLOWS = 28  # callbacks PortAudio flagged with paOutputUnderflow (the device ran late)
MAX_FORCE, MAX_STEP, DEVICE_LATENCY, LAST, FADE_FROM = 32, 33, 34, 40, 72  # float64 slots
MAX_HAPTIC = 32
#: Callbacks logged and haptic frames kept for the UDP sender (about 1.4 s and 85 ms).
CALLBACK_LOG_ROWS, HAPTIC_RING_ROWS = 1024, 4096
#: GIL switch interval while live (s): short enough for the producer to keep the ring full.
SWITCH_INTERVAL = 0.0002
#: Seconds between measurements of the stream clock against the monotonic clock, and the
#: weight of each in their running average (the stream clock jitters with the callbacks).
CLOCK_CHECK, CLOCK_WEIGHT = 0.02, 0.05
#: SCHED_FIFO priority of the producer thread where the OS grants it (JACK uses 70-95).
REALTIME_PRIORITY = 40


@nb.cfunc(
    types.int32(types.voidptr, types.voidptr, types.uint64, types.voidptr, types.uint64, types.voidptr),
    cache=True,
)
def ring_callback(inp, out, frames, time_info, status, user):
    """PortAudio callback: copy ring frames to the device, make haptics safe, log the
    haptic samples and this callback's device time for the UDP sender, count."""
    hdr = nb.carray(user, (HEADER,), np.int64)
    f64 = nb.carray(user, (STATE,), np.float64)
    cap, ch, na, dch, mcap = hdr[CAP], hdr[CHANNELS], hdr[N_AUDIO], hdr[DEVICE_CH], hdr[MONITOR_CAP]
    nh = hdr[HAPTIC_CH]  # then, if nh > 0, one channel of the producer's limiter flags
    f32 = nb.carray(user, (DATA_OFFSET_F32 + cap * ch + mcap * dch,), np.float32)
    toff, lrows, hrows = hdr[TAIL_OFFSET], hdr[LOG_ROWS], hdr[HAPTIC_ROWS]
    tail = nb.carray(user, (toff + lrows * LOG_COLUMNS + hrows * nh,), np.float64)
    dac = nb.carray(time_info, (3,), np.float64)[2]  # outputBufferDacTime (s, stream clock)
    o = nb.carray(out, (frames * dch,), np.float32)
    hdr[CALLBACKS] += 1
    hdr[FLAGS] |= status
    if status & 4:  # paOutputUnderflow
        hdr[UNDERFLOWS] += 1
    if frames > hdr[MAX_FRAMES]:
        hdr[MAX_FRAMES] = frames
    r = hdr[READ]
    p = hdr[PLAYED]
    avail = hdr[WRITE] - r
    n = frames if avail >= frames else avail
    max_force, max_step, window = f64[MAX_FORCE], f64[MAX_STEP], hdr[WATCHDOG]
    ending = hdr[ENDING] != 0
    flags = 0
    for i in range(frames):
        base = DATA_OFFSET_F32 + ((r + i) % cap) * ch
        have = i < n
        feed = have and not ending  # at the end, forces fade to zero as on a stall
        if feed:
            hdr[STALLED] = 0
        elif hdr[STALLED] == 0:  # the ring just ran dry (or the run ends): start the fade
            hdr[STALLED] = 1
            hdr[FADE_LEFT] = window
            for c in range(nh):
                f64[FADE_FROM + c] = f64[LAST + c]
        if not have and not ending:
            flags |= FLAG_STALLED
        if feed and nh > 0:
            flags |= int(f32[base + na + nh])  # clamped / slew-limited while rendering
        for c in range(na):
            x = f32[base + c] if have else 0.0
            if x != x:  # NaN
                x = 0.0
            o[i * dch + c] = min(max(x, -1.0), 1.0)
        left = hdr[FADE_LEFT]
        hbase = toff + lrows * LOG_COLUMNS + ((p + i) % hrows) * nh
        for c in range(nh):
            y = f64[LAST + c]
            if feed:
                x = f32[base + na + c]
                if x != x:  # NaN
                    x = 0.0
                if x > max_force or x < -max_force:
                    flags |= FLAG_CLAMPED
                    x = min(max(x, -max_force), max_force)
                if x > y + max_step or x < y - max_step:
                    flags |= FLAG_SLEW
                    x = min(max(x, y - max_step), y + max_step)
            else:
                x = f64[FADE_FROM + c] * (left - 1) / window if left > 0 else 0.0
                if left > 0:
                    flags |= FLAG_WATCHDOG
            f64[LAST + c] = x
            if dch > na:
                o[i * dch + na + c] = x
            tail[hbase + c] = x
        if not feed and left > 0:
            hdr[FADE_LEFT] = left - 1
    if n < frames and hdr[STOP] == 0 and not ending:  # running dry while stopping is no glitch
        hdr[UNDER_FRAMES] += frames - n
        hdr[UNDER_CALLBACKS] += 1
    hdr[READ] = r + n
    row = toff + (hdr[LOGGED] % lrows) * LOG_COLUMNS
    tail[row + LOG_START] = p
    tail[row + LOG_FRAMES] = frames
    tail[row + LOG_DAC] = dac
    tail[row + LOG_FLAGS] = flags
    hdr[LOGGED] += 1
    if mcap > 0:
        mbase = DATA_OFFSET_F32 + cap * ch
        ibase = (DATA_OFFSET_F32 + cap * ch + mcap * dch + 1) // 2  # int64 slot after the float32 data
        index = nb.carray(user, (ibase + mcap,), np.int64)
        for i in range(frames):
            slot = (p + i) % mcap
            k = mbase + slot * dch
            for c in range(dch):
                f32[k + c] = o[i * dch + c]
            index[ibase + slot] = r + i if i < n else -1
    hdr[PLAYED] = p + frames
    return 0


@nb.njit(cache=True, nogil=True)
def _ring_write(hdr, f32, block, n):
    """Append block[:, :n] (channels, frames) to the ring and publish it."""
    cap, ch, w = hdr[CAP], hdr[CHANNELS], hdr[WRITE]
    for i in range(n):
        base = DATA_OFFSET_F32 + ((w + i) % cap) * ch
        for c in range(ch):
            f32[base + c] = block[c, i]
    hdr[WRITE] = w + n


def _request_realtime_priority() -> bool:
    """Ask the OS to schedule the calling thread with SCHED_FIFO (needs root, CAP_SYS_NICE
    or an rtprio limit); True if granted. It wakes the producer promptly after its sleeps,
    which matters far more than CPU speed for keeping a few-ms ring full."""
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(REALTIME_PRIORITY))
    except (AttributeError, OSError):
        return False
    return True


@dataclass
class LiveStats:
    """Counters of a live run."""

    callbacks: int
    underrun_callbacks: int
    underrun_frames: int
    frames_played: int
    max_callback_frames: int
    status_flags: int
    ring_latency: float
    device_latency: float
    late_events: int
    realtime: bool
    #: "callback" (the graph rendered in the device callback) or "ring" (a producer ahead).
    mode: str = "ring"
    #: Callbacks the host flagged as late (output underflow), in either mode; in callback
    #: mode these are the underruns.
    device_underflows: int = 0

    @property
    def latency(self) -> float:
        """Event-to-DAC latency (s): ring depth plus the device's output latency."""
        return self.ring_latency + self.device_latency

    def summary(self) -> str:
        pct = 100.0 * self.underrun_callbacks / max(self.callbacks, 1)
        return (
            f"{self.mode} mode: {self.callbacks} callbacks, "
            f"{self.underrun_callbacks} underruns ({pct:.3f} %), "
            f"latency {self.latency * 1e3:.2f} ms (ring {self.ring_latency * 1e3:.2f} ms + device "
            f"{self.device_latency * 1e3:.2f} ms)"
        )


class LiveEngine:
    """Plays a graph and score in real time on a PortAudio device.

    Audio channels, then haptic channels if ``haptic_to_card``, go to the device in one
    stream, so they share the clock exactly. ``ring_blocks`` blocks (may be fractional:
    2.5 blocks of 64 = 160 frames) are rendered ahead; that ring depth is the engine's
    latency, on top of the device's.

    isolation: "process" runs the producer (and the stream) in a forked child process, so
    the caller's Python work never holds the GIL the producer needs: the robust choice
    for a few-ms ring; "thread" runs it in a thread of this process (shares the GIL;
    the switch interval is shortened while playing); "auto" picks "process" where fork
    is available and PortAudio is not yet loaded in this process.

    mode: "callback" renders the graph inside the device callback (jassy.engines.callback: no ring,
    latency = the device's); "ring" uses the producer above; "auto" (the default) takes
    the callback where the graph, score and options allow it (``mode_reason`` says why
    not otherwise): it never has fewer frames of latency, and its underruns on a loaded
    machine are the host's own (see ``jassy bench live --floor``).
    """

    def __init__(
        self,
        graph: Graph,
        score: Sequence[Event] = (),
        sample_rate: float = 48000,
        block: int = 64,
        ring_blocks: float = 2.5,
        device: str | int | None = None,
        haptic_to_card: bool = True,
        haptic_udp: str | None = None,
        haptic_safety: HapticSafety | None = None,
        offsets_ms: dict[str, float] | None = None,
        monitor_seconds: float = 0.0,
        isolation: str = "auto",
        haptic_torque: int = 0,
        send_log_frames: int = 0,
        mode: str = "auto",
    ):
        if not ring_blocks >= 1:
            raise JassyError(f"--ring: expected at least 1 block, got {ring_blocks}")
        if haptic_to_card and len(graph.haptic) > MAX_HAPTIC:
            raise JassyError(f"at most {MAX_HAPTIC} haptic channels can go to a sound card")
        if isolation not in ("auto", "thread", "process"):
            raise JassyError(f"isolation: expected auto, thread or process, got {isolation!r}")
        self.graph, self.score = graph, list(score)
        self.sample_rate, self.block = float(sample_rate), int(block)
        self.safety = haptic_safety or HapticSafety()
        self.offsets_ms = offsets_ms
        self.device = device
        self.isolation = isolation
        self.haptic_to_card = haptic_to_card and bool(graph.haptic)
        self.n_audio = len(graph.audio)
        n_haptic = len(graph.haptic)
        if not 0 <= haptic_torque <= n_haptic:
            raise JassyError(f"haptic_torque: expected 0..{n_haptic} torque channels, got {haptic_torque}")
        # the ring always carries the haptics and the flags of their limiter
        self.ring_channels = self.n_audio + n_haptic + (1 if n_haptic else 0)
        self.channels = self.n_audio + (n_haptic if self.haptic_to_card else 0)  # to the device
        self.capacity = int(round(ring_blocks * self.block))  # frames; refilled a block at a time
        self.monitor_capacity = int(round(monitor_seconds * self.sample_rate))
        floats = DATA_OFFSET_F32 + self.capacity * self.ring_channels + self.monitor_capacity * self.channels
        self._index_start = (floats + 1) // 2  # int64 slot of the monitor's frame index
        tail = self._index_start + self.monitor_capacity  # float64 slot: callback log, haptic ring
        control = tail + CALLBACK_LOG_ROWS * LOG_COLUMNS + HAPTIC_RING_ROWS * n_haptic
        sends = control + CONTROL_SLOTS
        # anonymous shared memory: seen by forked producer and sender processes at the same address
        self._mmap = mmap.mmap(-1, (sends + send_log_frames + 16) * 8)
        raw = np.frombuffer(self._mmap, dtype=np.float64)
        self._memory = raw
        self.header = raw.view(np.int64)[:HEADER]
        self.state = raw[:STATE]
        self.f32 = raw.view(np.float32)[:floats]
        self.header[CAP], self.header[CHANNELS], self.header[N_AUDIO] = (
            self.capacity,
            self.ring_channels,
            self.n_audio,
        )
        self.header[DEVICE_CH], self.header[HAPTIC_CH] = self.channels, n_haptic
        self.header[MONITOR_CAP] = self.monitor_capacity
        self.header[TAIL_OFFSET], self.header[LOG_ROWS], self.header[HAPTIC_ROWS] = (
            tail,
            CALLBACK_LOG_ROWS,
            HAPTIC_RING_ROWS,
        )
        self.tap = StreamTap(
            self.header,
            LOGGED,
            raw[tail : tail + CALLBACK_LOG_ROWS * LOG_COLUMNS].reshape(CALLBACK_LOG_ROWS, LOG_COLUMNS),
            raw[tail + CALLBACK_LOG_ROWS * LOG_COLUMNS : control].reshape(HAPTIC_RING_ROWS, n_haptic),
            raw[control:sends],
            raw[sends : sends + send_log_frames],
        )
        self.tap.control[STOP_AT] = -1
        self.haptic_torque = haptic_torque
        self.header[WATCHDOG] = max(1, int(self.safety.watchdog * self.sample_rate))
        self.state[MAX_FORCE] = self.safety.max_force
        self.state[MAX_STEP] = self.safety.step(self.sample_rate)
        self._haptic_udp = parse_address(haptic_udp) if haptic_udp and graph.haptic else None
        self._sender = None
        self._events_rx, self._events_tx = multiprocessing.Pipe(duplex=False)
        self._errors_rx, self._errors_tx = multiprocessing.Pipe(duplex=False)
        self._worker = None
        udp_off_card = bool(self._haptic_udp) and not self.haptic_to_card  # only the ring sends those
        self.mode, self.mode_reason = choose_mode(mode, graph, self.score, offsets_ms, udp_off_card)
        self._callback: CallbackPlayer | None = None
        self._clock: threading.Thread | None = None
        self._clock_stop = threading.Event()

    # ------------------------------------------------------------------ control
    def start(self, timeout: float = 60.0) -> None:
        """Start the producer (warm-up, prefill, open and start the stream) and wait
        until the device is running."""
        from jassy.engines import portaudio
        from jassy.engines.devices import find_device

        self._device_index = None if self.device is None else find_device(self.device)
        resident([self._memory])  # the rings, monitor and tap the callbacks write
        if self._haptic_udp is not None:  # forked first: before PortAudio runs in this process
            self._sender = multiprocessing.get_context("fork").Process(
                target=self._sender_main, args=(os.getpid(),), name="jassy-haptic-udp", daemon=True
            )
            self._sender.start()
        if self.mode == "callback":
            renderer = CallbackRenderer(
                self.graph,
                self.score,
                self.sample_rate,
                self.block,
                self.haptic_to_card,
                self.safety,
                self.monitor_capacity / self.sample_rate,
            )
            if self._sender is not None:
                self._tap_into(renderer.control)
            self._callback = CallbackPlayer(renderer)
            self._callback.start(self._device_index)
            if self._sender is not None:
                self._clock = threading.Thread(target=self._track_clock, name="jassy-clock", daemon=True)
                self._clock.start()
            return
        use_process = self.isolation == "process" or (
            self.isolation == "auto" and hasattr(os, "fork") and not portaudio.loaded()
        )
        if use_process:
            if portaudio.loaded():
                raise JassyError("isolation='process' needs PortAudio not yet loaded in this process")
            self._worker = multiprocessing.get_context("fork").Process(
                target=self._producer_main, args=(os.getpid(),), name="jassy-producer", daemon=True
            )
        else:
            self._switch_interval = sys.getswitchinterval()
            sys.setswitchinterval(SWITCH_INTERVAL)
            self._worker = threading.Thread(target=self._producer_main, name="jassy-producer", daemon=True)
        self._worker.start()
        deadline = time.monotonic() + timeout
        while self.header[RUNNING] == 0:
            self._raise_producer_error()
            if time.monotonic() > deadline:
                self.stop()
                raise JassyError(f"the live engine did not start within {timeout:g} s")
            time.sleep(0.01)

    def post(self, event: Event) -> None:
        """Schedule ``event`` from any thread: at its time if still ahead, else at the
        next frame to be rendered (``time = 0`` means as soon as possible; a later time
        already rendered counts as a late event)."""
        if self._callback is not None:
            self._callback.renderer.post(event)
            return
        self._events_tx.send(event)

    def pause_producer(self, paused: bool) -> None:
        """Stall (True) or resume the producer: for testing the haptic watchdog."""
        self.header[PAUSED] = int(paused)

    def stop(self) -> LiveStats:
        """End the run in order: fade the forces to zero within the watchdog time, send the
        UDP frames through the last sample played and then the final frame, stop the
        stream, end the child processes; return the counters."""
        if self._callback is not None:
            renderer = self._callback.renderer
            if self._callback.stream is not None:
                renderer.end()
                deadline = time.monotonic() + 0.5  # a dead device never plays the fade
                while not renderer.faded() and time.monotonic() < deadline:
                    time.sleep(0.001)
            self._finish_sender(int(renderer.control[CALLBACK_PLAYED]), self._callback.device_latency)
            self._clock_stop.set()
            if self._clock is not None:
                self._clock.join()
            self._callback.stop()
            return self.stats()
        h = self.header
        if h[RUNNING] and not h[ENDING]:
            h[ENDING] = 1
            faded_at = h[PLAYED] + h[WATCHDOG] + 2 * self.block
            deadline = time.monotonic() + 0.5  # a dead device never plays the fade
            while h[PLAYED] < faded_at and time.monotonic() < deadline:
                time.sleep(0.001)
        self._finish_sender(int(h[PLAYED]), float(self.state[DEVICE_LATENCY]))
        h[STOP] = 1
        if self._worker is not None:
            self._worker.join(timeout=5.0)
            if isinstance(self._worker, threading.Thread):
                sys.setswitchinterval(self._switch_interval)
            else:
                if self._worker.is_alive():
                    self._worker.kill()
                self._worker.join()
        self._worker = None
        self._raise_producer_error()
        return self.stats()

    def _finish_sender(self, played: int, device_latency: float) -> None:
        """Let the UDP sender send the frames through stream frame ``played``, then the
        final frame, and end its process."""
        if self._sender is None:
            return
        self.tap.control[STOP_AT] = played
        deadline = time.monotonic() + device_latency + 1.0
        while not self.tap.control[DONE] and time.monotonic() < deadline:
            time.sleep(0.001)
        self._sender.join(timeout=1.0)
        if self._sender.is_alive():
            self._sender.kill()
            self._sender.join()
        self._sender = None

    def _tap_into(self, control: np.ndarray) -> None:
        """Point the callback renderer's tap slots at this engine's stream tap (shared
        memory the sender process reads)."""
        control[TAP_LOG] = self.tap.log.ctypes.data
        control[TAP_LOG_ROWS], control[TAP_HAPTIC_ROWS] = self.tap.log.shape[0], self.tap.played.shape[0]
        control[TAP_LOGGED] = self.header.ctypes.data + LOGGED * self.header.itemsize

    def _track_clock(self) -> None:
        """Callback mode: keep the stream-clock offset for the sender up to date."""
        stream = self._callback.stream
        control = self.tap.control
        control[CLOCK_OFFSET] = stream.clock_offset()
        while not self._clock_stop.wait(CLOCK_CHECK):
            offset = control[CLOCK_OFFSET]
            control[CLOCK_OFFSET] = offset + CLOCK_WEIGHT * (stream.clock_offset() - offset)

    def _raise_producer_error(self) -> None:
        if self._errors_rx.poll():
            message = self._errors_rx.recv()
            raise JassyError(f"live engine: {message}")

    def stats(self) -> LiveStats:
        if self._callback is not None:
            c = self._callback.renderer.stats(self._callback.device_latency)
            return LiveStats(
                c.callbacks,
                c.xruns,
                c.xruns * self.block,
                c.frames_played,
                c.max_callback_frames,
                c.status_flags,
                0.0,
                c.device_latency,
                self._callback.renderer.late + c.late_strikes,
                c.realtime,
                "callback",
                c.xruns,
            )
        h = self.header
        return LiveStats(
            int(h[CALLBACKS]),
            int(h[UNDER_CALLBACKS]),
            int(h[UNDER_FRAMES]),
            int(h[PLAYED]),
            int(h[MAX_FRAMES]),
            int(h[FLAGS]),
            self.capacity / self.sample_rate,
            float(self.state[DEVICE_LATENCY]),
            int(h[LATE]),
            bool(h[REALTIME]),
            "ring",
            int(h[UNDERFLOWS]),
        )

    def callback_stats(self):
        """Callback mode: the renderer's counters (jassy.engines.callback.CallbackStats), else None."""
        return (
            None if self._callback is None else self._callback.renderer.stats(self._callback.device_latency)
        )

    def haptic_now(self) -> np.ndarray:
        """The haptic sample (per channel) the callback handed to the device last."""
        if self._callback is not None:
            return self._callback.renderer.haptic_last[: len(self.graph.haptic)].copy()
        played = int(self.header[PLAYED])
        rows = self.tap.played.shape[0]
        return self.tap.played[(played - 1) % rows].copy() if played else np.zeros(self.tap.played.shape[1])

    def monitor(self) -> tuple[np.ndarray, np.ndarray]:
        """What the device received last: (channels, frames) signals in playing order, and
        per frame the rendered frame it came from (-1 for silence inserted on an underrun)."""
        if self._callback is not None:
            return self._callback.renderer.monitor()
        if not self.monitor_capacity:
            raise JassyError("no monitor: create the engine with monitor_seconds > 0")
        played = int(self.header[PLAYED])
        size = min(played, self.monitor_capacity)
        ring = self.f32[DATA_OFFSET_F32 + self.capacity * self.ring_channels :].reshape(-1, self.channels)
        order = (np.arange(played - size, played)) % self.monitor_capacity
        index = self._memory.view(np.int64)[self._index_start : self._index_start + self.monitor_capacity]
        return ring[order].T.astype(np.float64), index[order].copy()

    # ----------------------------------------------------------------- producer
    def _sender_main(self, parent: int) -> None:
        """The UDP haptic sender's process (see :mod:`jassy.engines.hapticsender`)."""
        child_setup(parent)
        run_sender(self.tap, self._haptic_udp, self.sample_rate, self.haptic_torque)

    def _producer_main(self, parent: int | None = None) -> None:
        """Producer: runs in the child process (``parent`` = the caller's pid) or a thread
        until ``stop``."""
        stream = None
        if parent is not None:
            child_setup(parent)
        try:
            from jassy.engines import portaudio

            engine = self._warm_engine()
            buf = np.zeros((len(self.graph.bus_rows), self.block))
            out = np.zeros((self.ring_channels, self.block))
            self._haptic_rows = self.n_audio + len(self.graph.haptic)
            while self._fill_once(engine, buf, out):
                pass
            stream = portaudio.OutputStream(
                portaudio.default_output_device() if self._device_index is None else self._device_index,
                self.channels,
                self.sample_rate,
                self.block,
                ring_callback.address,
                self._memory.ctypes.data,
            )
            self.state[DEVICE_LATENCY] = stream.output_latency
            self.header[REALTIME] = int(_request_realtime_priority())
            gc.freeze()  # objects alive now are never scanned by the collector during the run
            self.tap.control[CLOCK_OFFSET] = stream.clock_offset()
            stream.start()
            self.tap.control[CLOCK_OFFSET] = stream.clock_offset()
            self.header[RUNNING] = 1
            pause = self.block / self.sample_rate / 4
            calibrate_at = time.monotonic() + CLOCK_CHECK
            while not self.header[STOP]:
                if self.header[PAUSED] or not self._fill_once(engine, buf, out):
                    time.sleep(pause)
                if time.monotonic() > calibrate_at:
                    offset = self.tap.control[CLOCK_OFFSET]
                    self.tap.control[CLOCK_OFFSET] = offset + CLOCK_WEIGHT * (stream.clock_offset() - offset)
                    calibrate_at += CLOCK_CHECK
        except BaseException as exc:  # reported to the caller; the callback keeps the device safe
            self._errors_tx.send(f"{type(exc).__name__}: {exc}")
        finally:
            if stream is not None:
                stream.close()
            gc.unfreeze()
            if isinstance(self._worker, threading.Thread):
                from jassy.engines import portaudio

                portaudio.release()  # leave this process as it was: the next engine may fork

    def _warm_engine(self) -> OfflineEngine:
        """Compile and warm every kernel on a scratch run, then the engine for real.

        The scratch run also applies one event of each (node, action) kind in the score,
        inside its second block: the first use of an action (and of a block split by an
        event) loads kernels, which takes milliseconds, more than a few-ms ring holds."""
        kinds = {}
        for event in self.score:
            kinds.setdefault((event.node, event.action, event.ramp is None), event)
        for node in self.graph.order:  # live taps: posted, so not in the score
            if isinstance(node, ImpactForce):
                silent = Event(0.0, node.name, "impact", {"impulse": 0.0})
                kinds.setdefault((node.name, "impact", True), silent)
        split = 1.5 * self.block / self.sample_rate
        rehearsal = [replace(event, time=split) for event in kinds.values()]
        warm = OfflineEngine(
            self.graph,
            rehearsal,
            self.sample_rate,
            self.block,
            haptic_safety=self.safety,
            offsets_ms=self.offsets_ms,
        )
        scratch = np.zeros((len(self.graph.bus_rows), self.block))
        for _ in range(4):
            warm.produce(scratch, self.block)
        return OfflineEngine(
            self.graph,
            self.score,
            self.sample_rate,
            self.block,
            haptic_safety=self.safety,
            offsets_ms=self.offsets_ms,
        )

    def _take_posted(self, engine: OfflineEngine) -> None:
        scheduler = engine.scheduler
        while self._events_rx.poll():
            event = self._events_rx.recv()
            if 0 < event.time * self.sample_rate < scheduler.frame - self.block:
                self.header[LATE] += 1  # asked for a time already rendered: applied now
            scheduler.insert(validate_event(self.graph, event, "posted event"))
            self.header[TAKEN_AT] = scheduler.frame  # the first frame it can affect

    def _fill_once(self, engine: OfflineEngine, buf: np.ndarray, out: np.ndarray) -> bool:
        """Render one block into the ring if there is room; False if full."""
        h = self.header
        if self.capacity - (h[WRITE] - h[READ]) < self.block:
            return False
        self._take_posted(engine)
        engine.haptic_flags = 0
        engine.produce(buf, self.block)
        rows = self._haptic_rows
        out[:rows] = buf[:rows]
        out[rows:] = engine.haptic_flags
        _ring_write(h, self.f32, out, self.block)
        return True
