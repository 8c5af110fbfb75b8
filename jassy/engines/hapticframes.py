"""The UDP haptic frame: one datagram per millisecond of stream time, version 2.

Layout (little-endian, 40-byte header, then the channels)::

    offset size  field
     0     4     magic b"JHAP"
     4     2     uint16 version (2)
     6     2     uint16 flags (FLAG_* below)
     8     8     uint64 sequence: the frame's index on the stream clock (sample time /
                 samples per frame), so a gap in sequence numbers is a lost frame
    16     8     int64 sample time: the stream frame of the frame's first sample
    24     8     float64 device time (s, PortAudio's stream clock): when that sample
                 plays (outputBufferDacTime of its callback + its offset / sample rate)
    32     2     uint16 number of force channels F
    34     2     uint16 number of torque channels T
    36     4     float32 sample rate (Hz)
    40     4 F   float32 force per channel (N), the mean over the frame's samples
    40+4F  4 T   float32 torque per channel (N m), likewise

Flags: the frame's samples were clamped (|force| limit), slew-limited, faded by the
watchdog (a stalled producer or the fade at the end of a run), produced while the
producer had stalled; FLAG_FINAL marks the last frame of a run (zero force): a device
lets go when it arrives.
"""

from __future__ import annotations

import socket
import struct
import sys
import time
from typing import NamedTuple

import numpy as np

from jassy.errors import JassyError

MAGIC = b"JHAP"
VERSION = 2
HEADER = struct.Struct("<4sHHQqdHHf")
FLAG_WATCHDOG, FLAG_CLAMPED, FLAG_SLEW, FLAG_STALLED, FLAG_FINAL = 1, 2, 4, 8, 16
FLAG_NAMES = {
    FLAG_WATCHDOG: "watchdog fading",
    FLAG_CLAMPED: "clamped",
    FLAG_SLEW: "slew-limited",
    FLAG_STALLED: "producer stalled",
    FLAG_FINAL: "final",
}


class HapticFrame(NamedTuple):
    """One decoded frame; ``received`` is the local monotonic time of arrival (s)."""

    sequence: int
    sample_time: int
    device_time: float
    flags: int
    force: np.ndarray
    torque: np.ndarray
    sample_rate: float
    received: float = 0.0


def encode(
    sequence: int,
    sample_time: int,
    device_time: float,
    flags: int,
    force: np.ndarray,
    torque: np.ndarray,
    sample_rate: float,
) -> bytes:
    """One datagram; non-finite channel values are sent as 0, finite values beyond the
    float32 range as the largest float32 of their sign."""
    values = np.concatenate([force, torque]).astype(np.float64)
    values[~np.isfinite(values)] = 0.0
    limit = float(np.finfo(np.float32).max)
    values = np.clip(values, -limit, limit).astype("<f4")
    header = HEADER.pack(
        MAGIC, VERSION, flags, sequence, sample_time, device_time, force.size, torque.size, sample_rate
    )
    return header + values.tobytes()


def decode(data: bytes, received: float = 0.0) -> HapticFrame:
    """Parse one datagram; JassyError on anything but a well-formed version-2 frame."""
    if len(data) < HEADER.size:
        raise JassyError(f"haptic frame: {len(data)} bytes, expected at least {HEADER.size}")
    magic, version, flags, seq, sample, device, n_force, n_torque, rate = HEADER.unpack_from(data)
    if magic != MAGIC or version != VERSION:
        raise JassyError(f"haptic frame: expected magic {MAGIC!r} version {VERSION}, got {magic!r} {version}")
    if len(data) != HEADER.size + 4 * (n_force + n_torque):
        raise JassyError(f"haptic frame: {len(data)} bytes do not hold {n_force} + {n_torque} channels")
    values = np.frombuffer(data, dtype="<f4", offset=HEADER.size).astype(np.float64)
    return HapticFrame(seq, sample, device, flags, values[:n_force], values[n_force:], rate, received)


def parse_address(address: str, what: str = "--haptic-udp") -> tuple[str, int]:
    """("host", port) from "HOST:PORT"."""
    host, _, port = address.rpartition(":")
    if not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise JassyError(f"{what} {address!r}: expected HOST:PORT")
    return host, int(port)


#: Receive buffer asked for (bytes; capped by net.core.rmem_max): at the default 208 KiB a
#: receiver held off the CPU for ~0.2 s (a loaded machine) lost frames in the kernel.
RECEIVE_BUFFER = 4 << 20
#: Linux's socket option that reports, with each datagram, how many the socket dropped.
SO_RXQ_OVFL = getattr(socket, "SO_RXQ_OVFL", 40)
#: Linux's SO_RCVBUF beyond net.core.rmem_max, allowed with CAP_NET_ADMIN (Python lacks the name).
SO_RCVBUFFORCE = 33
_DROPS = struct.Struct("=I")


