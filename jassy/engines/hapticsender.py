"""UDP haptic frames paced by the audio stream: each 1 ms frame leaves when its first
sample reaches the device, not when it was rendered.

The device callback writes every haptic sample it hands to the device, after the safety
stage, into a ring indexed by stream frame, and logs each callback (first stream frame,
frame count, ``outputBufferDacTime``, flags). This module's sender runs in a process of
its own (its own interpreter lock: nothing the engine or the caller does in Python
delays it): it maps each frame's first sample to its device time (the callback's DAC
time plus the sample's offset over the sample rate), converts that to the local
monotonic clock with the stream-clock offset the stream's owner measures, sleeps until
then and sends (format: :mod:`jassy.engines.hapticframes`); where the device buffer is
shorter than a frame, every frame waits (frame - buffer) more, the longest its last
samples can take to be handed over. At the end it sends every frame
through the last one played, then a final frame with zero force and FLAG_FINAL.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import signal
import socket
import time
from typing import NamedTuple

import numpy as np

from jassy.engines.hapticframes import FLAG_FINAL, encode

#: Control slots (float64) shared between the engine and the sender. LOST: frames skipped
#: because the sender fell a haptic ring behind; SEND_DROPPED: frames the socket refused
#: (its send buffer full, or an error), counted instead of blocking the sender.
CLOCK_OFFSET, STOP_AT, SENT, LOST, DONE, LOGGED_SENDS, LATE, REALTIME, SEND_DROPPED = range(9)
CONTROL_SLOTS = 9
#: Callback log columns: first stream frame, frames, DAC time (s, stream clock), flags.
LOG_START, LOG_FRAMES, LOG_DAC, LOG_FLAGS = range(4)
LOG_COLUMNS = 4
#: Seconds between polls while waiting for the callback to hand over more samples.
POLL = 0.0002
#: SCHED_FIFO priority of the sender where the OS grants it (above the producer's 40,
#: below JACK's 70-95): it sleeps almost always and must wake on time.
REALTIME_PRIORITY = 45
#: Weight of each callback's DAC time in the smoothed device clock (see _Callbacks).
CLOCK_SMOOTHING = 0.02
#: Socket buffer asked for (bytes; the kernel caps it at net.core.wmem_max / rmem_max).
SOCKET_BUFFER = 1 << 20


class StreamTap(NamedTuple):
    """Shared-memory views the device callback writes and the sender reads.

    header/logged_slot: the callback's counters and the slot counting logged callbacks;
    log: (callbacks, LOG_COLUMNS) ring (LOG_* columns); played: (frames, haptic channels) ring of
    the samples handed to the device, row = stream frame % rows; control: CONTROL_SLOTS
    values (CLOCK_OFFSET = monotonic - stream time, s; STOP_AT = stream frame to finish
    at, -1 while running; counters); send_times: ring of monotonic send times (s)."""

    header: np.ndarray
    logged_slot: int
    log: np.ndarray
    played: np.ndarray
    control: np.ndarray
    send_times: np.ndarray


def _die_with_parent_and_ignore_terminal_signals() -> None:
    """A child of the engine: killed when its parent dies (even by SIGKILL), deaf to the
    terminal's SIGINT/SIGHUP (the parent ends it in order), and woken precisely."""
    for sig in (signal.SIGINT, signal.SIGHUP, signal.SIGTERM):
        signal.signal(sig, signal.SIG_IGN)
    libc_name = ctypes.util.find_library("c")
    if libc_name is None:
        return
    libc = ctypes.CDLL(libc_name, use_errno=True)
    pr_set_pdeathsig, pr_set_timerslack = 1, 29
    libc.prctl(pr_set_pdeathsig, signal.SIGKILL, 0, 0, 0)
    libc.prctl(pr_set_timerslack, 1, 0, 0, 0)  # 1 ns timer slack: sleeps end on time


def request_realtime_priority(priority: int = REALTIME_PRIORITY) -> bool:
    """SCHED_FIFO for the calling thread where the OS grants it (root, CAP_SYS_NICE or
    an rtprio limit); True if granted."""
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except (AttributeError, OSError):
        return False
    return True


def child_setup(parent_pid: int) -> None:
    """Call first in an engine child process (see above); exits if the parent is gone."""
    _die_with_parent_and_ignore_terminal_signals()
    if os.getppid() != parent_pid:
        os._exit(0)


