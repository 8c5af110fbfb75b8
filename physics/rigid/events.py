"""From contact records to what sound and haptics consume: Impacts, ContactTracks, haptic frames.

- Impact: the records flagged as impacts at one time between one pair of bodies, merged:
  normal impulse summed (N s), approach speed the largest (m/s), location on each body the
  one nearest the impulse-weighted contact point (see :func:`location_on`).
- ContactTrack: sustained (non-impact) contact of a pair, per outer step: normal force =
  normal impulse / h (N), slip and rolling speed weighted by impulse (m/s), location of the
  strongest contact; runs of at least ``min_steps`` consecutive steps.
- Haptic frames: the contact force (N) and torque (N m, about a given point) on one body
  per outer step — e.g. the wok handle.
"""

from __future__ import annotations

import numpy as np

from jassy.events import ContactTrack, HapticFrame, Impact
from jassy.modal_model import Location
from physics.rigid import stepper as st
from physics.rigid.shapes import MESH
from physics.rigid.world import RunResult


def location_on(result: RunResult, body: int, local: np.ndarray, feature: int, bary: np.ndarray) -> Location:
    """Location of a contact on ``body``'s ModalModel: the triangle's vertices with barycentric
    weights on a mesh whose model rows are its vertices (``sound_points="vertices"``), else
    the model row whose ``sound_points`` entry is nearest the contact point, else row 0."""
    spec = result.world.bodies[body]
    points = spec.sound_points
    if isinstance(points, str) and points == "vertices" and spec.shape.kind == MESH and feature >= 0:
        face = spec.shape.surface.faces[int(feature)]
        return Location(tuple(int(v) for v in face), tuple(float(w) for w in bary))
    if points is None or isinstance(points, str):
        return Location((0,), (1.0,))
    com, rotation = result.world.arrays()[5][body]
    shape_point = rotation @ local + com
    nearest = int(np.argmin(np.linalg.norm(np.asarray(points) - shape_point, axis=1)))
    return Location((nearest,), (1.0,))


def _normal_impulse(rows: np.ndarray) -> np.ndarray:
    return np.einsum(
        "ij,ij->i", rows[:, st.REC_IMPULSE : st.REC_IMPULSE + 3], rows[:, st.REC_NORMAL : st.REC_NORMAL + 3]
    )


def _groups(keys: np.ndarray) -> list[np.ndarray]:
    """Row indices grouped by identical key rows (in order of first appearance)."""
    if len(keys) == 0:
        return []
    _, inverse = np.unique(keys, axis=0, return_inverse=True)
    order = np.argsort(inverse, kind="stable")
    splits = np.flatnonzero(np.diff(inverse[order])) + 1
    return np.split(order, splits)


def _locations(result: RunResult, rows: np.ndarray, weights: np.ndarray) -> tuple[Location, Location]:
    k = int(np.argmax(weights))
    row = rows[k]
    a, b = int(row[st.REC_A]), int(row[st.REC_B])
    bary = row[st.REC_BARY : st.REC_BARY + 3]
    loc_a = location_on(result, a, row[st.REC_LOCAL_A : st.REC_LOCAL_A + 3], int(row[st.REC_FEAT_A]), bary)
    loc_b = location_on(result, b, row[st.REC_LOCAL_B : st.REC_LOCAL_B + 3], int(row[st.REC_FEAT_B]), bary)
    return loc_a, loc_b


def impacts(result: RunResult) -> list[Impact]:
    """Impact events in time order (see module doc)."""
    rec = result.records
    rows = rec[rec[:, st.REC_IMPACT] > 0]
    out = []
    for group in _groups(rows[:, [st.REC_TIME, st.REC_A, st.REC_B]]):
        g = rows[group]
        jn = _normal_impulse(g)
        a, b = int(g[0, st.REC_A]), int(g[0, st.REC_B])
        out.append(
            Impact(
                float(g[0, st.REC_TIME]),
                (a, b),
                float(jn.sum()),
                float(g[:, st.REC_SPEED].max()),
                None,
                _locations(result, g, jn),
            )
        )
    return sorted(out, key=lambda e: e.time)