def open_receiver(host: str, port: int) -> tuple[socket.socket, bool]:
    """A bound UDP socket with a large receive buffer, and whether it reports the
    datagrams the kernel dropped because that buffer was full (SO_RXQ_OVFL, Linux)."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:  # where allowed, past a low rmem_max (a container's default 208 KiB)
        if not sys.platform.startswith("linux"):
            raise OSError("SO_RCVBUFFORCE is Linux's")
        sock.setsockopt(socket.SOL_SOCKET, SO_RCVBUFFORCE, RECEIVE_BUFFER)
    except OSError:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RECEIVE_BUFFER)
    try:
        sock.setsockopt(socket.SOL_SOCKET, SO_RXQ_OVFL, 1)
        counts_drops = True
    except OSError:
        counts_drops = False
    sock.bind((host, port))
    return sock, counts_drops


def kernel_drops(ancillary: list) -> int | None:
    """The socket's running count of dropped datagrams from recvmsg's ancillary data."""
    for level, kind, data in ancillary:
        if level == socket.SOL_SOCKET and kind == SO_RXQ_OVFL and len(data) >= _DROPS.size:
            return _DROPS.unpack_from(data)[0]
    return None


class FrameReceiver:
    """Receives haptic frames on a UDP port (device bridges, tests, the bench).
    ``dropped``: datagrams the kernel dropped at this socket (its buffer full) before
    the last one received; None where the OS does not report it."""

    def __init__(self, host: str = "127.0.0.1", port: int = 0, timeout: float = 0.5):
        self.sock, counts = open_receiver(host, port)
        self.sock.settimeout(timeout)
        self.address = f"{host}:{self.sock.getsockname()[1]}"
        self.dropped: int | None = 0 if counts else None

    def receive(self, timeout: float | None = None) -> HapticFrame | None:
        """The next frame, or None when none arrives within the timeout (s)."""
        if timeout is not None:
            self.sock.settimeout(timeout)
        try:
            data, ancillary, _, _ = self.sock.recvmsg(65536, socket.CMSG_SPACE(_DROPS.size))
        except (TimeoutError, BlockingIOError):
            return None
        drops = kernel_drops(ancillary)
        if drops is not None and self.dropped is not None:
            self.dropped = max(self.dropped, drops)
        return decode(data, time.monotonic())

    def close(self) -> None:
        self.sock.close()


class FrameRecorder:
    """Receives frames in the background into a list until the final frame arrives or
    :meth:`stop` is called (tests and the bench). ``process=True`` receives in a forked
    process of its own, so a busy interpreter in this one cannot make the socket
    overflow (the bench keeps its main thread busy on purpose)."""

    def __init__(self, host: str = "127.0.0.1", port: int = 0, process: bool = False):
        import multiprocessing
        import threading

        self.receiver = FrameReceiver(host, port, timeout=0.05)
        self.address = self.receiver.address
        self.frames: list[HapticFrame] = []
        self._dropped: int | None = None
        if process:
            context = multiprocessing.get_context("fork")
            self._stop, self._final = context.Event(), context.Event()
            self._results, sender = context.Pipe(duplex=False)
            self._worker = context.Process(target=self._run, args=(sender,), daemon=True)
        else:
            self._stop, self._final = threading.Event(), threading.Event()
            self._results = None
            self._worker = threading.Thread(target=self._run, daemon=True)
        self._worker.start()

    def _run(self, results=None) -> None:
        while not self._stop.is_set():
            frame = self.receiver.receive()
            if frame is not None:
                self.frames.append(frame)
                if frame.flags & FLAG_FINAL:
                    self._final.set()
                    break
        if results is not None:
            results.send((self.frames, self.receiver.dropped))

    def wait_final(self, timeout: float = 2.0) -> bool:
        """True once the final frame has arrived (waits at most ``timeout`` s)."""
        return self._final.wait(timeout)

    @property
    def dropped(self) -> int | None:
        """Datagrams the kernel dropped at the receiving socket (known after :meth:`stop`
        in process mode)."""
        return self._dropped if self._results is not None else self.receiver.dropped

    def stop(self) -> list[HapticFrame]:
        self._stop.set()
        if self._results is not None:
            self.frames, self._dropped = self._results.recv()
        self._worker.join()
        self.receiver.close()
        return self.frames
