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
from physics.rigid import codes
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
        "ij,ij->i",
        rows[:, codes.REC_IMPULSE : codes.REC_IMPULSE + 3],
        rows[:, codes.REC_NORMAL : codes.REC_NORMAL + 3],
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
    a, b = int(row[codes.REC_A]), int(row[codes.REC_B])
    bary = row[codes.REC_BARY : codes.REC_BARY + 3]
    loc_a = location_on(
        result, a, row[codes.REC_LOCAL_A : codes.REC_LOCAL_A + 3], int(row[codes.REC_FEAT_A]), bary
    )
    loc_b = location_on(
        result, b, row[codes.REC_LOCAL_B : codes.REC_LOCAL_B + 3], int(row[codes.REC_FEAT_B]), bary
    )
    return loc_a, loc_b


def impacts(result: RunResult) -> list[Impact]:
    """Impact events in time order (see module doc)."""
    rec = result.records
    rows = rec[rec[:, codes.REC_IMPACT] > 0]
    out = []
    for group in _groups(rows[:, [codes.REC_TIME, codes.REC_A, codes.REC_B]]):
        g = rows[group]
        jn = _normal_impulse(g)
        a, b = int(g[0, codes.REC_A]), int(g[0, codes.REC_B])
        out.append(
            Impact(
                float(g[0, codes.REC_TIME]),
                (a, b),
                float(jn.sum()),
                float(g[:, codes.REC_SPEED].max()),
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
    rows = np.flatnonzero(rec[:, codes.REC_IMPACT] == 0)
    if len(rows) == 0:
        return []
    n_bodies = len(result.world.bodies)
    cols = rec[
        np.ix_(rows, [codes.REC_A, codes.REC_B, codes.REC_STEP, codes.REC_SLIP, codes.REC_ROLL])
    ]  # record order
    jn = np.maximum(_normal_impulse(rec)[rows], 0.0)
    pair = cols[:, 0].astype(np.int64) * n_bodies + cols[:, 1].astype(np.int64)
    # records are in step order: a stable sort by pair keeps each pair's steps in order
    order = np.argsort(pair, kind="stable")
    rows, pair, jn, cols = rows[order], pair[order], jn[order], cols[order]
    step = cols[:, 2].astype(np.int64)
    new_group = np.r_[True, (pair[1:] != pair[:-1]) | (step[1:] != step[:-1])]
    first = np.flatnonzero(new_group)  # one group per (pair, step)
    total = np.add.reduceat(jn, first)
    count = np.diff(np.r_[first, len(rows)])
    safe = np.where(total > 0, total, 1.0)

    def weighted(values):
        w_sum = np.add.reduceat(jn * values, first) / safe
        plain = np.add.reduceat(values, first) / count
        return np.where(total > 0, w_sum, plain)

    slip, roll = weighted(cols[:, 3]), weighted(cols[:, 4])
    gpair, gstep = pair[first], step[first]
    breaks = np.flatnonzero((gpair[1:] != gpair[:-1]) | (gstep[1:] != gstep[:-1] + 1)) + 1
    starts, stops = np.r_[0, breaks], np.r_[breaks, len(first)]
    if with_locations:  # the strongest contact of each group (the first of equals)
        group = np.repeat(np.arange(len(first)), count)
        strongest = np.lexsort((-jn, group))[first]
    tracks = []
    for lo, hi in zip(starts.tolist(), stops.tolist(), strict=True):
        if hi - lo < min_steps:
            continue
        locs = []
        if with_locations:
            locs = [_locations(result, rec[rows[k] : rows[k] + 1], jn[k : k + 1]) for k in strongest[lo:hi]]
        a, b = divmod(int(gpair[lo]), n_bodies)
        tracks.append(
            ContactTrack((a, b), gstep[lo:hi] * h, total[lo:hi] / h, slip[lo:hi], roll[lo:hi], locs)
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
    for col, sign in ((codes.REC_A, 1.0), (codes.REC_B, -1.0)):
        rows = np.flatnonzero(rec[:, col] == body)
        if len(rows) == 0:
            continue
        k = rec[rows, codes.REC_STEP].astype(np.int64) - first
        f = rec[rows, codes.REC_IMPULSE : codes.REC_IMPULSE + 3] * (sign / h)
        _add_rows(force, k, f)
        if point is not None:
            times, which = np.unique(rec[rows, codes.REC_TIME], return_inverse=True)
            r = rec[rows, codes.REC_POINT : codes.REC_POINT + 3] - np.asarray(point(times), float)[which]
            lever = np.column_stack(
                [
                    r[:, 1] * f[:, 2] - r[:, 2] * f[:, 1],
                    r[:, 2] * f[:, 0] - r[:, 0] * f[:, 2],
                    r[:, 0] * f[:, 1] - r[:, 1] * f[:, 0],
                ]
            )
            _add_rows(torque, k, lever)
    return steps * h, force, torque


def _add_rows(out: np.ndarray, rows: np.ndarray, values: np.ndarray) -> None:
    """out[rows[i]] += values[i] for every i (repeated rows add up), column by column."""
    for x in range(out.shape[1]):
        out[:, x] += np.bincount(rows, values[:, x], minlength=out.shape[0])


def haptic_frames(result: RunResult, body: int, point=None) -> list[HapticFrame]:
    """HapticFrames of :func:`contact_wrench` (torque included when ``point`` is given)."""
    times, force, torque = contact_wrench(result, body, point)
    if not (np.all(np.isfinite(force)) and np.all(np.isfinite(torque))):
        raise ValueError("haptic_frames: non-finite contact force")
    torques = torque if point is not None else [None] * len(times)
    return [HapticFrame(float(t), f, tq) for t, f, tq in zip(times, force, torques, strict=True)]