class _Callbacks:
    """Reads the callback log in order; maps stream frames to device times and flags.

    The device plays samples at the sample rate, so the time at which stream frame s
    plays is origin + s / rate. Each callback's ``outputBufferDacTime`` estimates the
    origin with the jitter of the moment the callback ran; a slow exponential average
    of those estimates keeps the origin (and follows a drifting device clock) without
    passing the callbacks' jitter on to the frames."""

    def __init__(self, tap: StreamTap, sample_rate: float):
        self.tap, self.rate = tap, sample_rate
        self.entries: list[tuple[int, int, float, int]] = []
        self.read = 0
        self.origin: float | None = None

    def update(self) -> int:
        """Take the newly logged callbacks; the stream frame up to which samples exist."""
        logged = int(self.tap.header[self.tap.logged_slot])
        rows = self.tap.log.shape[0]
        self.read = max(self.read, logged - rows + 1)
        for k in range(self.read, logged):
            start, frames, dac, flags = self.tap.log[k % rows]
            self.entries.append((int(start), int(frames), float(dac), int(flags)))
            estimate = dac - start / self.rate
            if self.origin is None:
                self.origin = estimate
            self.origin += CLOCK_SMOOTHING * (estimate - self.origin)
        self.read = logged
        return self.end

    @property
    def buffer(self) -> int:
        """Frames of the last logged callback (the device buffer)."""
        return self.entries[-1][1] if self.entries else 0

    @property
    def end(self) -> int:
        return self.entries[-1][0] + self.entries[-1][1] if self.entries else 0

    def span(self, start: int, stop: int) -> tuple[float, int]:
        """Device time of frame ``start`` and the flags of callbacks covering [start, stop)."""
        while len(self.entries) > 1 and self.entries[1][0] <= start:
            self.entries.pop(0)
        dac = self.origin + start / self.rate
        flags = 0
        for s, n, _, f in self.entries:
            if s >= stop:
                break
            if s + n > start:
                flags |= f
        return dac, flags


#: Attempts at sending the final frame while the socket's send buffer is full (POLL apart).
FINAL_TRIES = 50


def _send(sock: socket.socket, datagram: bytes, address: tuple[str, int], control: np.ndarray) -> bool:
    """Send without blocking; count the frame as SENT, or as SEND_DROPPED if refused."""
    try:
        sock.sendto(datagram, address)
    except OSError:  # BlockingIOError (buffer full), ENOBUFS, an unreachable address...
        control[SEND_DROPPED] += 1
        return False
    control[SENT] += 1
    return True


def run_sender(
    tap: StreamTap,
    address: tuple[str, int],
    sample_rate: float,
    n_torque: int = 0,
    frame_rate: float = 1000.0,
) -> None:
    """Send frames until the engine sets STOP_AT, then the final frame; sets DONE."""
    control = tap.control
    rows, channels = tap.played.shape
    n_force = channels - n_torque
    per_frame = int(round(sample_rate / frame_rate))
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, SOCKET_BUFFER)
    sock.setblocking(False)  # a full send buffer drops (and counts) a frame, never stalls the clock
    control[REALTIME] = request_realtime_priority()
    callbacks = _Callbacks(tap, sample_rate)
    sequence = 0
    dac = 0.0
    try:
        while True:
            start = sequence * per_frame
            end = callbacks.update()
            stop_at = control[STOP_AT]
            if stop_at >= 0 and start + per_frame > min(stop_at, end):
                break
            if end < start + per_frame:
                time.sleep(POLL)
                continue
            if end - start > rows - 2 * per_frame:  # fell a ring behind: skip what was overwritten
                skipped = (end - rows // 2) // per_frame - sequence
                control[LOST] += skipped
                sequence += skipped
                continue
            dac, flags = callbacks.span(start, start + per_frame)
            # a device buffer shorter than a frame hands a frame's last samples over up to
            # (frame - buffer) after its first sample plays: every frame waits that long,
            # so none leaves late by a varying fraction of it
            hold = max(0, per_frame - callbacks.buffer) / sample_rate
            delay = dac + hold + control[CLOCK_OFFSET] - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            elif delay < -0.5e-3:
                control[LATE] += 1
            rows_of = np.arange(start, start + per_frame) % rows
            mean = tap.played[rows_of].mean(axis=0)
            _send(
                sock,
                encode(sequence, start, dac, flags, mean[:n_force], mean[n_force:], sample_rate),
                address,
                control,
            )
            now = time.monotonic()
            if tap.send_times.size:
                tap.send_times[int(control[LOGGED_SENDS]) % tap.send_times.size] = now
                control[LOGGED_SENDS] += 1
            sequence += 1
        start = sequence * per_frame
        if callbacks.origin is not None:
            dac = callbacks.origin + start / sample_rate
        zeros = np.zeros(channels)
        final = encode(sequence, start, dac, FLAG_FINAL, zeros[:n_force], zeros[n_force:], sample_rate)
        for _ in range(FINAL_TRIES):  # the final frame must not be the one a full buffer drops
            if _send(sock, final, address, control):
                break
            time.sleep(POLL)
    finally:
        sock.close()
        control[DONE] = 1


def jitter(send_times: np.ndarray, count: int) -> dict:
    """p50/p99 of the intervals between consecutive sends (ms) from the send-time ring."""
    size = send_times.size
    n = min(count, size)
    if n < 3:
        nan = float("nan")
        return {"frames": n, "p50_ms": nan, "p99_ms": nan, "p1_ms": nan, "max_ms": nan}
    order = np.arange(count - n, count) % size
    gaps = np.diff(send_times[order]) * 1e3
    return {
        "frames": int(n),
        "p50_ms": float(np.percentile(gaps, 50)),
        "p99_ms": float(np.percentile(gaps, 99)),
        "p1_ms": float(np.percentile(gaps, 1)),
        "max_ms": float(gaps.max()),
    }
