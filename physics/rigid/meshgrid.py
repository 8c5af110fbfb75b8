"""Closest points on triangle meshes: the point-triangle kernel and a uniform grid of triangles.

A static (or kinematic) surface is bucketed once into a uniform grid in its own frame; a
query visits the cells overlapping a ball and returns the closest point among their
triangles, with the triangle index and barycentric coordinates (the contact's location on
the mesh). Point-triangle closest point: Ericson, Real-Time Collision Detection, 5.1.5.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numba as nb
import numpy as np


@nb.njit(cache=True, inline="always")
def triangle_weights(px, py, pz, tri, t):
    """Barycentric weights (u, v, w) of the point of triangle tri[t] (vertices a, b, c) closest
    to the point (px, py, pz); scalar arithmetic, no allocation."""
    ax, ay, az = tri[t, 0, 0], tri[t, 0, 1], tri[t, 0, 2]
    ab0, ab1, ab2 = tri[t, 1, 0] - ax, tri[t, 1, 1] - ay, tri[t, 1, 2] - az
    ac0, ac1, ac2 = tri[t, 2, 0] - ax, tri[t, 2, 1] - ay, tri[t, 2, 2] - az
    ap0, ap1, ap2 = px - ax, py - ay, pz - az
    d1 = ab0 * ap0 + ab1 * ap1 + ab2 * ap2
    d2 = ac0 * ap0 + ac1 * ap1 + ac2 * ap2
    if d1 <= 0.0 and d2 <= 0.0:
        return 1.0, 0.0, 0.0
    bp0, bp1, bp2 = ap0 - ab0, ap1 - ab1, ap2 - ab2
    d3 = ab0 * bp0 + ab1 * bp1 + ab2 * bp2
    d4 = ac0 * bp0 + ac1 * bp1 + ac2 * bp2
    if d3 >= 0.0 and d4 <= d3:
        return 0.0, 1.0, 0.0
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        v = d1 / (d1 - d3)
        return 1.0 - v, v, 0.0
    cp0, cp1, cp2 = ap0 - ac0, ap1 - ac1, ap2 - ac2
    d5 = ab0 * cp0 + ab1 * cp1 + ab2 * cp2
    d6 = ac0 * cp0 + ac1 * cp1 + ac2 * cp2
    if d6 >= 0.0 and d5 <= d6:
        return 0.0, 0.0, 1.0
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        w = d2 / (d2 - d6)
        return 1.0 - w, 0.0, w
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return 0.0, 1.0 - w, w
    denom = 1.0 / (va + vb + vc)
    v = vb * denom
    w = vc * denom
    return 1.0 - v - w, v, w


@nb.njit(cache=True, inline="always")
def triangle_point(tri, t, u, v, w):
    """The point u a + v b + w c of triangle tri[t]."""
    return (
        u * tri[t, 0, 0] + v * tri[t, 1, 0] + w * tri[t, 2, 0],
        u * tri[t, 0, 1] + v * tri[t, 1, 1] + w * tri[t, 2, 1],
        u * tri[t, 0, 2] + v * tri[t, 1, 2] + w * tri[t, 2, 2],
    )


@dataclass(frozen=True)
class TriangleGrid:
    """Triangles (T, 3, 3), normals (T, 3) and bounding spheres (T, 4: centroid, radius) of one
    surface, bucketed in a uniform grid: cell (i, j, k) holds items[start[c]:start[c + 1]],
    c = (i * ny + j) * nz + k."""

    triangles: np.ndarray
    normals: np.ndarray
    spheres: np.ndarray
    origin: np.ndarray
    cell: float
    dims: np.ndarray
    start: np.ndarray
    items: np.ndarray

    def view(self) -> GridView:
        """The grid as the queries' record (a lone grid: offsets (0, 0, 0))."""
        return GridView(
            self.triangles, self.spheres, self.origin, self.cell, self.dims, self.start, self.items, (0, 0, 0)
        )


class GridView(NamedTuple):
    """What grid_closest and grid_within read of a grid. The arrays may hold several grids end
    to end (physics.rigid.model.Geometry's mesh tables): ``offsets`` = (first triangle, first
    cell start, first item) of this one; items and the triangle indices the queries return
    count from its first triangle."""

    tri: np.ndarray  # (T, 3, 3) triangles' corners, m
    spheres: np.ndarray  # (T, 4) their bounding spheres (centre, radius), m
    origin: tuple  # (x, y, z) of the grid's low corner, m (an array or a tuple)
    cell: float  # cell size, m
    dims: tuple  # cell counts (an array or a tuple)
    start: np.ndarray  # each cell's start in items
    items: np.ndarray  # triangle numbers of the cells' lists
    offsets: tuple  # (first triangle, first cell start, first item)


