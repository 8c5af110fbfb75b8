"""Contact detection between curved rod elements of radius r, rigid disks and planes (numba kernels).

An element (arc) is a row (x, y, theta, kappa, l): start pose, constant curvature (1/m), length (m);
its centre line is p(s) = (x, y) + s sinc(kappa s / 2) (cos, sin)(theta + kappa s / 2), s in [0, l].

* arc-point / arc-disk (analytic): the closest point of an arc to a centre c lies on the line through
  the arc's circle centre o and c, at theta(s) = atan2(d_x, -d_y) (kappa > 0) or atan2(-d_x, d_y)
  (kappa < 0), d = c - o, wrapped into the period 2 pi/|kappa| and compared with both end points.
  Nearly straight elements (|kappa l| < 1e-4) use the segment projection polished by Newton steps
  on (p(s) - c).t(s) = 0.
* arc-plane (analytic): the interior minimum of (p(s) - p0).n is where the tangent is normal to n.
* arc-arc: the minimum of |p1(s1) - p2(s2)| over the rectangle is at a stationary interior pair (both
  points on the line of centres: 4 sign choices; for a nearly straight element, the circle points whose
  tangent is parallel to it) or on an edge (each end point against the other arc). Centre lines that
  cross (penetration deeper than r1 + r2) are not detected as such.
* broad phase: each element lies in the disk of radius l/2 about its arc-length midpoint; candidate
  pairs come from scipy's cKDTree on these disks (``broad_phase`` within one set, ``cross_pairs``
  between two sets: elements against disks).

A contact is (s_a, s_b, p_a, p_b, n, gap): closest centre-line points, unit normal n from b to a,
gap = |p_a - p_b| - r_a - r_b (m, negative when penetrating).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np
from scipy.spatial import cKDTree

_STRAIGHT = 1e-4


class Arc(NamedTuple):
    """One element, a row (x, y, theta, kappa, l) of an arcs array."""

    x: float  #: start point x (m)
    y: float  #: start point y (m)
    theta: float  #: tangent angle at the start (rad)
    kappa: float  #: curvature (1/m)
    length: float  #: arc length l (m)


@numba.njit(inline="always", cache=True)
def as_arc(row):
    """The Arc record of a row of an arcs array."""
    return Arc(row[0], row[1], row[2], row[3], row[4])


class ContactRow(NamedTuple):
    """Columns of a contact row (the arrays returned by arc_disk, arc_plane and arc_arc)."""

    s_a: float  #: arc length of the closest point on a (m; 0 for a disk)
    s_b: float  #: arc length of the closest point on b (m; 0 for a disk or a plane)
    pa_x: float  #: closest centre-line point of a (m)
    pa_y: float
    pb_x: float  #: closest centre-line point (or centre, or plane point) of b (m)
    pb_y: float
    n_x: float  #: unit normal from b to a
    n_y: float
    gap: float  #: |p_a - p_b| - r_a - r_b (m, negative when penetrating)


#: Column of each ContactRow field in a contacts array.
S_A, S_B, PA_X, PA_Y, PB_X, PB_Y, N_X, N_Y, GAP = range(len(ContactRow._fields))


@numba.njit(inline="always", cache=True)
def _put(out, m, row):
    """Write the ContactRow ``row`` to out[m]."""
    for k in range(len(row)):
        out[m, k] = row[k]


@numba.njit(cache=True)
def _sinc(u):
    if abs(u) < 1e-4:
        return 1.0 - u * u / 6.0
    return math.sin(u) / u


@numba.njit(cache=True)
def arc_point(arc, s):
    """Centre-line point (x, y) at arc length s (stable sinc form)."""
    h = arc.kappa * s * 0.5
    c = s * _sinc(h)
    return arc.x + c * math.cos(arc.theta + h), arc.y + c * math.sin(arc.theta + h)


@numba.njit(cache=True)
def _wrap(s, k):
    period = 2.0 * math.pi / abs(k)
    return s - period * math.floor(s / period)


@numba.njit(cache=True)
def _circle_s(arc, dx, dy):
    """Arc length of the circle point in direction (dx, dy) from the circle centre (in [0, period))."""
    k = arc.kappa
    alpha = math.atan2(dx, -dy) if k > 0 else math.atan2(-dx, dy)
    return _wrap((alpha - arc.theta) / k, k)


@numba.njit(cache=True)
def _centre(arc):
    k = arc.kappa
    return arc.x - math.sin(arc.theta) / k, arc.y + math.cos(arc.theta) / k


@numba.njit(cache=True)
def closest_on_arc(arc, cx, cy):
    """(s, squared distance) of the arc point closest to (cx, cy)."""
    ln = arc.length
    best_s, best_d = 0.0, (arc.x - cx) ** 2 + (arc.y - cy) ** 2
    ex, ey = arc_point(arc, ln)
    d = (ex - cx) ** 2 + (ey - cy) ** 2
    if d < best_d:
        best_s, best_d = ln, d
    k = arc.kappa
    if abs(k) * ln >= _STRAIGHT:
        ox, oy = _centre(arc)
        s = _circle_s(arc, cx - ox, cy - oy) if cx != ox or cy != oy else 2.0 * ln
    else:
        s = min(max((cx - arc.x) * math.cos(arc.theta) + (cy - arc.y) * math.sin(arc.theta), 0.0), ln)
        for _ in range(3):
            px, py = arc_point(arc, s)
            th = arc.theta + k * s
            tx, ty = math.cos(th), math.sin(th)
            g = (px - cx) * tx + (py - cy) * ty
            dg = 1.0 + k * (-(px - cx) * ty + (py - cy) * tx)
            s = min(max(s - g / dg, 0.0), ln) if dg > 0 else s
    if 0.0 < s < ln:
        px, py = arc_point(arc, s)
        d = (px - cx) ** 2 + (py - cy) ** 2
        if d < best_d:
            best_s, best_d = s, d
    return best_s, best_d


@numba.njit(cache=True)
def _fill(out, m, sa, sb, pa, pb, fallback, gap_offset):
    """out[m] = the ContactRow of closest points pa, pb (x, y); the normal is ``fallback``
    (x, y) when they coincide; gap = |pa - pb| - gap_offset."""
    (pax, pay), (pbx, pby) = pa, pb
    dx, dy = pax - pbx, pay - pby
    dist = math.sqrt(dx * dx + dy * dy)
    if dist > 1e-300:
        nx, ny = dx / dist, dy / dist
    else:
        nx, ny = fallback
    _put(out, m, ContactRow(sa, sb, pax, pay, pbx, pby, nx, ny, dist - gap_offset))


@numba.njit(cache=True)
def arc_disk(arcs, elems, centres, radii, r):
    """Contacts of arcs[elems[m]] (rod radius r[m]) with disks (centres[m], radii[m]): rows
    (s, 0, p_arc, p_centre, n from disk to arc, gap)."""
    out = np.empty((elems.size, 9))
    for m in range(elems.size):
        arc = as_arc(arcs[elems[m]])
        cx, cy = centres[m, 0], centres[m, 1]
        s, _ = closest_on_arc(arc, cx, cy)
        px, py = arc_point(arc, s)
        th = arc.theta + arc.kappa * s
        _fill(out, m, s, 0.0, (px, py), (cx, cy), (-math.sin(th), math.cos(th)), radii[m] + r[m])
    return out


@numba.njit(cache=True)
def arc_plane(arcs, elems, point, normal, r):
    """Contacts of arcs[elems[m]] with the plane (point, unit normal out of the solid): rows
    (s, 0, p_arc, p_plane, n = normal, gap = (p_arc - point).n - r)."""
    out = np.empty((elems.size, 9))
    nx, ny = normal[0], normal[1]
    for m in range(elems.size):
        arc = as_arc(arcs[elems[m]])
        ln, k = arc.length, arc.kappa
        best_s = 0.0
        best = (arc.x - point[0]) * nx + (arc.y - point[1]) * ny
        ex, ey = arc_point(arc, ln)
        d = (ex - point[0]) * nx + (ey - point[1]) * ny
        if d < best:
            best_s, best = ln, d
        if abs(k) * ln >= _STRAIGHT:
            s = _circle_s(arc, -nx, -ny)
            if s < ln:
                px, py = arc_point(arc, s)
                d = (px - point[0]) * nx + (py - point[1]) * ny
                if d < best:
                    best_s, best = s, d
        px, py = arc_point(arc, best_s)
        qx, qy = px - best * nx, py - best * ny
        _put(out, m, ContactRow(best_s, 0.0, px, py, qx, qy, nx, ny, best - r))
    return out


@numba.njit(cache=True)
def _try_pair(a1, a2, s1, s2, best):
    if 0.0 <= s1 <= a1.length and 0.0 <= s2 <= a2.length:
        p1x, p1y = arc_point(a1, s1)
        p2x, p2y = arc_point(a2, s2)
        d = (p1x - p2x) ** 2 + (p1y - p2y) ** 2
        if d < best[2]:
            best[0], best[1], best[2] = s1, s2, d


@numba.njit(cache=True)
def closest_arc_arc(a1, a2):
    """(s1, s2, squared distance) of the closest centre-line points of two arcs."""
    best = np.array([0.0, 0.0, np.inf])
    for e in range(2):
        px, py = arc_point(a1, e * a1.length)
        s, _ = closest_on_arc(a2, px, py)
        _try_pair(a1, a2, e * a1.length, s, best)
        px, py = arc_point(a2, e * a2.length)
        s, _ = closest_on_arc(a1, px, py)
        _try_pair(a1, a2, s, e * a2.length, best)
    c1 = abs(a1.kappa) * a1.length >= _STRAIGHT
    c2 = abs(a2.kappa) * a2.length >= _STRAIGHT
    if c1 and c2:
        o1x, o1y = _centre(a1)
        o2x, o2y = _centre(a2)
        ux, uy = o2x - o1x, o2y - o1y
        if ux != 0.0 or uy != 0.0:
            for sg1 in (1.0, -1.0):
                for sg2 in (1.0, -1.0):
                    _try_pair(
                        a1, a2, _circle_s(a1, sg1 * ux, sg1 * uy), _circle_s(a2, -sg2 * ux, -sg2 * uy), best
                    )
    elif c1 or c2:
        ca, sa = (a1, a2) if c1 else (a2, a1)
        tx, ty = math.cos(sa.theta), math.sin(sa.theta)
        for sg in (1.0, -1.0):
            sc = _circle_s(ca, sg * -ty, sg * tx)
            if sc <= ca.length:
                px, py = arc_point(ca, sc)
                ss, _ = closest_on_arc(sa, px, py)
                if c1:
                    _try_pair(a1, a2, sc, ss, best)
                else:
                    _try_pair(a1, a2, ss, sc, best)
    if not (c1 and c2):
        s1, s2 = best[0], best[1]
        for _ in range(3):
            px, py = arc_point(a2, s2)
            s1, _ = closest_on_arc(a1, px, py)
            px, py = arc_point(a1, s1)
            s2, _ = closest_on_arc(a2, px, py)
        _try_pair(a1, a2, s1, s2, best)
    return best[0], best[1], best[2]


@numba.njit(cache=True)
def arc_arc(arcs, ia, ib, ra, rb):
    """Contacts between arcs[ia[m]] (radius ra[m]) and arcs[ib[m]] (radius rb[m]): rows
    (s_a, s_b, p_a, p_b, n from b to a, gap)."""
    out = np.empty((ia.size, 9))
    for m in range(ia.size):
        a1, a2 = as_arc(arcs[ia[m]]), as_arc(arcs[ib[m]])
        s1, s2, _ = closest_arc_arc(a1, a2)
        p1x, p1y = arc_point(a1, s1)
        p2x, p2y = arc_point(a2, s2)
        th = a2.theta + a2.kappa * s2
        _fill(out, m, s1, s2, (p1x, p1y), (p2x, p2y), (-math.sin(th), math.cos(th)), ra[m] + rb[m])
    return out


def element_bounds(arcs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Bounding disks (centres (N, 2), radii (N,)) of arcs (N, 5): arc-length midpoint, l/2."""
    h = arcs[:, 3] * arcs[:, 4] * 0.25
    c = 0.5 * arcs[:, 4] * np.sinc(h / np.pi)
    ang = arcs[:, 2] + h
    centres = np.column_stack([arcs[:, 0] + c * np.cos(ang), arcs[:, 1] + c * np.sin(ang)])
    return centres, 0.5 * arcs[:, 4]


