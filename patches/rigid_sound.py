"""The sound of a rigid scene, from its events (van den Doel, Kry & Pai, FoleyAutomatic 2001).

Each body with a ModalModel gets a ModalBank whose input is the sum of
- an ImpactForce struck by every Impact involving the body (impulse in N s, at the impact's
  time, after the bank's location jumps to where the impact landed), and
- for each sustained contact of the body (one pair of bodies), a Scrape driven by the
  contact's normal force and slip speed and a Roll driven by its normal force and rolling
  speed (jassy.events.track_events: audio-rate interpolation of the ContactTrack).

The generators of one contact feed both bodies' banks.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from jassy.events import ContactTrack, Event, Impact, track_events
from jassy.graph import Graph


@dataclass(frozen=True)
class Voice:
    """How one body sounds: hit duration (s, its contact stiffness), sliding and rolling
    roughness (m RMS) and the stiffness that turns the profile into force (N/m)."""

    hit_duration: float = 1e-3
    scrape_roughness: float = 2e-6
    roll_roughness: float = 1e-5
    stiffness: float = 300.0
    level: float = 1.0


def _slug(name: str) -> str:
    return "".join(ch if ch.isalnum() else "_" for ch in name)


def decimate(track: ContactTrack, interval: float) -> ContactTrack:
    """The track sampled every ``interval`` seconds (block means of force and speeds; the last
    sample kept), for audio-rate control lines that need no more than envelope detail."""
    dt = float(track.times[1] - track.times[0]) if len(track.times) > 1 else interval
    k = max(1, int(round(interval / dt)))
    if k == 1 or len(track.times) <= 2 * k:
        return track
    n = len(track.times) // k * k

    def mean(x):
        return np.asarray(x)[:n].reshape(-1, k).mean(axis=1)

    idx = list(range(0, n, k))
    return ContactTrack(
        track.bodies,
        np.asarray(track.times)[idx],
        mean(track.normal_force),
        mean(track.slip_speed),
        mean(track.rolling_speed),
        [track.locations[i] for i in idx] if track.locations else [],
    )


def scene_graph(
    bodies,
    impacts: list[Impact],
    tracks: list[ContactTrack],
    voices: dict[int, Voice],
    max_contacts: int = 8,
    control_interval: float = 5e-3,
):
    """(Graph, score) for ``bodies`` (list of physics.rigid.world.Body) and their events.
    Only the ``max_contacts`` pairs with the longest sustained contact get sliding/rolling
    generators (the rest are too brief to hear as sliding); their controls follow the tracks
    decimated to ``control_interval`` seconds."""
    from ugens.impact import ImpactForce
    from ugens.mix import Gain, Mixer
    from ugens.modal import ModalBank
    from ugens.roll import Roll
    from ugens.scrape import Scrape

    sounding = [i for i, b in enumerate(bodies) if b.sound is not None]
    names = {i: _slug(bodies[i].name) for i in sounding}
    inputs = {i: [] for i in sounding}
    hits = {}
    for i in sounding:
        hits[i] = ImpactForce(name=f"hit_{names[i]}", duration=voices[i].hit_duration)
        inputs[i].append(hits[i])
    score: list[Event] = []
    for ev in impacts:
        for body, loc in zip(ev.bodies, ev.locations, strict=False):
            if body in hits:
                score.append(Event(ev.time, f"bank_{names[body]}", "set", {"location": loc}, jump=True))
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
        for body in (a, b):
            if body in hits:
                inputs[body].extend([scrape, roll])
        for tr in (decimate(t, control_interval) for t in by_pair[(a, b)]):
            score += track_events(
                tr, {"normal_force": (scrape.name, "force"), "slip_speed": (scrape.name, "speed")}
            )
            score += track_events(
                tr, {"normal_force": (roll.name, "force"), "rolling_speed": (roll.name, "speed")}
            )
            dt = float(tr.times[1] - tr.times[0]) if len(tr.times) > 1 else 1e-3
            for node in (scrape.name, roll.name):
                score.append(
                    Event(float(tr.times[-1]) + dt, node, "set", {"force": 0.0, "speed": 0.0}, jump=True)
                )
    outs = []
    for i in sounding:
        drive = inputs[i][0] if len(inputs[i]) == 1 else Mixer(*inputs[i], name=f"drive_{names[i]}")
        bank = ModalBank(bodies[i].sound, name=f"bank_{names[i]}")(drive)
        outs.append(Gain(bank, gain=voices[i].level, name=f"level_{names[i]}"))
    mix = outs[0] if len(outs) == 1 else Mixer(*outs, name="mix")
    return Graph(mix), sorted(score, key=lambda e: e.time)


def impact_rows(hits: list[Impact]) -> np.ndarray:
    """Rows (time s, body a, body b, normal impulse N s, approach speed m/s) of impacts."""
    return np.array([[e.time, *e.bodies, e.impulse, e.speed] for e in hits]).reshape(-1, 5)


IMPACT_HEADER = "time_s,body_a,body_b,impulse_ns,speed_ms"