def build_grid(vertices: np.ndarray, faces: np.ndarray, cell: float | None = None) -> TriangleGrid:
    """Bucket the triangles by the cells their bounding boxes overlap. The default cell is
    twice the mean edge length (a few triangles per cell)."""
    tri = np.ascontiguousarray(vertices[faces], dtype=np.float64)
    normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-300)
    centroids = tri.mean(axis=1)
    spheres = np.c_[centroids, np.linalg.norm(tri - centroids[:, None], axis=2).max(axis=1)]
    if cell is None:
        edges = np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2)
        cell = 2.0 * float(edges.mean())
    lo = tri.min(axis=(0, 1)) - 1e-9
    hi = tri.max(axis=(0, 1)) + 1e-9
    dims = np.maximum(1, np.ceil((hi - lo) / cell)).astype(np.int64)
    tlo = np.floor((tri.min(axis=1) - lo) / cell).astype(np.int64)
    thi = np.minimum(np.floor((tri.max(axis=1) - lo) / cell).astype(np.int64), dims - 1)
    # every (triangle, cell) of the triangle's cell range, triangle by triangle
    span = thi - tlo + 1
    counts = span.prod(axis=1)
    owners_a = np.repeat(np.arange(len(tri)), counts)
    local = np.arange(owners_a.size) - np.repeat(np.cumsum(counts) - counts, counts)
    sy, sz = span[owners_a, 1], span[owners_a, 2]
    ijk = tlo[owners_a] + np.column_stack([local // (sy * sz), (local // sz) % sy, local % sz])
    cells_a = (ijk[:, 0] * dims[1] + ijk[:, 1]) * dims[2] + ijk[:, 2]
    order = np.argsort(cells_a, kind="stable")
    start = np.searchsorted(cells_a[order], np.arange(int(np.prod(dims)) + 1)).astype(np.int64)
    return TriangleGrid(tri, normals, spheres, lo, float(cell), dims, start, owners_a[order].astype(np.int64))


@nb.njit(cache=True, inline="always")
def triangle_distance2(px, py, pz, tri, spheres, t, within):
    """Squared distance (m^2) from (px, py, pz) to triangle tri[t] and the barycentric weights
    of its nearest point, or (inf, 0, 0, 0) without computing it when the triangle's bounding
    sphere spheres[t] is further than ``within`` (m)."""
    dx, dy, dz = px - spheres[t, 0], py - spheres[t, 1], pz - spheres[t, 2]
    lim = within + spheres[t, 3]
    if dx * dx + dy * dy + dz * dz > lim * lim:
        return math.inf, 0.0, 0.0, 0.0
    u, v, w = triangle_weights(px, py, pz, tri, t)
    qx, qy, qz = triangle_point(tri, t, u, v, w)
    return (px - qx) ** 2 + (py - qy) ** 2 + (pz - qz) ** 2, u, v, w


@nb.njit(cache=True, inline="always")
def _cell_range(px, py, pz, radius, origin, cell, dims):
    """Index ranges (lo_i, hi_i, lo_j, hi_j, lo_k, hi_k) of the cells that the box around the
    ball of ``radius`` (m) about (px, py, pz) overlaps."""
    return (
        max(0, int(math.floor((px - radius - origin[0]) / cell))),
        min(dims[0] - 1, int(math.floor((px + radius - origin[0]) / cell))),
        max(0, int(math.floor((py - radius - origin[1]) / cell))),
        min(dims[1] - 1, int(math.floor((py + radius - origin[1]) / cell))),
        max(0, int(math.floor((pz - radius - origin[2]) / cell))),
        min(dims[2] - 1, int(math.floor((pz + radius - origin[2]) / cell))),
    )


@nb.njit(cache=True, inline="always")
def grid_closest(px, py, pz, reach, grid):
    """Closest point of the surface ``grid`` (GridView) within ``reach`` (m) of (px, py, pz):
    (triangle index from the grid's first or -1, squared distance, barycentric weights u, v,
    w); no allocation."""
    tri, spheres, origin, cell, dims, start, items, offsets = grid
    t0, s0, i0 = offsets[0], offsets[1], offsets[2]
    best = -1
    best_d2 = reach * reach
    best_d = math.sqrt(best_d2)
    bu = bv = bw = 0.0
    lo_i, hi_i, lo_j, hi_j, lo_k, hi_k = _cell_range(px, py, pz, reach, origin, cell, dims)
    for i in range(lo_i, hi_i + 1):
        for j in range(lo_j, hi_j + 1):
            for k in range(lo_k, hi_k + 1):
                c = s0 + (i * dims[1] + j) * dims[2] + k
                for s in range(start[c], start[c + 1]):
                    t = t0 + items[i0 + s]
                    d2, u, v, w = triangle_distance2(px, py, pz, tri, spheres, t, best_d)
                    if d2 < best_d2:
                        best_d2, best_d, best = d2, math.sqrt(d2), t - t0
                        bu, bv, bw = u, v, w
    return best, best_d2, bu, bv, bw


@nb.njit(cache=True, inline="always")
def grid_within(px, py, pz, radius, grid, out, dist, row):
    """The triangles of the surface ``grid`` (GridView) within ``radius`` (m) of (px, py, pz),
    nearest first: their indices (from the grid's first triangle, as grid_closest) into
    out[row] and distances (m) into dist[row]; returns how many, or -1 when there are more
    than a row holds."""
    tri, spheres, origin, cell, dims, start, items, offsets = grid
    t0, s0, i0 = offsets[0], offsets[1], offsets[2]
    n = 0
    lo_i, hi_i, lo_j, hi_j, lo_k, hi_k = _cell_range(px, py, pz, radius, origin, cell, dims)
    for i in range(lo_i, hi_i + 1):
        for j in range(lo_j, hi_j + 1):
            for k in range(lo_k, hi_k + 1):
                c = s0 + (i * dims[1] + j) * dims[2] + k
                for s in range(start[c], start[c + 1]):
                    t = t0 + items[i0 + s]
                    d2 = triangle_distance2(px, py, pz, tri, spheres, t, radius)[0]
                    if d2 > radius * radius:
                        continue
                    d = math.sqrt(d2)
                    at = n  # insertion point, keeping out sorted by distance; skip repeats
                    for e in range(n):
                        if out[row, e] == t - t0:
                            at = -1
                            break
                    if at < 0:
                        continue
                    if n == out.shape[1]:
                        return -1
                    while at > 0 and dist[row, at - 1] > d:
                        out[row, at], dist[row, at] = out[row, at - 1], dist[row, at - 1]
                        at -= 1
                    out[row, at], dist[row, at] = t - t0, d
                    n += 1
    return n