def contact_tracks(result: RunResult, min_steps: int = 5, with_locations: bool = True) -> list[ContactTrack]:
    """Sustained contacts per pair (see module doc); times are the steps' start times (s).
    ``with_locations=False`` leaves the tracks' locations empty (faster)."""
    h = result.world.params.h
    rec = result.records
    rows = rec[rec[:, st.REC_IMPACT] == 0]
    if len(rows) == 0:
        return []
    jn = np.maximum(_normal_impulse(rows), 0.0)
    a, b, step = rows[:, st.REC_A], rows[:, st.REC_B], rows[:, st.REC_STEP]
    order = np.lexsort((-jn, step, b, a))  # per (pair, step): strongest contact first
    rows, jn, a, b, step = rows[order], jn[order], a[order], b[order], step[order]
    new_group = np.r_[True, (a[1:] != a[:-1]) | (b[1:] != b[:-1]) | (step[1:] != step[:-1])]
    first = np.flatnonzero(new_group)
    total = np.add.reduceat(jn, first)
    count = np.diff(np.r_[first, len(rows)])
    safe = np.where(total > 0, total, 1.0)

    def weighted(col):
        w_sum = np.add.reduceat(jn * rows[:, col], first) / safe
        plain = np.add.reduceat(rows[:, col], first) / count
        return np.where(total > 0, w_sum, plain)

    slip, roll = weighted(st.REC_SLIP), weighted(st.REC_ROLL)
    ga, gb, gstep = a[first].astype(int), b[first].astype(int), step[first].astype(int)
    breaks = np.flatnonzero((ga[1:] != ga[:-1]) | (gb[1:] != gb[:-1]) | (gstep[1:] != gstep[:-1] + 1)) + 1
    tracks = []
    for run in np.split(np.arange(len(first)), breaks):
        if len(run) < min_steps:
            continue
        locs = (
            [_locations(result, rows[first[i] : first[i] + 1], jn[first[i] : first[i] + 1]) for i in run]
            if with_locations
            else []
        )
        tracks.append(
            ContactTrack(
                (int(ga[run[0]]), int(gb[run[0]])), gstep[run] * h, total[run] / h, slip[run], roll[run], locs
            )
        )
    return sorted(tracks, key=lambda t: t.times[0])


def contact_wrench(result: RunResult, body: int, point=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(times (S,), force (S, 3) N, torque (S, 3) N m) of the contacts on ``body`` per outer
    step; torque about ``point``: a vectorised function of times (T,) s -> (T, 3) world points
    (m), or None for none."""
    h = result.world.params.h
    rec = result.records
    first = int(round(result.start_time / h))
    steps = np.arange(first, int(round(result.state.time / h)))
    force = np.zeros((steps.size, 3))
    torque = np.zeros((steps.size, 3))
    for col, sign in ((st.REC_A, 1.0), (st.REC_B, -1.0)):
        rows = rec[rec[:, col] == body]
        if len(rows) == 0:
            continue
        k = rows[:, st.REC_STEP].astype(int) - first
        f = sign * rows[:, st.REC_IMPULSE : st.REC_IMPULSE + 3] / h
        np.add.at(force, k, f)
        if point is not None:
            times, which = np.unique(rows[:, st.REC_TIME], return_inverse=True)
            centres = np.asarray(point(times), float)[which]
            np.add.at(torque, k, np.cross(rows[:, st.REC_POINT : st.REC_POINT + 3] - centres, f))
    return steps * h, force, torque


def haptic_frames(result: RunResult, body: int, point=None) -> list[HapticFrame]:
    """HapticFrames of :func:`contact_wrench` (torque included when ``point`` is given)."""
    times, force, torque = contact_wrench(result, body, point)
    if not (np.all(np.isfinite(force)) and np.all(np.isfinite(torque))):
        raise ValueError("haptic_frames: non-finite contact force")
    torques = torque if point is not None else [None] * len(times)
    return [HapticFrame(float(t), f, tq) for t, f, tq in zip(times, force, torques, strict=True)]
