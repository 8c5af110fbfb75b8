"""Sample-accurate scheduling: blocks are split at event sample offsets.

An event at fractional sample time ``t`` is applied before frame ``ceil(t)`` is computed
(the first frame at or after ``t``); the current block is split there, so no event is
moved to a block boundary (Faust ``timed_dsp``, SuperCollider ``OffsetOut``). Ugens that
need the fraction (impacts) receive ``t`` itself.

Ugens with ``inline_events`` (ImpactForce, ModalBank) apply an event at its own frame
inside a sub-block, so their events do not split it: they are handed over at the start
of the sub-block that contains their frame (parameter changes through ``set_param_at``).
A rigid scene's hundreds of impacts then cost no extra sub-blocks of the whole graph.

A location ramp along a model's texture track becomes a chain of ramps through the
track's points (jassy.tracks.walk_score) before the render starts.
"""

from __future__ import annotations

import bisect
import math
import weakref
from collections.abc import Sequence
from typing import Any, NamedTuple

import numba as nb
import numpy as np

from jassy.errors import PatchError, suggest
from jassy.events import Event
from jassy.graph import Graph
from jassy.jit import specialise
from jassy.tracks import walk_score

# Times are converted as t * sample_rate; this slack keeps 0.01 s * 48000 on frame 480.
_SAMPLE_SLACK = 1e-6


def apply_frame(sample_time: float) -> int:
    """The frame at which an event at ``sample_time`` (in samples) applies: the first frame
    at or after it, allowing _SAMPLE_SLACK of rounding in the time's conversion."""
    return math.ceil(sample_time - _SAMPLE_SLACK)


def ramp_seconds(event: Event, frame: int, sample_rate: float) -> float | None:
    """The ramp of a set event applied at ``frame``, in seconds, made to end on the frame
    where ``time + ramp`` applies (so that ramps chained along a track join exactly); None
    if the event gives no ramp."""
    if event.ramp is None:
        return None
    return (apply_frame((event.time + event.ramp) * sample_rate) - frame) / sample_rate


def prepare_score(graph: Graph, score: Sequence[Event], sample_rate: float) -> list[Event]:
    """The score validated against ``graph`` (errors name ``score[i]``), in time order (equal
    times keep the score's order), with location ramps along texture tracks walked through
    the tracks' points (jassy.tracks.walk_score).

    A graph's last prepared score is kept (:class:`PreparedScore`) and returned again, as a
    new list, while the score's contents, the sample rate and every node's parameter values
    (by identity) are those it was prepared with: rendering a graph again does not validate
    its score again."""
    key = _score_key(score, sample_rate)
    kept = _PREPARED.get(graph)
    if key is not None and kept is not None and kept.key == key and kept.same_values(graph):
        return list(kept.events)
    checked = [validate_event(graph, ev, f"score[{i}]") for i, ev in enumerate(score)]
    order = sorted(range(len(checked)), key=lambda i: (checked[i].time, i))
    events = walk_score(graph, [checked[i] for i in order], sample_rate)
    if key is not None:
        _PREPARED[graph] = PreparedScore(key, _values_of(graph), tuple(events))
    return events


class _Uncacheable(Exception):
    """An event argument :func:`_snapshot` cannot compare by value."""


#: Types an event field is compared by value as (with the type: 1, 1.0 and True validate
#: differently).
_SCALARS = frozenset((bool, int, float, str, type(None)))


def _snapshot(value: Any) -> Any:
    """A comparable copy of an event field, with each value's type, or _Uncacheable."""
    kind = type(value)
    if kind in _SCALARS:
        return kind, value
    if kind is list or kind is tuple:
        return kind, tuple(map(_snapshot, value))
    if kind is dict:
        return kind, tuple((k, _snapshot(v)) for k, v in value.items())
    if kind is np.ndarray or isinstance(value, np.generic):
        return kind, value.dtype.str, np.shape(value), value.tobytes()
    raise _Uncacheable


def _score_key(score: Sequence[Event], sample_rate: float) -> tuple | None:
    """The score's contents and the sample rate, compared by value (None: not comparable).
    Node names and actions are those of a validated score when the key is kept."""
    try:
        events = tuple(
            (
                ev.node,
                ev.action,
                _snapshot(ev.time),
                _snapshot(ev.args),
                _snapshot(ev.jump),
                _snapshot(ev.ramp),
            )
            for ev in score
        )
    except (_Uncacheable, AttributeError):  # an item that is no Event fails validation
        return None
    return float(sample_rate), events


