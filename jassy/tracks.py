"""Texture tracks: a modal model's points along a line, and contacts moving along them.

A model whose points include t0, t1, ... (named in order along a straight track) and
optionally ``t{i}_{j}``, the fraction j / (m_i + 1) of the way from t{i} to t{i+1} (m_i such
points in interval i; see patches.models_surface.track_points), has a *track*: a 1-D mesh
whose coordinate s is i + j / (m_i + 1), uniform in distance along the track.

Gains on a track are its linear shape functions: a location whose vertices all lie on the
track stands for the point at its mean coordinate s = sum w_v s_v, and its gains are
interpolated between the two track points around s. For neighbouring points (or one point)
that is the barycentric blend itself; for others (``{t0, t1}`` with weights 0.5 on a track
that also holds t0_1 .. t0_7) it is the gain of the real point halfway along, where a blend
of the two end rows would be an average unlike any point of the surface.

A contact moving along a track (a location ramp, :func:`walk_score`) passes through every
track point between its ends at constant speed, so its gains follow the shape functions
along the way instead of cross-fading the two end rows.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import replace
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from jassy.events import Event

if TYPE_CHECKING:
    from jassy.graph import Graph
    from jassy.modal_model import Location, ModalModel

_TRACK_POINT = re.compile(r"t(\d+)(?:_(\d+))?")


class Track(NamedTuple):
    """A model's track: its points' coordinates (ascending), their gain rows and names."""

    coordinates: np.ndarray  # s of each point, ascending (t{i} at s = i)
    rows: np.ndarray  # the model's row index of each point
    names: tuple[str, ...]

    def segment(self, s: float) -> tuple[int, float]:
        """(i, x): coordinate s (clamped to the track) lies between its points i and i + 1,
        a fraction x of the way."""
        c = self.coordinates
        s = min(max(s, c[0]), c[-1])
        i = min(int(np.searchsorted(c, s, side="right")) - 1, c.size - 2)
        return i, (s - c[i]) / (c[i + 1] - c[i])


def find_track(points: Sequence[str]) -> Track | None:
    """The track of a model's point names (None unless t0 and t1 exist, the t{i} are
    numbered 0 .. n-1 without gaps, and each interval's t{i}_{j} are j = 1 .. m_i)."""
    named: dict[int, int] = {}
    inner: dict[int, dict[int, int]] = {}
    for row, name in enumerate(points):
        match = _TRACK_POINT.fullmatch(name)
        if match is None:
            continue
        i = int(match.group(1))
        if match.group(2) is None:
            named[i] = row
        else:
            inner.setdefault(i, {})[int(match.group(2))] = row
    n = len(named)
    if n < 2 or sorted(named) != list(range(n)):
        return None
    coordinates, rows = [], []
    for i in range(n):
        coordinates.append(float(i))
        rows.append(named[i])
        between = inner.get(i, {})
        if between and (i == n - 1 or sorted(between) != list(range(1, len(between) + 1))):
            return None
        for j in range(1, len(between) + 1):
            coordinates.append(i + j / (len(between) + 1))
            rows.append(between[j])
    if set(inner) - set(range(n - 1)):
        return None
    rows_arr = np.array(rows, dtype=np.int64)
    return Track(np.array(coordinates), rows_arr, tuple(points[r] for r in rows_arr))


def track_coordinate(model: ModalModel, location: Location) -> float | None:
    """The track coordinate s of ``location`` (None if the model has no track or a vertex
    is off it)."""
    track = model.track
    if track is None:
        return None
    at = {int(r): float(s) for r, s in zip(track.rows, track.coordinates, strict=True)}
    s = 0.0
    for v, w in zip(location.vertices, location.weights, strict=True):
        row = model.point_index(v, "location")
        if row not in at:
            return None
        s += w * at[row]
    return s


def track_gains(model: ModalModel, rows: np.ndarray, location: Location) -> np.ndarray | None:
    """Rows (gains or driving gains, one per point) interpolated at ``location`` with the
    track's linear shape functions; None if ``location`` is not on the model's track, or is
    one point or two neighbours on it (their barycentric blend, as given, is the same)."""
    s = track_coordinate(model, location)
    if s is None:
        return None
    i, x = model.track.segment(s)
    a, b = int(model.track.rows[i]), int(model.track.rows[i + 1])
    own = {model.point_index(v, "location") for v in location.vertices}
    if own <= {a, b}:
        return None
    return (1.0 - x) * rows[a] + x * rows[b]


class _Walk(NamedTuple):
    """A contact's movement along a track between frames start and end (coordinates)."""

    start: int
    end: int
    origin: float
    goal: float

    def at(self, frame: int) -> float:
        if frame >= self.end:
            return self.goal
        return self.origin + (self.goal - self.origin) * (frame - self.start) / (self.end - self.start)


