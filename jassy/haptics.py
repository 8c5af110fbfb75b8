"""The haptic channel: safety (force clamp, slew-rate limit, stall watchdog), per-channel
offsets in exact samples, and the UDP frame stream for kinesthetic device bridges.

UDP frame format (little-endian), one datagram per frame, at ``frame_rate`` (1 kHz):

    int64   sample time of the frame's first sample on the engine clock (frames)
    uint32  flags: bit 0 = watchdog fade active, bit 1 = clamped, bit 2 = slew-limited
    uint32  number of force channels C
    float32 x C   force per channel (N), the mean over the frame's samples

The receiver (:class:`HapticReceiver`) parses the same format; a device bridge aligns the
frames with audio through the sample time.
"""

from __future__ import annotations

import math
import socket
import struct
from dataclasses import dataclass

import numba as nb
import numpy as np

from jassy.errors import JassyError

FRAME_HEADER = struct.Struct("<qII")
FLAG_WATCHDOG, FLAG_CLAMPED, FLAG_SLEW = 1, 2, 4


@dataclass(frozen=True)
class HapticSafety:
    """Limits applied to every haptic sample before it reaches a device or file.

    max_force: |force| clamp (N); max_slew: rate limit (N/s); watchdog: seconds within
    which force fades to zero when the producer stalls (at most 0.01 s).
    """

    max_force: float = math.inf
    max_slew: float = math.inf
    watchdog: float = 0.01

    def __post_init__(self):
        if not self.max_force > 0:
            raise JassyError(f"--max-force: expected newtons > 0, got {self.max_force}")
        if not self.max_slew > 0:
            raise JassyError(f"--max-slew: expected N/s > 0, got {self.max_slew}")
        if not 0 < self.watchdog <= 0.01:
            raise JassyError(f"watchdog: expected seconds in (0, 0.01], got {self.watchdog}")

    def step(self, sample_rate: float) -> float:
        """Largest change per sample (N)."""
        return self.max_slew / sample_rate


@nb.njit(cache=True)
def limit_force(buf, n, last, max_force, max_step):
    """Clamp |force| and its change per sample, channel by channel, in place.

    buf: (channels, frames); last: previous output per channel (updated). Non-finite
    samples count as 0. Returns flags (FLAG_CLAMPED | FLAG_SLEW) of what was limited.
    """
    flags = 0
    for c in range(buf.shape[0]):
        y = last[c]
        for i in range(n):
            x = buf[c, i]
            if not math.isfinite(x):
                x = 0.0
            if x > max_force:
                x = max_force
                flags |= 2
            elif x < -max_force:
                x = -max_force
                flags |= 2
            d = x - y
            if d > max_step:
                x = y + max_step
                flags |= 4
            elif d < -max_step:
                x = y - max_step
                flags |= 4
            y = x
            buf[c, i] = y
        last[c] = y
    return flags


def channel_delays(
    offsets_ms: dict[str, float], n_audio: int, n_haptic: int, sample_rate: float
) -> np.ndarray:
    """Per output channel delay (frames) from offsets in ms for "audio" and "haptic".

    Positive offset = later. Offsets are applied exactly in samples (rounded to the
    nearest sample); both kinds are shifted so the earliest has zero delay, e.g.
    {"haptic": 2.0} at 48 kHz delays the haptic channels by 96 samples.
    """
    for key in offsets_ms:
        if key not in ("audio", "haptic"):
            raise JassyError(f"offsets: unknown channel kind {key!r}; expected audio or haptic")
    a = offsets_ms.get("audio", 0.0)
    h = offsets_ms.get("haptic", 0.0)
    base = min(a, h)
    da = int(round((a - base) * sample_rate / 1000.0))
    dh = int(round((h - base) * sample_rate / 1000.0))
    return np.array([da] * n_audio + [dh] * n_haptic, dtype=np.int64)


@nb.njit(cache=True)
def delay_channels(buf, n, history, delays, pos):
    """Delay each channel of buf[:, :n] by delays[c] frames in place.

    history: (channels, H) ring of past input, H > max delay; pos: [write index]."""
    H = history.shape[1]
    p = pos[0]
    for i in range(n):
        for c in range(buf.shape[0]):
            history[c, (p + i) % H] = buf[c, i]
            buf[c, i] = history[c, (p + i - delays[c]) % H]
    pos[0] = (p + n) % H


class ChannelDelay:
    """Stateful per-channel delay line (see :func:`delay_channels`)."""

    def __init__(self, delays: np.ndarray):
        self.delays = np.asarray(delays, dtype=np.int64)
        self.history = np.zeros((self.delays.size, int(self.delays.max(initial=0)) + 1))
        self.pos = np.zeros(1, dtype=np.int64)
        self.active = bool(np.any(self.delays))

    def __call__(self, buf: np.ndarray, n: int) -> None:
        if self.active:
            delay_channels(buf, n, self.history, self.delays, self.pos)


class UdpHapticSink:
    """Sends haptic frames (format above) to ``host:port`` at ``frame_rate`` frames/s."""

    def __init__(self, address: str, sample_rate: float, channels: int, frame_rate: float = 1000.0):
        host, _, port = address.rpartition(":")
        if not host or not port.isdigit():
            raise JassyError(f"--haptic-udp {address!r}: expected HOST:PORT")
        self.target = (host, int(port))
        self.samples_per_frame = int(round(sample_rate / frame_rate))
        if self.samples_per_frame < 1:
            raise JassyError(f"haptic frame rate {frame_rate} Hz exceeds the sample rate")
        self.channels = channels
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._pending = np.zeros((channels, 0))
        self._start = 0
        self.frames_sent = 0

    def send(self, block: np.ndarray, start_frame: int, flags: int = 0) -> None:
        """Queue rendered haptic samples (channels, n) that start at ``start_frame``."""
        if self._pending.shape[1] == 0:
            self._start = start_frame
        self._pending = np.concatenate([self._pending, block], axis=1)
        m = self.samples_per_frame
        while self._pending.shape[1] >= m:
            force = self._pending[:, :m].mean(axis=1).astype("<f4")
            header = FRAME_HEADER.pack(self._start, flags, self.channels)
            self.sock.sendto(header + force.tobytes(), self.target)
            self.frames_sent += 1
            self._pending = self._pending[:, m:]
            self._start += m

    def close(self) -> None:
        self.sock.close()


class HapticReceiver:
    """Receives and parses haptic frames on a UDP port (for tests and device bridges)."""

    def __init__(self, host: str = "127.0.0.1", port: int = 0):
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind((host, port))
        self.sock.settimeout(0.5)
        self.address = f"{host}:{self.sock.getsockname()[1]}"

    def receive(self) -> tuple[int, int, np.ndarray] | None:
        """(sample time, flags, force per channel) of the next frame, or None on timeout."""
        try:
            data, _ = self.sock.recvfrom(65536)
        except TimeoutError:
            return None
        return parse_frame(data)

    def close(self) -> None:
        self.sock.close()


def parse_frame(data: bytes) -> tuple[int, int, np.ndarray]:
    """Decode one UDP haptic frame."""
    if len(data) < FRAME_HEADER.size:
        raise JassyError(f"haptic frame: {len(data)} bytes, expected at least {FRAME_HEADER.size}")
    frame, flags, channels = FRAME_HEADER.unpack_from(data)
    force = np.frombuffer(data, dtype="<f4", count=channels, offset=FRAME_HEADER.size)
    return frame, flags, force.astype(np.float64)