def broad_phase(centres: np.ndarray, radii: np.ndarray, margin: float) -> np.ndarray:
    """Pairs (P, 2), i < j, of disks (centres (N, 2), radii (N,) including thickness) closer than
    ``margin`` (m): cKDTree pairs within 2 max(radii) + margin, then the exact disk test."""
    if len(centres) < 2:
        return np.zeros((0, 2), dtype=np.int64)
    tree = cKDTree(centres)
    pairs = tree.query_pairs(2.0 * float(np.max(radii)) + margin, output_type="ndarray")
    if pairs.size == 0:
        return np.zeros((0, 2), dtype=np.int64)
    d = np.linalg.norm(centres[pairs[:, 0]] - centres[pairs[:, 1]], axis=1)
    return pairs[d <= radii[pairs[:, 0]] + radii[pairs[:, 1]] + margin].astype(np.int64)


def cross_pairs(
    centres_a: np.ndarray, radii_a: np.ndarray, centres_b: np.ndarray, radii_b: np.ndarray, margin: float
) -> np.ndarray:
    """Pairs (P, 2) (index in a, index in b), in lexicographic order, of a disk of set a and a disk of
    set b closer than ``margin`` (m): cKDTree neighbours within max(radii_a) + max(radii_b) + margin,
    then the exact disk test."""
    if len(centres_a) == 0 or len(centres_b) == 0:
        return np.zeros((0, 2), dtype=np.int64)
    reach = float(np.max(radii_a)) + float(np.max(radii_b)) + margin
    near = cKDTree(centres_a).sparse_distance_matrix(cKDTree(centres_b), reach, output_type="ndarray")
    i, j = near["i"].astype(np.int64), near["j"].astype(np.int64)
    d = np.linalg.norm(centres_a[i] - centres_b[j], axis=1)
    ok = d <= radii_a[i] + radii_b[j] + margin
    pairs = np.column_stack([i[ok], j[ok]])
    return pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))]
