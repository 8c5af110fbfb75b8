"""Score events and contact data types shared by physics, ugens and engines.

Times are in seconds on the engine's clock; the scheduler converts them to fractional
sample times (``time * sample_rate``) and applies each event before the first sample at or
after that time, so an impact at t = 0.0100104 s starts between two samples.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np


@dataclass(frozen=True)
class Event:
    """A timed action on one node.

    action ``set`` changes parameters (``args`` maps name -> value): linearly over
    ``ramp`` seconds if given, else over the node's ``smooth`` time, or at once if
    ``jump``. Any other action is one the node's type declares (e.g. ``impact``).
    """

    time: float
    node: str
    action: str = "set"
    args: dict[str, Any] = field(default_factory=dict)
    jump: bool = False
    ramp: float | None = None


@dataclass(frozen=True)
class Impact:
    """A collision reported by physics.

    time (s), the two body ids, normal impulse (N s), relative normal speed (m/s), contact
    duration (s, or None to let the sound model choose), and the location on each body
    (vertex index, or (vertices, barycentric weights)).
    """

    time: float
    bodies: tuple[int, int]
    impulse: float
    speed: float
    duration: float | None = None
    locations: tuple[Any, Any] = (None, None)


@dataclass(frozen=True)
class ContactTrack:
    """A sustained contact sampled at the physics rate.

    times (s), normal force (N), slip speed (m/s), rolling speed (m/s) and location per
    sample; ugens interpolate it to the audio rate.
    """

    bodies: tuple[int, int]
    times: np.ndarray
    normal_force: np.ndarray
    slip_speed: np.ndarray
    rolling_speed: np.ndarray
    locations: list[Any] = field(default_factory=list)


@dataclass(frozen=True)
class HapticFrame:
    """Force (N) and optional torque (N m) on the user's probe at ``time`` (s)."""

    time: float
    force: np.ndarray
    torque: np.ndarray | None = None


def track_events(track: ContactTrack, controls: dict[str, tuple[str, str]]) -> list[Event]:
    """Events that make node parameters follow a ContactTrack, linearly interpolated.

    ``controls`` maps a track field (``normal_force``, ``slip_speed``, ``rolling_speed``,
    ``locations``) to (node, parameter). The parameter jumps to the first sample at
    ``times[0]``, then each event ramps to the next sample over the interval between them,
    so the audio-rate parameter is the piecewise-linear interpolation of the track.
    """
    times = np.asarray(track.times, dtype=np.float64)
    if times.ndim != 1 or times.size == 0 or np.any(np.diff(times) <= 0):
        raise ValueError("ContactTrack.times: expected increasing times in seconds")
    columns = {}
    for name, (node, param) in controls.items():
        values = getattr(track, name)
        if len(values) != times.size:
            raise ValueError(f"ContactTrack.{name}: expected {times.size} samples, got {len(values)}")
        columns.setdefault(node, []).append((param, values))
    events = []
    for node, cols in columns.items():
        events.append(Event(float(times[0]), node, "set", {p: _plain(v[0]) for p, v in cols}, jump=True))
        for i in range(times.size - 1):
            args = {p: _plain(v[i + 1]) for p, v in cols}
            events.append(Event(float(times[i]), node, "set", args, ramp=float(times[i + 1] - times[i])))
    return events


def _plain(value: Any) -> Any:
    """numpy scalars to Python numbers (events hold plain values)."""
    return value.item() if isinstance(value, np.generic) else value
