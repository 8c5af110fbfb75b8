"""The sound of a rigid scene, from its events (van den Doel, Kry & Pai, FoleyAutomatic 2001).

Each body with a ModalModel gets a ModalBank whose input is the sum of
- an ImpactForce struck by every Impact involving the body (impulse in N s, at the impact's
  time, after the bank's location jumps to where the impact landed), and
- for each sustained contact of the body (one pair of bodies), a Scrape driven by the
  contact's normal force and slip speed and a Roll driven by its normal force and rolling
  speed (control curves: audio-rate linear interpolation of the pair's ContactTracks).

The generators of one contact feed both bodies' banks.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from jassy.events import ContactTrack, Event, Impact
from jassy.graph import Graph
from jassy.modal_model import Location, ModalModel


@dataclass(frozen=True)
class Voice:
    """How one body sounds: the ModalModel its contacts strike (``model``); where each of the
    model's gain rows sits in the body's shape frame (``points`` (P, 3) m: the row nearest the
    contact is struck; None: row 0; "vertices": the rows are a TriangleMesh body's vertices,
    struck with the barycentric weights of the hit triangle); hit duration (s, its contact
    stiffness), sliding and rolling roughness (m RMS) and the stiffness that turns the profile
    into force (N/m)."""

    model: ModalModel
    points: np.ndarray | str | None = field(default=None, compare=False)
    hit_duration: float = 1e-3
    scrape_roughness: float = 2e-6
    roll_roughness: float = 1e-5
    stiffness: float = 300.0
    level: float = 1.0


def contact_locator(world, voices: dict[int, Voice]):
    """``locate(bodies, local, feature, bary)`` for physics.rigid.events.impacts and
    contact_tracks: the Location on each body's ModalModel of contacts at the points ``local``
    (K, 3) (m, each body's principal frame) with features and barycentric weights (see
    :class:`Voice`'s ``points``); row 0 for a body without a voice or points. Vectorised per
    body."""
    from physics.rigid.shapes import MESH

    frames = world.frames()

    def locate(bodies, local, feature, bary) -> list[Location]:
        out: list[Location | None] = [None] * len(bodies)
        for body in np.unique(bodies).tolist():
            at = np.flatnonzero(bodies == body)
            voice = voices.get(body)
            points = voice.points if voice is not None else None
            shape = world.bodies[body].shape
            if isinstance(points, str) and points == "vertices" and shape.kind == MESH:
                on_face = feature[at] >= 0
                faces = shape.surface.faces[feature[at[on_face]]].tolist()
                for k, face, weights in zip(
                    at[on_face].tolist(), faces, bary[at[on_face]].tolist(), strict=True
                ):
                    out[k] = Location(tuple(face), tuple(weights))
                at = at[~on_face]
                points = None
            if points is None or isinstance(points, str):
                for k in at.tolist():
                    out[k] = Location((0,), (1.0,))
                continue
            com, rotation = frames[body]
            shape_points = local[at] @ rotation.T + com
            candidates = np.asarray(points, float)
            d2 = ((shape_points[:, None, :] - candidates[None, :, :]) ** 2).sum(axis=2)
            for k, nearest in zip(at.tolist(), np.argmin(d2, axis=1).tolist(), strict=True):
                out[k] = Location((nearest,), (1.0,))
        return out

    return locate


def _slug(name: str) -> str:
    return "".join(ch if ch.isalnum() else "_" for ch in name)


def contact_curves(tracks: list[ContactTrack]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(times s, normal force N, slip speed m/s, rolling speed m/s) of one pair of bodies
    through all its tracks: each track's samples, with zeros one sample interval before it
    starts and after it ends (where no other track of the pair is running)."""
    rows = []
    for tr in sorted(tracks, key=lambda t: t.times[0]):
        t = np.asarray(tr.times, dtype=np.float64)
        dt = float(t[1] - t[0]) if t.size > 1 else 1e-3
        body = np.column_stack([t, tr.normal_force, tr.slip_speed, tr.rolling_speed])
        rows += [np.array([[t[0] - dt, 0.0, 0.0, 0.0]]), body, np.array([[t[-1] + dt, 0.0, 0.0, 0.0]])]
    table = np.concatenate(rows)
    times = table[:, 0]  # where tracks touch or overlap, the earlier rows win
    table = table[np.r_[True, times[1:] > np.maximum.accumulate(times)[:-1]]]
    return table[:, 0], table[:, 1], table[:, 2], table[:, 3]


def scene_graph(
    bodies,
    impacts: list[Impact],
    tracks: list[ContactTrack],
    voices: dict[int, Voice],
    max_contacts: int = 8,
):
    """(Graph, score) for ``bodies`` (list of physics.rigid.world.Body) and their events; the
    bodies with a voice (``voices``: body number -> Voice) sound.
    Only the ``max_contacts`` pairs with the longest sustained contact get sliding/rolling
    generators (the rest are too brief to hear as sliding); the generators follow the pair's
    tracks at their full rate as control curves (ContactControls.follow), so the score holds
    only the impacts."""
    from ugens.impact import ImpactForce
    from ugens.mix import Mixer
    from ugens.modal import ModalBank
    from ugens.roll import Roll
    from ugens.scrape import Scrape

    sounding = [i for i in range(len(bodies)) if i in voices]
    names = {i: _slug(bodies[i].name) for i in sounding}
    inputs = {i: [] for i in sounding}
    hits = {}
    for i in sounding:
        hits[i] = ImpactForce(name=f"hit_{names[i]}", duration=voices[i].hit_duration)
        inputs[i].append(hits[i])
    score: list[Event] = []
    where = {i: Location((0,), (1.0,)) for i in sounding}  # each bank's location (it starts at 0)
    for ev in sorted(impacts, key=lambda e: e.time):
        for body, loc in zip(ev.bodies, ev.locations, strict=False):
            if body in hits:
                if loc is not None and loc != where[body]:  # a jump only where the location changes
                    score.append(Event(ev.time, f"bank_{names[body]}", "set", {"location": loc}, jump=True))
                    where[body] = loc
                score.append(Event(ev.time, hits[body].name, "impact", {"impulse": ev.impulse}))
    by_pair: dict[tuple[int, int], list[ContactTrack]] = {}
    for tr in tracks:
        if any(b in hits for b in tr.bodies):
            by_pair.setdefault(tr.bodies, []).append(tr)
    ranked = sorted(by_pair, key=lambda p: -sum(t.times[-1] - t.times[0] for t in by_pair[p]))[:max_contacts]
    for a, b in ranked:
        voice = voices.get(a if a in hits else b)
        tag = f"{a}_{b}"
        scrape = Scrape(
            name=f"scrape_{tag}",
            roughness=voice.scrape_roughness,
            stiffness=voice.stiffness,
            seed=a * 7919 + b,
        )
        roll = Roll(
            name=f"roll_{tag}", roughness=voice.roll_roughness, stiffness=voice.stiffness, seed=a * 104729 + b
        )
        times, force, slip, rolling = contact_curves(by_pair[(a, b)])
        scrape.follow(times, force, slip)
        roll.follow(times, force, rolling)
        for body in (a, b):
            if body in hits:
                inputs[body].extend([scrape, roll])
    banks = []
    for i in sounding:
        drive = inputs[i][0] if len(inputs[i]) == 1 else Mixer(*inputs[i], name=f"drive_{names[i]}")
        banks.append(ModalBank(voices[i].model, name=f"bank_{names[i]}")(drive))
    mix = Mixer(*banks, gains=[voices[i].level for i in sounding], name="mix")
    return Graph(mix), sorted(score, key=lambda e: e.time)


def impact_rows(hits: list[Impact]) -> np.ndarray:
    """Rows (time s, body a, body b, normal impulse N s, approach speed m/s) of impacts."""
    return np.array([[e.time, *e.bodies, e.impulse, e.speed] for e in hits]).reshape(-1, 5)


IMPACT_HEADER = "time_s,body_a,body_b,impulse_ns,speed_ms"