def walk_score(graph: Graph, events: Sequence[Event], sample_rate: float) -> list[Event]:
    """The (validated, time-sorted) score with every ramped location change of a ModalBank
    on a track replaced by a chain of ramps through the track points between its ends.

    The contact moves at constant speed along the track from where it is when the event
    applies (mid-way along an earlier walk, if one is under way) to the new location over
    the event's ramp; it reaches each track point at the nearest frame, and each link of the
    chain is a ramp between neighbouring points, i.e. the linear shape functions along the
    way. A later location change of the same node (a jump, an impact's location, another
    ramp) stops a walk under way. Other parameters set by the same event are set with the
    chain's first link (a ModalBank ramps all its coefficients together). Events apply at
    ceil(time * sample_rate) and ramps end at ceil((time + ramp) * sample_rate), as in
    jassy.scheduler. Events posted during a render (live input) are neither expanded nor
    stop a walk of the score."""
    from jassy.scheduler import apply_frame

    def frame_of(t: float) -> int:
        return apply_frame(t * sample_rate)

    out: list[_Scored] = []
    walks: dict[str, _Walk] = {}  # node -> where its contact is (or goes) on its track
    for order, ev in enumerate(events):
        frame = frame_of(ev.time)
        for name in _located(graph, ev):  # a new location stops a walk under way
            walk = walks.pop(name, None)
            if walk is not None and walk.end > frame:
                out = [x for x in out if not (x.link and x.event.node == name and x.frame >= frame)]
                walks[name] = _Walk(walk.start, frame, walk.origin, walk.at(frame))
            elif walk is not None:
                walks[name] = walk
        links = _links(graph, ev, frame, frame_of(ev.time + ev.ramp) if ev.ramp is not None else frame, walks)
        for name in _located(graph, ev):
            if not links or name != ev.node:
                goal = _coordinate(graph, name, ev.args["location"])
                walks.pop(name, None)
                if goal is not None:
                    walks[name] = _Walk(frame, frame, goal, goal)
        if not links:
            out.append(_Scored(frame, 2 * order, False, ev))
            continue
        start = frame
        for i, (at, location) in enumerate(links):
            args = {**ev.args, "location": location} if i == 0 else {"location": location}
            time = ev.time if i == 0 else start / sample_rate
            link = replace(ev, time=time, args=args, ramp=at / sample_rate - time)
            out.append(_Scored(start, 2 * order + (i > 0), i > 0, link))
            start = at
    out.sort(key=lambda x: (x.frame, x.order))
    return [x.event for x in out]


class _Scored(NamedTuple):
    frame: int
    order: int  # score order (events of one frame keep it)
    link: bool  # a later link of a walk (dropped if a new location comes first)
    event: Event


def _located(graph: Graph, ev: Event) -> list[str]:
    """The nodes whose location ``ev`` changes."""
    if ev.action == "set":
        return [ev.node] if "location" in ev.args else []
    if ev.args.get("location") is None:
        return []
    return [t.name for t in graph.location_targets(ev.node)]


def _links(
    graph: Graph, ev: Event, frame: int, end: int, walks: dict[str, _Walk]
) -> list[tuple[int, object]]:
    """(frame reached, location) of each link of ``ev``'s walk, the last at its own
    location; empty if ``ev`` is not a ramped location change along a track. Records the
    walk in ``walks``."""
    node = graph.nodes[ev.node]
    model = getattr(node, "model", None)
    if ev.action != "set" or "location" not in ev.args or ev.jump or end <= frame:
        return []
    if model is None or getattr(model, "track", None) is None:
        return []
    from jassy.modal_model import Location

    goal = track_coordinate(model, ev.args["location"])
    walk = walks.get(ev.node)
    origin = walk.at(frame) if walk is not None else _coordinate(graph, ev.node, node.values["location"])
    if goal is None or origin is None or goal == origin:
        return []
    walks[ev.node] = _Walk(frame, end, origin, goal)
    track = model.track
    inside = (track.coordinates > min(origin, goal)) & (track.coordinates < max(origin, goal))
    passed = np.flatnonzero(inside)
    if goal < origin:
        passed = passed[::-1]
    links: list[tuple[int, object]] = []
    for p in passed:
        at = frame + round((track.coordinates[p] - origin) / (goal - origin) * (end - frame))
        if frame < at < end and (not links or at > links[-1][0]):
            links.append((at, Location((track.names[p],), (1.0,))))
    links.append((end, ev.args["location"]))
    return links


def _coordinate(graph: Graph, name: str, location) -> float | None:
    from jassy.modal_model import parse_location

    model = getattr(graph.nodes[name], "model", None)
    if model is None or getattr(model, "track", None) is None or location is None:
        return None
    return track_coordinate(model, parse_location(location, name))
