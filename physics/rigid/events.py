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
from physics.rigid.codes import (
    REC_A,
    REC_B,
    REC_BARY,
    REC_FEAT_A,
    REC_FEAT_B,
    REC_IMPACT,
    REC_IMPULSE,
    REC_LOCAL_A,
    REC_LOCAL_B,
    REC_NORMAL,
    REC_POINT,
    REC_ROLL,
    REC_SLIP,
    REC_SPEED,
    REC_STEP,
    REC_TIME,
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
        rows[:, REC_IMPULSE : REC_IMPULSE + 3],
        rows[:, REC_NORMAL : REC_NORMAL + 3],
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
    a, b = int(row[REC_A]), int(row[REC_B])
    bary = row[REC_BARY : REC_BARY + 3]
    loc_a = location_on(result, a, row[REC_LOCAL_A : REC_LOCAL_A + 3], int(row[REC_FEAT_A]), bary)
    loc_b = location_on(result, b, row[REC_LOCAL_B : REC_LOCAL_B + 3], int(row[REC_FEAT_B]), bary)
    return loc_a, loc_b


def impacts(result: RunResult) -> list[Impact]:
    """Impact events in time order (see module doc)."""
    rec = result.records
    rows = rec[rec[:, REC_IMPACT] > 0]
    out = []
    for group in _groups(rows[:, [REC_TIME, REC_A, REC_B]]):
        g = rows[group]
        jn = _normal_impulse(g)
        a, b = int(g[0, REC_A]), int(g[0, REC_B])
        out.append(
            Impact(
                float(g[0, REC_TIME]),
                (a, b),
                float(jn.sum()),
                float(g[:, REC_SPEED].max()),
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
    rows = np.flatnonzero(rec[:, REC_IMPACT] == 0)
    pair = rec[rows, REC_A].astype(np.int64) * n_bodies + rec[rows, REC_B].astype(np.int64)
    # records are in step order: a stable sort by pair leaves each pair's records in step order
    order = np.argsort(pair, kind="stable")
    gpair, gstep, total, slip, roll, strongest = _step_groups(rec, rows[order], pair[order])
    breaks = np.flatnonzero((gpair[1:] != gpair[:-1]) | (gstep[1:] != gstep[:-1] + 1)) + 1
    starts, stops = np.r_[0, breaks], np.r_[breaks, len(gpair)]
    long_enough = stops - starts >= min_steps
    tracks = []
    for lo, hi in zip(starts[long_enough].tolist(), stops[long_enough].tolist(), strict=True):
        locs = []
        if with_locations:
            locs = [_locations(result, rec[k : k + 1], np.ones(1)) for k in strongest[lo:hi]]
        a, b = divmod(int(gpair[lo]), n_bodies)
        tracks.append(
            ContactTrack((a, b), gstep[lo:hi] * h, total[lo:hi] / h, slip[lo:hi], roll[lo:hi], locs)
        )
    return sorted(tracks, key=lambda t: t.times[0])


@nb.njit(cache=True)
def _step_groups(rec, rows, pair_of):
    """The records ``rows`` (non-impact, ordered by pair then step; pair_of: their pair keys
    a * bodies + b) grouped per (pair, step): (pair key, step, normal impulse summed over the
    group (N s, each record's clamped at >= 0), slip and rolling speed weighted by it (m/s;
    plain means where it sums to 0), record row of the strongest contact (the first of
    equals)), in one pass."""
    n = rows.shape[0]
    pair, step, strongest = np.empty(n, np.int64), np.empty(n, np.int64), np.empty(n, np.int64)
    sums = np.zeros((n, 6))  # impulse, impulse * slip, impulse * roll, slip, roll, records
    best = np.empty(n)
    g = -1
    for j in range(n):
        i = rows[j]
        s = int(rec[i, REC_STEP])
        if g < 0 or pair_of[j] != pair[g] or s != step[g]:
            g += 1
            pair[g], step[g], best[g] = pair_of[j], s, -1.0
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
    rows, sign = _rows_on(rec, body)
    centres, run = np.zeros((0, 3)), np.zeros(len(rows), np.int64)
    if point is not None and len(rows):
        # the point once per run of equal record times (records are in time order)
        times = rec[rows, REC_TIME]
        starts = np.r_[True, times[1:] != times[:-1]]
        run = np.cumsum(starts) - 1
        centres = np.asarray(point(times[starts]), float).reshape(-1, 3)
    _wrench_sums(rec, rows, sign, first, h, centres, run, force, torque)
    return steps * h, force, torque


@nb.njit(cache=True)
def _rows_on(rec, body):
    """Rows of the records on ``body`` and the sign of their impulse on it (+1 as body a, -1
    as body b)."""
    rows, sign = np.empty(rec.shape[0], np.int64), np.empty(rec.shape[0])
    n = 0
    for i in range(rec.shape[0]):
        if rec[i, REC_A] == body or rec[i, REC_B] == body:
            rows[n], sign[n] = i, 1.0 if rec[i, REC_A] == body else -1.0
            n += 1
    return rows[:n], sign[:n]


@nb.njit(cache=True)
def _wrench_sums(rec, rows, sign, first, h, centres, run, force, torque):
    """Add each record's force (impulse / h, N) to force[step - first] and, when centres
    holds the torque point of each run of record times (run[j]: row j's), its moment about
    that point (N m) to torque."""
    for j in range(rows.shape[0]):
        i = rows[j]
        k = int(rec[i, REC_STEP]) - first
        scale = sign[j] / h
        f0 = rec[i, REC_IMPULSE] * scale
        f1 = rec[i, REC_IMPULSE + 1] * scale
        f2 = rec[i, REC_IMPULSE + 2] * scale
        force[k, 0] += f0
        force[k, 1] += f1
        force[k, 2] += f2
        if centres.shape[0]:
            c = run[j]
            r0 = rec[i, REC_POINT] - centres[c, 0]
            r1 = rec[i, REC_POINT + 1] - centres[c, 1]
            r2 = rec[i, REC_POINT + 2] - centres[c, 2]
            torque[k, 0] += r1 * f2 - r2 * f1
            torque[k, 1] += r2 * f0 - r0 * f2
            torque[k, 2] += r0 * f1 - r1 * f0


def haptic_frames(result: RunResult, body: int, point=None) -> list[HapticFrame]:
    """HapticFrames of :func:`contact_wrench` (torque included when ``point`` is given)."""
    times, force, torque = contact_wrench(result, body, point)
    if not (np.all(np.isfinite(force)) and np.all(np.isfinite(torque))):
        raise ValueError("haptic_frames: non-finite contact force")
    torques = torque if point is not None else [None] * len(times)
    return [HapticFrame(float(t), f, tq) for t, f, tq in zip(times, force, torques, strict=True)]
