"""Narrow phase: contact points between two posed shapes, and a sweep-and-prune broad phase.

Every contact is (point, normal, gap, feature of a, feature of b, barycentric weights on b)
with the normal pointing from b to a (pushing a along +n) and gap < 0 meaning penetration.
Pairs are ordered so that type(a) <= type(b) (sphere < capsule < box < convex < plane <
mesh). Methods:

- sphere/capsule vs sphere/capsule: closest points of two segments (Ericson 5.1.9);
- sphere vs polytope (box, convex): inside by the face planes (deepest face), outside by the
  closest point on the hull triangles; a capsule is tested as its two end spheres and its
  middle sphere;
- polytope vs polytope: each vertex of one against the other's face planes (vertex-face
  contacts; edge-edge contacts are not generated);
- anything vs plane: the sphere centres or vertices against the plane;
- anything vs triangle mesh: the same points against the mesh's triangle grid, keeping the
  side the triangle normals face; points up to the mesh's ``depth`` behind it penetrate.

``geo`` is the tuple of flat model arrays built by physics.rigid.world._build_arrays.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from physics.rigid.meshgrid import closest_on_triangle, closest_weights, grid_closest, weighted_distance2
from physics.rigid.shapes import CAPSULE, MESH, PLANE, SPHERE
from physics.rigid.spatial import dot3, mtv, mv


@nb.njit(cache=True)
def _push(buf, count, a, b, point, normal, gap, fa, fb, bary):
    """Append one contact to the buffers; returns the new count (drops when full)."""
    pts, nrm, gaps, pair, feat, bar = buf
    if count >= gaps.size:
        return count
    pts[count] = point
    nrm[count] = normal
    gaps[count] = gap
    pair[count, 0] = a
    pair[count, 1] = b
    feat[count, 0] = fa
    feat[count, 1] = fb
    bar[count] = bary
    return count + 1


@nb.njit(cache=True)
def _segment_points(body, pos, rot, geo):
    """World end points of a sphere (a degenerate segment) or a capsule axis."""
    btype, param = geo[0], geo[2]
    c = pos[body]
    if btype[body] == SPHERE:
        return c.copy(), c.copy()
    axis = rot[body][:, 2] * param[body, 1]
    return c - axis, c + axis


@nb.njit(cache=True)
def closest_segments(p1, q1, p2, q2):
    """Closest points (c1, c2) of segments p1q1 and p2q2."""
    d1 = q1 - p1
    d2 = q2 - p2
    r = p1 - p2
    a = dot3(d1, d1)
    e = dot3(d2, d2)
    f = dot3(d2, r)
    eps = 1e-24
    if a <= eps and e <= eps:
        return p1.copy(), p2.copy()
    if a <= eps:
        s = 0.0
        t = min(max(f / e, 0.0), 1.0)
    else:
        c = dot3(d1, r)
        if e <= eps:
            t = 0.0
            s = min(max(-c / a, 0.0), 1.0)
        else:
            b = dot3(d1, d2)
            denom = a * e - b * b
            s = min(max((b * f - c * e) / denom, 0.0), 1.0) if denom > eps else 0.0
            t = (b * s + f) / e
            if t < 0.0:
                t = 0.0
                s = min(max(-c / a, 0.0), 1.0)
            elif t > 1.0:
                t = 1.0
                s = min(max((b - c) / a, 0.0), 1.0)
    return p1 + d1 * s, p2 + d2 * t


@nb.njit(cache=True)
def _segment_segment(a, b, pos, rot, geo, margin, buf, count):
    param = geo[2]
    pa, qa = _segment_points(a, pos, rot, geo)
    pb, qb = _segment_points(b, pos, rot, geo)
    ca, cb = closest_segments(pa, qa, pb, qb)
    d = ca - cb
    dist = math.sqrt(dot3(d, d))
    gap = dist - param[a, 0] - param[b, 0]
    if gap > margin:
        return count
    n = d / dist if dist > 1e-12 else np.array([0.0, 0.0, 1.0])
    point = cb + n * (param[b, 0] + 0.5 * gap)
    return _push(buf, count, a, b, point, n, gap, -1, -1, np.zeros(3))


@nb.njit(cache=True)
def _sphere_points(a, pos, rot, geo):
    """Centres of the spheres standing for body a (1 for a sphere, 3 for a capsule)."""
    pa, qa = _segment_points(a, pos, rot, geo)
    if geo[0][a] == SPHERE:
        out = np.empty((1, 3))
        out[0] = pa
        return out
    out = np.empty((3, 3))
    out[0] = pa
    out[1] = 0.5 * (pa + qa)
    out[2] = qa
    return out


@nb.njit(cache=True)
def _deepest_plane(local, b, geo):
    """(largest signed distance of the body-frame point ``local`` over polytope b's face
    planes, index of that plane): negative inside, an under-estimate of the distance outside."""
    pstart, planes = geo[6], geo[7]
    best = -math.inf
    face = -1
    for j in range(pstart[b], pstart[b + 1]):
        sd = dot3(planes[j, :3], local) - planes[j, 3]
        if sd > best:
            best = sd
            face = j
    return best, face


@nb.njit(cache=True)
def _polytope_distance(x, b, pos, rot, geo):
    """Signed distance from world point x to polytope b, with the outward normal (world) at
    the closest point and the index of the face plane or hull triangle reached."""
    pstart, planes, hstart, htris = geo[6], geo[7], geo[8], geo[9]
    local = mtv(rot[b], x - pos[b])
    best, face = _deepest_plane(local, b, geo)
    if best <= 0.0:
        return best, mv(rot[b], planes[face, :3]), face - pstart[b]
    best_d2 = math.inf
    tri = -1
    for t in range(hstart[b], hstart[b + 1]):
        u, v, w = closest_weights(local, htris[t, 0], htris[t, 1], htris[t, 2])
        d2 = weighted_distance2(local, htris[t], u, v, w)
        if d2 < best_d2:
            best_d2 = d2
            tri = t
    best_q, _ = closest_on_triangle(local, htris[tri, 0], htris[tri, 1], htris[tri, 2])
    tri -= hstart[b]
    dist = math.sqrt(best_d2)
    n_local = (local - best_q) / dist if dist > 1e-12 else planes[face, :3]
    return dist, mv(rot[b], n_local), tri


@nb.njit(cache=True)
def _spheres_polytope(a, b, pos, rot, geo, margin, buf, count):
    r = geo[2][a, 0]
    centres = _sphere_points(a, pos, rot, geo)
    for i in range(centres.shape[0]):
        x = centres[i]
        sd, n, feature = _polytope_distance(x, b, pos, rot, geo)
        gap = sd - r
        if gap <= margin:
            count = _push(buf, count, a, b, x - n * (r + 0.5 * gap), n, gap, -1, feature, np.zeros(3))
    return count


@nb.njit(cache=True)
def _vertices_polytope(a, b, pos, rot, geo, margin, buf, count, flip):
    """Vertices of polytope a against polytope b (normal from b to a; reversed if flip)."""
    vstart, verts = geo[4], geo[5]
    pstart, planes = geo[6], geo[7]
    for v in range(vstart[a], vstart[a + 1]):
        x = pos[a] + mv(rot[a], verts[v])
        best, face = _deepest_plane(mtv(rot[b], x - pos[b]), b, geo)
        if best <= margin:
            n = mv(rot[b], planes[face, :3])
            point = x - 0.5 * best * n
            if flip:
                count = _push(buf, count, b, a, point, -n, best, face - pstart[b], v - vstart[a], np.zeros(3))
            else:
                count = _push(buf, count, a, b, point, n, best, v - vstart[a], face - pstart[b], np.zeros(3))
    return count


@nb.njit(cache=True)
def _points_of(a, pos, rot, geo):
    """(world points, radius, vertex indices or -1) standing for body a against a plane or mesh."""
    btype = geo[0]
    if btype[a] == SPHERE or btype[a] == CAPSULE:
        pts = _sphere_points(a, pos, rot, geo)
        return pts, geo[2][a, 0], np.full(pts.shape[0], -1, np.int64)
    vstart, verts = geo[4], geo[5]
    n = vstart[a + 1] - vstart[a]
    pts = np.empty((n, 3))
    for i in range(n):
        pts[i] = pos[a] + mv(rot[a], verts[vstart[a] + i])
    return pts, 0.0, np.arange(n)


@nb.njit(cache=True)
def _against_plane(a, b, pos, rot, geo, margin, buf, count):
    param = geo[2]
    n = mv(rot[b], param[b, :3])
    d = param[b, 3] + dot3(n, pos[b])
    pts, r, ids = _points_of(a, pos, rot, geo)
    for i in range(pts.shape[0]):
        gap = dot3(n, pts[i]) - d - r
        if gap <= margin:
            count = _push(buf, count, a, b, pts[i] - n * (r + 0.5 * gap), n, gap, ids[i], -1, np.zeros(3))
    return count


@nb.njit(cache=True)
def _against_mesh(a, b, pos, rot, geo, margin, buf, count):
    mesh_id, tri_off, tris, nrms, grid_f, grid_i, cell_off, starts, item_off, items = geo[10:20]
    m = mesh_id[b]
    thick, depth = geo[2][b, 0], geo[2][b, 1]
    pts, r, ids = _points_of(a, pos, rot, geo)
    t0, t1 = tri_off[m], tri_off[m + 1]
    for i in range(pts.shape[0]):
        local = mtv(rot[b], pts[i] - pos[b])
        reach = r + thick + max(margin, 0.0) + depth
        tri, dist, q, n_tri, bary = grid_closest(
            local,
            reach,
            tris[t0:t1],
            nrms[t0:t1],
            geo[20][t0:t1],
            grid_f[m, :3],
            grid_f[m, 3],
            grid_i[m],
            starts[cell_off[m] : cell_off[m + 1]],
            items[item_off[m] : item_off[m + 1]],
        )
        if tri < 0:
            continue
        d = local - q
        side = dot3(d, n_tri)
        if dist > 1e-12 and side > 0.0:
            n_local = d / dist
            sd = dist
        else:
            n_local = n_tri
            sd = -dist
        gap = sd - r - thick
        if gap <= margin:
            n = mv(rot[b], n_local)
            point = pts[i] - n * (r + 0.5 * gap)
            count = _push(buf, count, a, b, point, n, gap, ids[i], tri, bary)
    return count


@nb.njit(cache=True)
def pair_contacts(a, b, pos, rot, geo, margin, buf, count):
    """Append the contacts of bodies a and b (any order) within ``margin`` (m); returns count."""
    btype = geo[0]
    if btype[a] > btype[b]:
        a, b = b, a
    ta, tb = btype[a], btype[b]
    if ta >= PLANE:
        return count  # plane/mesh against plane/mesh: both environment
    if tb == PLANE:
        return _against_plane(a, b, pos, rot, geo, margin, buf, count)
    if tb == MESH:
        return _against_mesh(a, b, pos, rot, geo, margin, buf, count)
    if tb <= CAPSULE:
        return _segment_segment(a, b, pos, rot, geo, margin, buf, count)
    if ta <= CAPSULE:
        return _spheres_polytope(a, b, pos, rot, geo, margin, buf, count)
    count = _vertices_polytope(a, b, pos, rot, geo, margin, buf, count, False)
    return _vertices_polytope(b, a, pos, rot, geo, margin, buf, count, True)


@nb.njit(cache=True)
def sweep_and_prune(lo, hi, movable):
    """Pairs (i, j) whose boxes [lo, hi] overlap and of which at least one is movable.
    Sorted on x, swept; O(n log n + pairs)."""
    n = lo.shape[0]
    order = np.argsort(lo[:, 0])
    pairs = np.empty((max(16, 8 * n), 2), np.int64)
    count = 0
    active = np.empty(n, np.int64)
    n_active = 0
    for oi in range(n):
        i = order[oi]
        keep = 0
        for k in range(n_active):
            j = active[k]
            if hi[j, 0] >= lo[i, 0]:
                active[keep] = j
                keep += 1
                overlap_y = hi[j, 1] >= lo[i, 1] and hi[i, 1] >= lo[j, 1]
                overlap_z = hi[j, 2] >= lo[i, 2] and hi[i, 2] >= lo[j, 2]
                if (movable[i] or movable[j]) and overlap_y and overlap_z:
                    if count == pairs.shape[0]:
                        grown = np.empty((2 * count, 2), np.int64)
                        grown[:count] = pairs
                        pairs = grown
                    pairs[count, 0] = min(i, j)
                    pairs[count, 1] = max(i, j)
                    count += 1
        n_active = keep
        active[n_active] = i
        n_active += 1
    return pairs[:count]