def _values_of(graph: Graph) -> tuple:
    """Every node and its parameter values (the objects themselves, held)."""
    return tuple((node, tuple(node.values.items())) for node in graph.order)


class PreparedScore(NamedTuple):
    """A graph's last prepared score: the key it was prepared for, the nodes' parameter
    values then (validation and track walks read them: a model, a location) and the events."""

    key: tuple
    values: tuple
    events: tuple

    def same_values(self, graph: Graph) -> bool:
        """Whether ``graph``'s nodes hold the very same parameter values (by identity; a
        value changed in place, such as a model's arrays, is not seen)."""
        now = _values_of(graph)
        return len(now) == len(self.values) and all(
            node is kept_node
            and len(items) == len(kept_items)
            and all(k == kk and v is kv for (k, v), (kk, kv) in zip(items, kept_items, strict=True))
            for (node, items), (kept_node, kept_items) in zip(now, self.values, strict=True)
        )


#: Each graph's last prepared score (dropped with the graph).
_PREPARED: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def validate_event(graph: Graph, event: Event, where: str) -> Event:
    """Check an event against the graph; return it with validated, coerced args."""
    if not isinstance(event.time, (int, float)) or not math.isfinite(event.time) or event.time < 0:
        raise PatchError(f"{where}.time: expected a time in seconds >= 0, got {event.time!r}")
    node = graph.nodes.get(event.node)
    if node is None:
        raise PatchError(
            f"{where}.node: unknown node {event.node!r}; nodes are {', '.join(graph.nodes)}"
            f"{suggest(event.node, graph.nodes)}"
        )
    args: dict[str, Any] = {}
    ramp = event.ramp
    if ramp is not None and (
        isinstance(ramp, bool) or not isinstance(ramp, (int, float)) or not math.isfinite(ramp) or ramp < 0
    ):
        raise PatchError(f"{where}.ramp: expected seconds >= 0, got {ramp!r}")
    if ramp is not None and event.action != "set":
        raise PatchError(f"{where}.ramp: only 'set' events ramp")
    if event.action == "set":
        if not event.args:
            raise PatchError(f"{where}.set: expected at least one parameter to set")
        specs = node.all_specs()
        for key, value in event.args.items():
            spec = specs.get(key)
            if spec is None:
                raise PatchError(
                    f"{where}.set.{key}: {node.type_name} has no parameter {key!r}; "
                    f"expected one of {', '.join(specs)}{suggest(key, specs)}"
                )
            if spec.fixed:
                raise PatchError(f"{where}.set.{key}: parameter {key!r} cannot change during a render")
            args[key] = node.check_param(key, value, f"{where}.set.{key}")
    else:
        specs = node.actions.get(event.action)
        if specs is None:
            acts = ["set", *node.actions]
            raise PatchError(
                f"{where}: {node.type_name} has no action {event.action!r}; expected one of {', '.join(acts)}"
                f"{suggest(event.action, acts)}"
            )
        for key in event.args:
            if key not in specs:
                raise PatchError(
                    f"{where}.{event.action}.{key}: unknown argument; expected one of {', '.join(specs)}"
                    f"{suggest(key, specs)}"
                )
        for key, spec in specs.items():
            if key in event.args:
                args[key] = node.check_value(spec, event.args[key], f"{where}.{event.action}.{key}")
            elif spec.required:
                raise PatchError(f"{where}.{event.action}: missing {key!r} ({spec.expected()})")
            elif spec.default is not None:
                args[key] = spec.default
        if args.get("location") is not None:
            for target in graph.location_targets(event.node):
                target.check_param("location", args["location"], f"{where}.{event.action}.location")
    return Event(
        float(event.time),
        event.node,
        event.action,
        args,
        bool(event.jump),
        None if ramp is None else float(ramp),
    )


@nb.njit(cache=True)
def gather(bus, rows, out, offset, m):
    """out[r, offset:offset+m] = bus[rows[r], :m] for every output channel r."""
    for r in range(rows.shape[0]):
        src = bus[rows[r]]
        dst = out[r]
        for i in range(m):
            dst[offset + i] = src[i]


class ListedImpacts(NamedTuple):
    """The score's impacts (:meth:`Scheduler.listed_impacts`), one row per ugen struck, in
    frame order: the frame each applies at, the ugen whose force it drives, the impulse
    (N s) and the location (the impact's own, one set on that ugen at that frame, or None)."""

    frames: list[int]
    nodes: list
    impulses: list[float]
    locations: list


