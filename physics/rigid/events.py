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

import numba as nb
import numpy as np

from jassy.events import ContactTrack, HapticFrame, Impact
from jassy.modal_model import Location
from physics.rigid import codes
from physics.rigid.codes import (
    REC_A,
    REC_B,
    REC_IMPACT,
    REC_IMPULSE,
    REC_NORMAL,
    REC_ROLL,
    REC_SLIP,
    REC_STEP,
)
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
    n_bodies = len(result.world.bodies)
    gpair, gstep, total, slip, roll, strongest = _step_groups(rec, n_bodies)
    breaks = np.flatnonzero((gpair[1:] != gpair[:-1]) | (gstep[1:] != gstep[:-1] + 1)) + 1
    starts, stops = np.r_[0, breaks], np.r_[breaks, len(gpair)]
    tracks = []
    for lo, hi in zip(starts.tolist(), stops.tolist(), strict=True):
        if hi - lo < min_steps:
            continue
        locs = []
        if with_locations:
            locs = [_locations(result, rec[k : k + 1], np.ones(1)) for k in strongest[lo:hi]]
        a, b = divmod(int(gpair[lo]), n_bodies)
        tracks.append(
            ContactTrack((a, b), gstep[lo:hi] * h, total[lo:hi] / h, slip[lo:hi], roll[lo:hi], locs)
        )
    return sorted(tracks, key=lambda t: t.times[0])


@nb.njit(cache=True)
def _step_groups(rec, n_bodies):
    """The non-impact records grouped per (pair, step), ordered by pair then step: (pair key
    a * n_bodies + b, step, normal impulse summed over the group (N s, each record's clamped
    at >= 0), slip and rolling speed weighted by it (m/s; plain means where it sums to 0),
    record row of the strongest contact (the first of equals)). One pass after a stable
    sort by pair: the records are in step order."""
    m = rec.shape[0]
    key = np.empty(m, np.int64)
    row = np.empty(m, np.int64)
    n = 0
    for i in range(m):
        if rec[i, REC_IMPACT] == 0.0:
            key[n] = int(rec[i, REC_A]) * n_bodies + int(rec[i, REC_B])
            row[n] = i
            n += 1
    order = np.argsort(key[:n], kind="mergesort")
    pair, step, strongest = np.empty(n, np.int64), np.empty(n, np.int64), np.empty(n, np.int64)
    sums = np.zeros((n, 6))  # impulse, impulse * slip, impulse * roll, slip, roll, records
    best = np.empty(n)
    g = -1
    for j in order:
        i = row[j]
        s = int(rec[i, REC_STEP])
        if g < 0 or key[j] != pair[g] or s != step[g]:
            g += 1
            pair[g], step[g], best[g] = key[j], s, -1.0
        jn = 0.0
        for x in range(3):
            jn += rec[i, REC_IMPULSE + x] * rec[i, REC_NORMAL + x]
        jn = max(jn, 0.0)
        slip, roll = rec[i, REC_SLIP], rec[i, REC_ROLL]
        sums[g, 0] += jn
        sums[g, 1] += jn * slip
        sums[g, 2] += jn * roll
        sums[g, 3] += slip
        sums[g, 4] += roll
        sums[g, 5] += 1.0
        if jn > best[g]:
            best[g], strongest[g] = jn, i
    g += 1
    total, slip_mean, roll_mean = sums[:g, 0].copy(), np.empty(g), np.empty(g)
    for k in range(g):
        if total[k] > 0.0:
            slip_mean[k], roll_mean[k] = sums[k, 1] / total[k], sums[k, 2] / total[k]
        else:
            slip_mean[k], roll_mean[k] = sums[k, 3] / sums[k, 5], sums[k, 4] / sums[k, 5]
    return pair[:g].copy(), step[:g].copy(), total, slip_mean, roll_mean, strongest[:g].copy()


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
            # the point once per run of equal record times (records are in time order)
            times = rec[rows, codes.REC_TIME]
            run = np.r_[True, times[1:] != times[:-1]]
            which = np.cumsum(run) - 1
            r = rec[rows, codes.REC_POINT : codes.REC_POINT + 3] - np.asarray(point(times[run]), float)[which]
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
