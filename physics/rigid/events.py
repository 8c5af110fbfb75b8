"""From contact records to what sound and haptics consume: Impacts, ContactTracks, haptic frames.

- Impact: the records flagged as impacts at one time between one pair of bodies, merged:
  normal impulse summed (N s), approach speed the largest (m/s), location on each body where
  its strongest record landed, given by the caller's ``locate`` (physics knows the contact
  point, feature and barycentric weights, not the bodies' sound models: patches.rigid_sound
  maps them to modal model rows).
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
from physics.rigid.world import RunResult


def _contact_locations(rows: np.ndarray, locate) -> list[tuple]:
    """(location on body a, location on body b) of each record row, by ``locate(bodies, local,
    feature, bary)`` (body numbers (K,), contact points in the bodies' frames (K, 3) m, features
    (K,), barycentric weights on b (K, 3)) -> one location per row."""
    bary = rows[:, REC_BARY : REC_BARY + 3]
    sides = [
        locate(
            rows[:, col].astype(np.int64),
            rows[:, local : local + 3],
            rows[:, feat].astype(np.int64),
            bary,
        )
        for col, local, feat in ((REC_A, REC_LOCAL_A, REC_FEAT_A), (REC_B, REC_LOCAL_B, REC_FEAT_B))
    ]
    return list(zip(*sides, strict=True))


def impacts(result: RunResult, locate=None) -> list[Impact]:
    """Impact events in time order (see module doc); their locations by ``locate`` (as in
    :func:`_contact_locations`; e.g. patches.rigid_sound.contact_locator), None without it."""
    rec = result.records
    rows = np.flatnonzero(rec[:, REC_IMPACT] > 0)
    if rows.size == 0:
        return []
    # groups of equal (time, a, b), in that order
    order = rows[np.lexsort((rec[rows, REC_B], rec[rows, REC_A], rec[rows, REC_TIME]))]
    first, impulse, speed, strongest = _impact_groups(rec, order)
    heads = order[first]  # each group's first record row
    locations = _contact_locations(rec[strongest], locate) if locate else [(None, None)] * len(heads)
    return [
        Impact(time, (int(a), int(b)), jn, vn, None, where)
        for time, a, b, jn, vn, where in zip(
            rec[heads, REC_TIME].tolist(),
            rec[heads, REC_A].tolist(),
            rec[heads, REC_B].tolist(),
            impulse.tolist(),
            speed.tolist(),
            locations,
            strict=True,
        )
    ]


@nb.njit(cache=True)
def _impact_groups(rec, order):
    """The impact records ``order`` (sorted on time, a, b) grouped per (time, a, b), in one
    pass: (position in ``order`` of each group's first row, normal impulse summed (N s),
    approach speed the largest (m/s), record row of the largest normal impulse (the first
    of equals))."""
    n = order.shape[0]
    first, strongest = np.empty(n, np.int64), np.empty(n, np.int64)
    impulse, speed, best = np.zeros(n), np.empty(n), np.empty(n)
    g = -1
    for j in range(n):
        i = order[j]
        if (
            g < 0
            or rec[i, REC_TIME] != rec[order[j - 1], REC_TIME]
            or rec[i, REC_A] != rec[order[j - 1], REC_A]
            or rec[i, REC_B] != rec[order[j - 1], REC_B]
        ):
            g += 1
            first[g], speed[g], best[g] = j, -np.inf, -np.inf
        jn = 0.0
        for x in range(3):
            jn += rec[i, REC_IMPULSE + x] * rec[i, REC_NORMAL + x]
        impulse[g] += jn
        speed[g] = max(speed[g], rec[i, REC_SPEED])
        if jn > best[g]:
            best[g], strongest[g] = jn, i
    g += 1
    return first[:g].copy(), impulse[:g].copy(), speed[:g].copy(), strongest[:g].copy()


def contact_tracks(result: RunResult, min_steps: int = 5, locate=None) -> list[ContactTrack]:
    """Sustained contacts per pair (see module doc); times are the steps' start times (s);
    the locations of each step's strongest contact by ``locate`` (as for :func:`impacts`),
    empty without it."""
    h = result.world.params.h
    rec = result.records
    n_bodies = len(result.world.bodies)
    rows, pair, step, jn, slip, roll = _sustained_columns(rec, n_bodies)
    # records are in step order: a stable sort by pair leaves each pair's records in step order
    order = np.argsort(pair, kind="stable")
    gpair, gstep, total, slip, roll, strongest = _step_groups(order, rows, pair, step, jn, slip, roll)
    breaks = np.flatnonzero((gpair[1:] != gpair[:-1]) | (gstep[1:] != gstep[:-1] + 1)) + 1
    starts, stops = np.r_[0, breaks], np.r_[breaks, len(gpair)]
    long_enough = stops - starts >= min_steps
    times, force = gstep * h, total / h
    tracks = []
    for lo, hi in zip(starts[long_enough].tolist(), stops[long_enough].tolist(), strict=True):
        locs = _contact_locations(rec[strongest[lo:hi]], locate) if locate else []
        a, b = divmod(int(gpair[lo]), n_bodies)
        tracks.append(ContactTrack((a, b), times[lo:hi], force[lo:hi], slip[lo:hi], roll[lo:hi], locs))
    return sorted(tracks, key=lambda t: t.times[0])


@nb.njit(cache=True)
def _sustained_columns(rec, n_bodies):
    """The non-impact records in one pass over ``rec`` (memory order): (record row, pair key
    a * n_bodies + b, step, normal impulse clamped at >= 0 (N s), slip speed, rolling speed
    (m/s))."""
    n = rec.shape[0]
    rows, pair, step = np.empty(n, np.int64), np.empty(n, np.int64), np.empty(n, np.int64)
    jn, slip, roll = np.empty(n), np.empty(n), np.empty(n)
    m = 0
    for i in range(n):
        if rec[i, REC_IMPACT] != 0:
            continue
        rows[m] = i
        pair[m] = int(rec[i, REC_A]) * n_bodies + int(rec[i, REC_B])
        step[m] = int(rec[i, REC_STEP])
        normal = 0.0
        for x in range(3):
            normal += rec[i, REC_IMPULSE + x] * rec[i, REC_NORMAL + x]
        jn[m] = max(normal, 0.0)
        slip[m], roll[m] = rec[i, REC_SLIP], rec[i, REC_ROLL]
        m += 1
    return rows[:m], pair[:m], step[:m], jn[:m], slip[:m], roll[:m]


@nb.njit(cache=True)
def _step_groups(order, rows, pair_of, step_of, jn_of, slip_of, roll_of):
    """The sustained records taken in ``order`` (by pair, then step) grouped per (pair, step):
    (pair key, step, normal impulse summed over the group (N s), slip and rolling speed
    weighted by it (m/s; plain means where it sums to 0), record row of the strongest
    contact (the first of equals)), in one pass."""
    n = order.shape[0]
    pair, step, strongest = np.empty(n, np.int64), np.empty(n, np.int64), np.empty(n, np.int64)
    sums = np.zeros((n, 6))  # impulse, impulse * slip, impulse * roll, slip, roll, records
    best = np.empty(n)
    g = -1
    for j in range(n):
        o = order[j]
        if g < 0 or pair_of[o] != pair[g] or step_of[o] != step[g]:
            g += 1
            pair[g], step[g], best[g] = pair_of[o], step_of[o], -1.0
        jn, slip, roll = jn_of[o], slip_of[o], roll_of[o]
        sums[g, 0] += jn
        sums[g, 1] += jn * slip
        sums[g, 2] += jn * roll
        sums[g, 3] += slip
        sums[g, 4] += roll
        sums[g, 5] += 1.0
        if jn > best[g]:
            best[g], strongest[g] = jn, rows[o]
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
