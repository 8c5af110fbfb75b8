"""Live engine: a producer thread renders ahead into a lock-free ring; the sound card
callback is a numba ``@cfunc`` that only copies frames, so it never takes the GIL, never
allocates and never compiles.

Shared memory (one aligned block, see ``_layout``): an int64 header (positions and
counters), float64 haptic state, float32 interleaved ring frames, and an optional float32
monitor ring where the callback keeps a copy of what it sent to the device (tests and
benchmarks read the true output from it). Single producer (``_ring_write``, publishes the
write position after the frames) and single consumer (the callback, publishes the read
position after reading); positions only grow, so ``write - read`` is the fill level.

The haptic channels are made safe in the callback itself, the last stage before the
device: |force| clamp, slew-rate limit, and on a stall (ring empty) a linear fade of the
force to zero within the watchdog time (at most 10 ms).
"""

from __future__ import annotations

import queue
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass

import numba as nb
import numpy as np
from numba import types

from jassy.errors import JassyError
from jassy.events import Event
from jassy.graph import Graph
from jassy.haptics import HapticSafety, UdpHapticSink
from jassy.offline import OfflineEngine
from jassy.scheduler import validate_event

HEADER, STATE, DATA_OFFSET_F32 = 32, 128, 256  # int64 slots, float64 slots, first float32 slot
CAP, CHANNELS, N_AUDIO, WRITE, READ, UNDER_FRAMES, CALLBACKS, UNDER_CALLBACKS, FLAGS = range(9)
WATCHDOG, FADE_LEFT, PLAYED, MONITOR_CAP, MAX_FRAMES, STALLED = range(9, 15)
MAX_FORCE, MAX_STEP, LAST, FADE_FROM = 32, 33, 40, 72  # float64 slots (per haptic channel: 32 max)
MAX_HAPTIC = 32


@nb.cfunc(
    types.int32(types.voidptr, types.voidptr, types.uint64, types.voidptr, types.uint64, types.voidptr),
    cache=True,
)
def ring_callback(inp, out, frames, time_info, status, user):
    """PortAudio callback: copy ring frames to the device, make haptics safe, count."""
    hdr = nb.carray(user, (HEADER,), np.int64)
    f64 = nb.carray(user, (STATE,), np.float64)
    cap, ch, na, mcap = hdr[CAP], hdr[CHANNELS], hdr[N_AUDIO], hdr[MONITOR_CAP]
    f32 = nb.carray(user, (DATA_OFFSET_F32 + (cap + mcap) * ch,), np.float32)
    o = nb.carray(out, (frames * ch,), np.float32)
    hdr[CALLBACKS] += 1
    hdr[FLAGS] |= status
    if frames > hdr[MAX_FRAMES]:
        hdr[MAX_FRAMES] = frames
    r = hdr[READ]
    avail = hdr[WRITE] - r
    n = frames if avail >= frames else avail
    max_force, max_step, window = f64[MAX_FORCE], f64[MAX_STEP], hdr[WATCHDOG]
    for i in range(frames):
        base = DATA_OFFSET_F32 + ((r + i) % cap) * ch
        have = i < n
        if have:
            hdr[STALLED] = 0
        elif hdr[STALLED] == 0:  # the ring just ran dry: start the watchdog fade
            hdr[STALLED] = 1
            hdr[FADE_LEFT] = window
            for c in range(ch - na):
                f64[FADE_FROM + c] = f64[LAST + c]
        for c in range(na):
            x = f32[base + c] if have else 0.0
            if x != x:  # NaN
                x = 0.0
            o[i * ch + c] = min(max(x, -1.0), 1.0)
        left = hdr[FADE_LEFT]
        for c in range(ch - na):
            y = f64[LAST + c]
            if have:
                x = f32[base + na + c]
                if x != x:  # NaN
                    x = 0.0
                x = min(max(x, -max_force), max_force)
                x = min(max(x, y - max_step), y + max_step)
            else:
                x = f64[FADE_FROM + c] * (left - 1) / window if left > 0 else 0.0
            f64[LAST + c] = x
            o[i * ch + na + c] = x
        if not have and left > 0:
            hdr[FADE_LEFT] = left - 1
    if n < frames:
        hdr[UNDER_FRAMES] += frames - n
        hdr[UNDER_CALLBACKS] += 1
    hdr[READ] = r + n
    if mcap > 0:
        p = hdr[PLAYED]
        mbase = DATA_OFFSET_F32 + cap * ch
        for i in range(frames):
            k = mbase + ((p + i) % mcap) * ch
            for c in range(ch):
                f32[k + c] = o[i * ch + c]
    hdr[PLAYED] += frames
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

    @property
    def latency(self) -> float:
        """Event-to-DAC latency (s): ring depth plus the device's output latency."""
        return self.ring_latency + self.device_latency

    def summary(self) -> str:
        pct = 100.0 * self.underrun_callbacks / max(self.callbacks, 1)
        return (
            f"{self.callbacks} callbacks, {self.underrun_callbacks} underruns ({pct:.3f} %), "
            f"latency {self.latency * 1e3:.2f} ms (ring {self.ring_latency * 1e3:.2f} ms + device "
            f"{self.device_latency * 1e3:.2f} ms)"
        )


