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

    action ``set`` changes parameters (``args`` maps name -> value; ramped unless ``jump``);
    any other action is one the node's type declares (e.g. ``impact`` on ImpactForce).
    """

    time: float
    node: str
    action: str = "set"
    args: dict[str, Any] = field(default_factory=dict)
    jump: bool = False


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
