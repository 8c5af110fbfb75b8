"""``jassy haptic-bridge``: a reference device side for the UDP haptic loop.

It runs a 1 kHz servo loop like a kinesthetic device's: each tick it sends the probe's
pose (from a scripted path or the mouse) to the engine (:mod:`jassy.engines.probeinput`) and
takes the newest haptic frame the engine sent (:mod:`jassy.engines.hapticframes`) as its output
force. It lets go on its own: when the final frame arrives, or when no frame has
arrived for ``GAP`` seconds, the output force fades linearly to zero within ``FADE``
seconds, so it is zero at most GAP + FADE = 5 ms after the last frame, whatever
happened to the engine (a kill -9 included).
"""

from __future__ import annotations

import math
import socket
import time
from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from jassy.engines.hapticframes import FLAG_FINAL, decode, open_receiver, parse_address
from jassy.engines.hapticsender import request_realtime_priority
from jassy.engines.probeinput import BUTTON_MAIN, encode_pose
from jassy.errors import JassyError

#: Silence after which the bridge stops trusting the last frame (s), and the fade (s).
GAP, FADE = 0.002, 0.003


class BridgeTick(NamedTuple):
    """One servo tick: local monotonic time (s), probe position (m), output force (N),
    age of the newest frame (s, inf before the first) and whether the bridge lets go."""

    time: float
    position: tuple[float, float, float]
    force: np.ndarray
    frame_age: float
    letting_go: bool


def scripted_path(period: float = 2.0, length: float = 0.5, depth: float = 0.002):
    """A stroke repeated every ``period`` s: touch down at 10 % of the plate, slide to
    90 % over 60 % of the period, lift off, wait. Returns pose(t) -> (position, buttons)."""

    def pose(t: float):
        phase = (t % period) / period
        if 0.1 <= phase < 0.7:
            x = length * (0.1 + 0.8 * (phase - 0.1) / 0.6)
            return (x, 0.0, -depth), BUTTON_MAIN
        return (length * 0.1, 0.0, 0.01), 0

    return pose


class ForceOutput:
    """The device's force command from the frames received: the newest frame's force,
    faded linearly to zero over FADE once it is GAP old or the final frame came."""

    def __init__(self):
        self.force = np.zeros(0)
        self.last_arrival = -math.inf
        self.final_at: float | None = None

    def take(self, frame_force: np.ndarray, flags: int, now: float) -> None:
        self.force = frame_force
        self.last_arrival = now
        if flags & FLAG_FINAL:
            self.final_at = now
        else:
            self.final_at = None

    def __call__(self, now: float) -> tuple[np.ndarray, bool]:
        """(force, letting go) at time ``now``."""
        fade_from = self.last_arrival + GAP if self.final_at is None else self.final_at
        if now < fade_from:
            return self.force, False
        faded = now - fade_from
        return (self.force * (1.0 - faded / FADE) if faded < FADE else np.zeros_like(self.force)), True


def run_bridge(
    engine: str,
    listen: str,
    pose: Callable[[float], tuple[tuple[float, float, float], int]],
    duration: float | None = None,
    rate: float = 1000.0,
    on_tick: Callable[[BridgeTick], None] | None = None,
) -> dict:
    """Run the servo loop until ``duration`` s (None: until stopped); returns counters.

    engine: HOST:PORT of the engine's probe input; listen: HOST:PORT for its frames."""
    target = parse_address(engine, "--engine")
    host, port = parse_address(listen, "--listen")
    if not 0 < rate <= 10000:
        raise JassyError(f"--rate: expected Hz in (0, 10000], got {rate}")
    rx, _ = open_receiver(host, port)
    rx.setblocking(False)
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    request_realtime_priority()  # a servo loop must wake on time
    output = ForceOutput()
    counts = {"ticks": 0, "frames": 0, "finals": 0, "rejected": 0, "lost": 0}
    expected = None  # the next frame's sequence number: a jump is frames lost on the way
    start = time.monotonic()
    tick = 0
    try:
        while duration is None or tick < duration * rate:
            now = time.monotonic()
            position, buttons = pose(now - start)
            tx.sendto(encode_pose(tick, now, position, buttons=buttons), target)
            while True:
                try:
                    data = rx.recv(65536)
                except (BlockingIOError, InterruptedError):
                    break
                try:
                    frame = decode(data)
                except JassyError:
                    counts["rejected"] += 1
                    continue
                counts["frames"] += 1
                counts["finals"] += bool(frame.flags & FLAG_FINAL)
                if expected is not None and frame.sequence > expected:
                    counts["lost"] += frame.sequence - expected
                expected = frame.sequence + 1
                output.take(frame.force, frame.flags, time.monotonic())
            now = time.monotonic()
            force, letting_go = output(now)
            if on_tick is not None:
                on_tick(BridgeTick(now, position, force, now - output.last_arrival, letting_go))
            counts["ticks"] += 1
            tick += 1
            delay = start + tick / rate - time.monotonic()
            if delay > 0:
                time.sleep(delay)
    finally:
        rx.close()
        tx.close()
    return counts


def write_log(path, ticks: list[BridgeTick]) -> None:
    """The ticks as CSV (time_s on the monotonic clock, x/y/z_m, force_n per channel,
    frame_age_s, letting_go), written atomically."""
    from jassy.files import atomic_path

    channels = max((t.force.size for t in ticks), default=0)
    header = (
        "time_s,x_m,y_m,z_m," + "".join(f"force_{c}_n," for c in range(channels)) + "frame_age_s,letting_go"
    )
    with atomic_path(path) as tmp, open(tmp, "w") as f:
        f.write(header + "\n")
        for t in ticks:
            force = np.zeros(channels)
            force[: t.force.size] = t.force
            values = [t.time, *t.position, *force, t.frame_age, int(t.letting_go)]
            f.write(",".join(f"{v:.9g}" for v in values) + "\n")