class LiveEngine:
    """Plays a graph and score in real time on a PortAudio device.

    Audio channels, then haptic channels if ``haptic_to_card``, go to the device in one
    stream, so they share the clock exactly. ``ring_blocks`` blocks are rendered ahead.
    """

    def __init__(
        self,
        graph: Graph,
        score: Sequence[Event] = (),
        sample_rate: float = 48000,
        block: int = 64,
        ring_blocks: int = 3,
        device: str | int | None = None,
        haptic_to_card: bool = True,
        haptic_udp: str | None = None,
        haptic_safety: HapticSafety | None = None,
        offsets_ms: dict[str, float] | None = None,
        monitor_seconds: float = 0.0,
    ):
        if ring_blocks < 1:
            raise JassyError(f"--ring: expected at least 1 block, got {ring_blocks}")
        if haptic_to_card and len(graph.haptic) > MAX_HAPTIC:
            raise JassyError(f"at most {MAX_HAPTIC} haptic channels can go to a sound card")
        self.graph, self.score = graph, list(score)
        self.sample_rate, self.block = float(sample_rate), int(block)
        self.safety = haptic_safety or HapticSafety()
        self.offsets_ms = offsets_ms
        self.device = device
        self.haptic_to_card = haptic_to_card and bool(graph.haptic)
        self.n_audio = len(graph.audio)
        self.channels = self.n_audio + (len(graph.haptic) if self.haptic_to_card else 0)
        self.capacity = ring_blocks * self.block
        self.monitor_capacity = int(round(monitor_seconds * self.sample_rate))
        floats = DATA_OFFSET_F32 + (self.capacity + self.monitor_capacity) * self.channels
        self._memory = np.zeros(floats // 2 + 16, dtype=np.float64)  # 8-byte aligned, zeroed
        raw = self._memory
        self.header = raw.view(np.int64)[:HEADER]
        self.state = raw[:STATE]
        self.f32 = raw.view(np.float32)[:floats]
        self.header[CAP], self.header[CHANNELS], self.header[N_AUDIO] = (
            self.capacity,
            self.channels,
            self.n_audio,
        )
        self.header[MONITOR_CAP] = self.monitor_capacity
        self.header[WATCHDOG] = max(1, int(self.safety.watchdog * self.sample_rate))
        self.state[MAX_FORCE] = self.safety.max_force
        self.state[MAX_STEP] = self.safety.step(self.sample_rate)
        self._udp = (
            UdpHapticSink(haptic_udp, self.sample_rate, len(graph.haptic))
            if haptic_udp and graph.haptic
            else None
        )
        self._posted: queue.SimpleQueue[Event] = queue.SimpleQueue()
        self._stop = threading.Event()
        self._running = threading.Event()
        self._running.set()
        self._thread: threading.Thread | None = None
        self._stream = None
        self.late_events = 0
        self.error: BaseException | None = None

    # ------------------------------------------------------------------ control
    def start(self) -> None:
        """Warm every kernel, prefill the ring, open the stream and start producing."""
        from jassy import portaudio

        warm = OfflineEngine(self.graph, [], self.sample_rate, self.block)
        scratch = np.zeros((len(self.graph.bus_rows), self.block))
        for _ in range(4):
            warm.produce(scratch, self.block)
        self.engine = OfflineEngine(
            self.graph,
            self.score,
            self.sample_rate,
            self.block,
            haptic_safety=self.safety,
            offsets_ms=self.offsets_ms,
        )
        self._buf = np.zeros((len(self.graph.bus_rows), self.block))
        self._out = np.zeros((self.channels, self.block))
        while self._fill_once():
            pass
        device = portaudio.find_device(self.device)
        self._stream = portaudio.OutputStream(
            device,
            self.channels,
            self.sample_rate,
            self.block,
            ring_callback.address,
            self._memory.ctypes.data,
        )
        self.device_latency = self._stream.output_latency
        self._thread = threading.Thread(target=self._produce, name="jassy-producer", daemon=True)
        self._thread.start()
        self._stream.start()

    def post(self, event: Event) -> None:
        """Schedule ``event`` from any thread: at its time if still ahead, else at the
        next frame to be rendered (``time = 0`` means as soon as possible; a later time
        already rendered counts as a late event)."""
        self._posted.put(event)

    def pause_producer(self, paused: bool) -> None:
        """Stall (True) or resume the producer: for testing the haptic watchdog."""
        if paused:
            self._running.clear()
        else:
            self._running.set()

    def stop(self) -> LiveStats:
        """Stop the stream and the producer; return the counters."""
        if self._stream is not None:
            self._stream.close()  # first, so the device never sees the producer stop
        self._stop.set()
        self._running.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        if self._udp is not None:
            self._udp.close()
        if self.error is not None:
            raise JassyError(f"the producer failed: {self.error!r}")
        return self.stats()

    def stats(self) -> LiveStats:
        h = self.header
        return LiveStats(
            int(h[CALLBACKS]),
            int(h[UNDER_CALLBACKS]),
            int(h[UNDER_FRAMES]),
            int(h[PLAYED]),
            int(h[MAX_FRAMES]),
            int(h[FLAGS]),
            self.capacity / self.sample_rate,
            getattr(self, "device_latency", 0.0),
            self.late_events,
        )

    def monitor(self) -> np.ndarray:
        """The last frames sent to the device, (channels, frames) in playing order."""
        if not self.monitor_capacity:
            raise JassyError("no monitor: create the engine with monitor_seconds > 0")
        played = int(self.header[PLAYED])
        size = min(played, self.monitor_capacity)
        ring = self.f32[DATA_OFFSET_F32 + self.capacity * self.channels :].reshape(-1, self.channels)
        order = (np.arange(played - size, played)) % self.monitor_capacity
        return ring[order].T.astype(np.float64)

    # ----------------------------------------------------------------- producer
    def _take_posted(self) -> None:
        scheduler = self.engine.scheduler
        while True:
            try:
                event = self._posted.get_nowait()
            except queue.Empty:
                return
            if 0 < event.time * self.sample_rate < scheduler.frame - self.block:
                self.late_events += 1  # asked for a time already rendered: applied now
            scheduler.insert(validate_event(self.graph, event, "posted event"))

    def _fill_once(self) -> bool:
        """Render one block into the ring if there is room; False if full."""
        h = self.header
        if self.capacity - (h[WRITE] - h[READ]) < self.block:
            return False
        self._take_posted()
        start = self.engine.frame
        self.engine.produce(self._buf, self.block)
        self._out[:] = self._buf[: self.channels]
        _ring_write(h, self.f32, self._out, self.block)
        if self._udp is not None:
            self._udp.send(self._buf[self.n_audio :], start)
        return True

    def _produce(self) -> None:
        pause = self.block / self.sample_rate / 4
        try:
            while not self._stop.is_set():
                self._running.wait()
                if not self._fill_once():
                    time.sleep(pause)
        except BaseException as exc:  # reported by stop(); the callback keeps the device safe
            self.error = exc