class Scheduler:
    """Applies a score to a graph while rendering frames in sub-blocks."""

    def __init__(
        self,
        graph: Graph,
        score: Sequence[Event],
        sample_rate: float,
        block: int,
    ):
        if block < 1:
            raise PatchError(f"block: expected an integer >= 1, got {block}")
        self.graph = graph
        self.block = int(block)
        self.sample_rate = float(sample_rate)
        self.events = prepare_score(graph, score, self.sample_rate)
        self.sample_times = [ev.time * self.sample_rate for ev in self.events]
        self.apply_frames = [apply_frame(t) for t in self.sample_times]
        self.inline = [self._is_inline(ev) for ev in self.events]
        self.next_event = 0
        self.frame = 0
        self._impacts = None  # the score's ListedImpacts, listed when first asked
        budget = graph.budget
        self.period = budget.period if budget is not None and graph.budgeted else None
        if self.period is not None:
            budget.attach(
                graph.budgeted, self.sample_rate, self.listed_impacts, graph.budget_renders, graph.audio
            )
            if not budget.active or budget.renders:  # it holds every mode, or splits the banks'
                self.period = None  # sub-blocks itself where it decides: no sub-block cuts

    def insert(self, event: Event) -> None:
        """Add a validated event during a render (live input). An event whose time has
        passed applies at the next frame to be rendered. Only an impact-like event or a set
        naming a location changes the impacts listed (:meth:`listed_impacts`)."""
        sample_time = max(event.time * self.sample_rate, float(self.frame))
        frame = max(apply_frame(sample_time), self.frame)
        i = bisect.bisect_right(self.apply_frames, frame, lo=self.next_event)
        self.events.insert(i, event)
        self.sample_times.insert(i, sample_time)
        self.apply_frames.insert(i, frame)
        self.inline.insert(i, self._is_inline(event))
        if event.action != "set" or "location" in event.args:  # (what :meth:`_list_impacts` reads)
            self._impacts = None  # listed again when next asked (~0.7 ms for the wok scene)
            if self.graph.budget is not None:
                self.graph.budget.score_changed(frame, self.frame)

    def _is_inline(self, event: Event) -> bool:
        """Whether the event's node (and every node its impact location moves) applies it at
        its own frame inside a sub-block."""
        if not self.graph.nodes[event.node].inline_events:
            return False
        if event.action == "set" or event.args.get("location") is None:
            return True
        return all(t.inline_events for t in self.graph.location_targets(event.node))

    def upcoming_impulses(self, start: int, end: int) -> list[tuple[int, list, float, object]]:
        """(frame, ugens whose force it drives, impulse N s, location or None) of the
        impact-like events applied in frames [start, end); an action without an ``impulse``
        argument counts as 1 N s. The location is the impact's own, else one set on that
        ugen at that frame (rigid scenes set each bank's location, then strike its hammer).
        Listed once per score (again after :meth:`insert`), then found by bisection."""
        listed = self.listed_impacts()
        rows = slice(bisect.bisect_left(listed.frames, start), bisect.bisect_left(listed.frames, end))
        return [
            (frame, [node], impulse, location)
            for frame, node, impulse, location in zip(
                listed.frames[rows],
                listed.nodes[rows],
                listed.impulses[rows],
                listed.locations[rows],
                strict=True,
            )
        ]

    def listed_impacts(self) -> ListedImpacts:
        """The impacts of the whole score as :meth:`upcoming_impulses` lists them, one row
        per ugen struck, in columns: the same object until :meth:`insert` changes the score."""
        if self._impacts is None:
            self._impacts = self._list_impacts()
        return self._impacts

    def _list_impacts(self) -> ListedImpacts:
        """Every impact of the score, in frame order, one row per ugen struck. Columns of
        the events' own values: no container per impact (with the hundreds of thousands
        of objects a compiled render keeps alive, the garbage collector's passes that
        allocations trigger made a row a tuple cost ~0.5 us; the wok scene's 1030 impacts
        are listed at every budgeted render's start)."""
        placed = {
            (frame, ev.node): ev.args["location"]
            for frame, ev in zip(self.apply_frames, self.events, strict=True)
            if ev.action == "set" and "location" in ev.args
        }
        struck, targets = self.graph.struck_targets, {}
        listed = ListedImpacts([], [], [], [])
        frames, nodes, impulses, locations = listed
        for frame, ev in zip(self.apply_frames, self.events, strict=True):
            if ev.action == "set":
                continue
            struck_here = targets.get(ev.node)
            if struck_here is None:
                struck_here = targets[ev.node] = struck(ev.node)
            args = ev.args
            impulse, location = float(args.get("impulse", 1.0)), args.get("location")
            for target in struck_here:
                frames.append(frame)
                nodes.append(target)
                impulses.append(impulse)
                locations.append(
                    location if location is not None or not placed else placed.get((frame, target.name))
                )
        return listed

    def _dispatch(self, index: int) -> None:
        ev = self.events[index]
        node = self.graph.nodes[ev.node]
        frame = self.apply_frames[index]
        if ev.action == "set":
            ramp = ramp_seconds(ev, frame, self.sample_rate)
            for key, value in ev.args.items():
                _set(node, frame, key, value, ev.jump, ramp)
            return
        location = ev.args.get("location")
        if location is not None:
            for target in self.graph.location_targets(ev.node):
                _set(target, frame, "location", location, True, None)
        node.act(ev.action, ev.args, self.sample_times[index])

    def _dispatch_due(self, pos: int, never: int) -> int:
        """Dispatch every event that applies at or before frame ``pos``; return the frame of
        the next event left (``never`` if none)."""
        frames, count = self.apply_frames, len(self.apply_frames)
        while self.next_event < count and frames[self.next_event] <= pos:
            self._dispatch(self.next_event)
            self.next_event += 1
        return frames[self.next_event] if self.next_event < count else never

    def _dispatch_inline(self, stop: int, never: int) -> int:
        """Dispatch the inline events before frame ``stop`` up to the first event that is not
        inline; return the frame of the next event left (``never`` if none)."""
        frames, inline, count = self.apply_frames, self.inline, len(self.apply_frames)
        while self.next_event < count and frames[self.next_event] < stop and inline[self.next_event]:
            self._dispatch(self.next_event)
            self.next_event += 1
        return frames[self.next_event] if self.next_event < count else never

    def run(self, n: int, out: np.ndarray) -> None:
        """Render the next ``n`` frames into ``out[:, :n]`` (rows: the graph's audio then
        haptic channels).

        Sub-blocks end at block boundaries (multiples of ``block`` on the clock), at the
        frames of events that are not inline, and at the graph's feedback limit; inline
        events inside a sub-block are dispatched before it.
        """
        process = self.graph.process
        steps = self.graph.steps
        period = self.period
        bus, rows = self.graph.bus, self.graph.bus_rows
        copy = specialise(gather, bus, rows, out, 0, 0)
        block = self.block
        limit = min(block, self.graph.max_sub_block)
        frames = self.apply_frames
        count = len(frames)
        never = 1 << 62
        begin = pos = self.frame
        end = begin + n
        upcoming = frames[self.next_event] if self.next_event < count else never
        while pos < end:
            if upcoming <= pos:
                upcoming = self._dispatch_due(pos, never)
            if limit == block and pos % block == 0 and (period is None or period % block == 0):
                # fast path: whole blocks up to the next event that splits one, or the end
                while pos + block <= end:
                    stop = pos + block
                    upcoming = self._dispatch_inline(stop, never)
                    if upcoming < stop:
                        break
                    for step in steps:  # Graph.process, inlined on the hot path
                        step(pos, block)
                    copy(bus, rows, out, pos - begin, block)
                    pos = stop
                if pos >= end:
                    break
                if upcoming <= pos:
                    continue
            stop = min(end, (pos // block + 1) * block, pos + limit)
            if period is not None:
                stop = min(stop, (pos // period + 1) * period)
            upcoming = self._dispatch_inline(stop, never)
            stop = min(stop, upcoming)
            process(pos, stop - pos)
            copy(bus, rows, out, pos - begin, stop - pos)
            pos = stop
        self.frame = end


def _set(node, frame: int, key: str, value, jump: bool, ramp: float | None) -> None:
    """Change a parameter at ``frame``: through set_param_at for an inline-event ugen (which
    applies it at that frame), else now (the sub-block starts at that frame)."""
    if node.inline_events:
        node.set_param_at(frame, key, value, jump, ramp)
    else:
        node.set_param(key, value, jump=jump, ramp=ramp)
