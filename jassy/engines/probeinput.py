"""Probe input over UDP: position (3D), orientation and buttons from a haptic device, up
to 1 kHz, version 1.

Datagram layout (little-endian, 52 bytes)::

    offset size  field
     0     4     magic b"JPOS"
     4     2     uint16 version (1)
     6     2     uint16 buttons (bit 0: the main button)
     8     8     uint64 sequence
    16     8     float64 send time (s, the sender's monotonic clock)
    24    12     float32 x 3 probe tip position (m): x along the object, y across it,
                 z height above its surface (z <= 0: touching)
    36    16     float32 x 4 orientation quaternion (w, x, y, z)

:class:`PoseReceiver` decodes them in a thread and hands each pose to a callback; the
live scenes feed it to the same probe objects the mouse drives.
"""

from __future__ import annotations

import socket
import struct
import threading
import time
from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from jassy.errors import JassyError

MAGIC = b"JPOS"
VERSION = 1
POSE = struct.Struct("<4sHHQd3f4f")
BUTTON_MAIN = 1


class Pose(NamedTuple):
    """One probe sample; ``received`` is the local monotonic time of arrival (s)."""

    sequence: int
    sent: float
    position: tuple[float, float, float]
    orientation: tuple[float, float, float, float]
    buttons: int
    received: float = 0.0

    @property
    def touching(self) -> bool:
        """In contact: at or below the surface, or the main button held."""
        return self.position[2] <= 0.0 or bool(self.buttons & BUTTON_MAIN)


def encode_pose(
    sequence: int,
    sent: float,
    position,
    orientation=(1.0, 0.0, 0.0, 0.0),
    buttons: int = 0,
) -> bytes:
    values = np.concatenate([np.asarray(position, float), np.asarray(orientation, float)])
    if values.size != 7 or not np.all(np.isfinite(values)):
        raise JassyError(f"probe pose: expected 3 finite coordinates and a quaternion, got {values}")
    return POSE.pack(MAGIC, VERSION, buttons, sequence, sent, *values)


def decode_pose(data: bytes, received: float = 0.0) -> Pose:
    if len(data) != POSE.size:
        raise JassyError(f"probe pose: {len(data)} bytes, expected {POSE.size}")
    magic, version, buttons, seq, sent, *values = POSE.unpack(data)
    if magic != MAGIC or version != VERSION:
        raise JassyError(f"probe pose: expected magic {MAGIC!r} version {VERSION}, got {magic!r} {version}")
    if not all(np.isfinite(values)):
        raise JassyError("probe pose: non-finite coordinates")
    return Pose(seq, sent, tuple(values[:3]), tuple(values[3:]), buttons, received)


class PoseReceiver:
    """Listens on ``host:port`` and calls ``handler(pose)`` for every valid pose, in a
    daemon thread; malformed datagrams are counted in ``rejected`` and dropped."""

    def __init__(self, handler: Callable[[Pose], None], host: str = "127.0.0.1", port: int = 0):
        self.handler = handler
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind((host, port))
        self.sock.settimeout(0.1)
        self.address = f"{host}:{self.sock.getsockname()[1]}"
        self.received = self.rejected = 0
        self.latest: Pose | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="probe-input", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                data, _ = self.sock.recvfrom(4096)
            except (TimeoutError, OSError):
                continue
            try:
                pose = decode_pose(data, time.monotonic())
            except JassyError:
                self.rejected += 1
                continue
            self.received += 1
            self.latest = pose
            self.handler(pose)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=1.0)
        self.sock.close()


class PoseDriver:
    """Feeds poses to a demo probe exactly as pointer events: contact begins -> press,
    moves while touching -> move, contact ends -> release, hovering -> only its drawn
    position. x (m) maps to the probe's 0..1 track position over ``length`` metres."""

    def __init__(self, probe, length: float = 0.5):
        self.probe, self.length = probe, length
        self.touching = False

    def __call__(self, pose: Pose) -> None:
        x = min(max(pose.position[0] / self.length, 0.0), 1.0)
        t = pose.received
        if pose.touching and not self.touching:
            self.probe.press(x, t)
        elif pose.touching:
            self.probe.move(x, t)
        elif self.touching:
            self.probe.release(t)
        if not pose.touching:
            self.probe.x = x  # hovering: only where it is drawn
        self.touching = pose.touching
