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
  contacts; edge-edge contacts are not generated), unless a face plane of one has the
  other's bounding sphere beyond it;
- anything vs plane: the sphere centres or vertices against the plane;
- anything vs triangle mesh: the same points against the mesh's triangle grid, keeping the
  side the triangle normals face; points up to the mesh's ``depth`` behind it penetrate.

``geo`` is the tuple of flat model arrays built by physics.rigid.world._build_arrays; the
contact buffers carry per-point hints (the mesh triangle each body point was last closest to).
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from physics.rigid.meshgrid import grid_closest, triangle_point, triangle_weights
from physics.rigid.shapes import CAPSULE, MESH, PLANE, SPHERE

# All kernels below use scalar arithmetic (3-vectors as float triples): no allocation per
# contact or per vertex.


@nb.njit(cache=True, inline="always")
def _push(buf, count, a, b, px, py, pz, nx, ny, nz, gap, fa, fb, u=0.0, v=0.0, w=0.0):
    """Append one contact to the buffers; returns the new count (drops when full)."""
    pts, nrm, gaps, pair, feat, bar, _ = buf
    if count >= gaps.size:
        return count
    pts[count, 0], pts[count, 1], pts[count, 2] = px, py, pz
    nrm[count, 0], nrm[count, 1], nrm[count, 2] = nx, ny, nz
    gaps[count] = gap
    pair[count, 0], pair[count, 1] = a, b
    feat[count, 0], feat[count, 1] = fa, fb
    bar[count, 0], bar[count, 1], bar[count, 2] = u, v, w
    return count + 1


@nb.njit(cache=True, inline="always")
def _push_point(buf, count, a, b, x, y, z, r, nx, ny, nz, gap, fa, fb, u=0.0, v=0.0, w=0.0):
    """Append the contact of a's point (x, y, z) of radius r (m) at the middle of the overlap,
    (x, y, z) - n (r + gap / 2)."""
    off = r + 0.5 * gap
    return _push(buf, count, a, b, x - nx * off, y - ny * off, z - nz * off, nx, ny, nz, gap, fa, fb, u, v, w)


@nb.njit(cache=True, inline="always")
def to_world(i, pos, rot, x, y, z):
    """World coordinates of the point (x, y, z) of body i's frame."""
    r = rot[i]
    return (
        pos[i, 0] + r[0, 0] * x + r[0, 1] * y + r[0, 2] * z,
        pos[i, 1] + r[1, 0] * x + r[1, 1] * y + r[1, 2] * z,
        pos[i, 2] + r[2, 0] * x + r[2, 1] * y + r[2, 2] * z,
    )


@nb.njit(cache=True, inline="always")
def to_local(i, pos, rot, x, y, z):
    """Body i's frame coordinates of the world point (x, y, z)."""
    r = rot[i]
    dx, dy, dz = x - pos[i, 0], y - pos[i, 1], z - pos[i, 2]
    return (
        r[0, 0] * dx + r[1, 0] * dy + r[2, 0] * dz,
        r[0, 1] * dx + r[1, 1] * dy + r[2, 1] * dz,
        r[0, 2] * dx + r[1, 2] * dy + r[2, 2] * dz,
    )


@nb.njit(cache=True, inline="always")
def _rotate(i, rot, x, y, z):
    """The body-frame direction (x, y, z) of body i in world coordinates."""
    r = rot[i]
    return (
        r[0, 0] * x + r[0, 1] * y + r[0, 2] * z,
        r[1, 0] * x + r[1, 1] * y + r[1, 2] * z,
        r[2, 0] * x + r[2, 1] * y + r[2, 2] * z,
    )


@nb.njit(cache=True, inline="always")
def point_count(a, geo):
    """How many points stand for body a against planes and meshes (world._point_count: 1 for
    a sphere, 3 for a capsule, the vertices of a polytope), from the point offsets geo[21]."""
    return geo[21][a + 1] - geo[21][a]


@nb.njit(cache=True, inline="always")
def body_point(a, i, pos, rot, geo):
    """World position of point i of body a (see point_count) and its radius (m)."""
    btype, param = geo[0], geo[2]
    if btype[a] == SPHERE:
        return pos[a, 0], pos[a, 1], pos[a, 2], param[a, 0]
    if btype[a] == CAPSULE:
        x, y, z = to_world(a, pos, rot, 0.0, 0.0, (i - 1) * param[a, 1])
        return x, y, z, param[a, 0]
    vert = geo[5][geo[4][a] + i]
    x, y, z = to_world(a, pos, rot, vert[0], vert[1], vert[2])
    return x, y, z, 0.0


@nb.njit(cache=True)
def segment_params(p1, q1, p2, q2):
    """Parameters (s, t) in [0, 1] of the closest points p1 + s (q1 - p1) and p2 + t (q2 - p2)
    of two segments given as float triples (Ericson 5.1.9)."""
    d1 = (q1[0] - p1[0], q1[1] - p1[1], q1[2] - p1[2])
    d2 = (q2[0] - p2[0], q2[1] - p2[1], q2[2] - p2[2])
    r = (p1[0] - p2[0], p1[1] - p2[1], p1[2] - p2[2])
    a = d1[0] * d1[0] + d1[1] * d1[1] + d1[2] * d1[2]
    e = d2[0] * d2[0] + d2[1] * d2[1] + d2[2] * d2[2]
    f = d2[0] * r[0] + d2[1] * r[1] + d2[2] * r[2]
    eps = 1e-24
    if a <= eps and e <= eps:
        return 0.0, 0.0
    if a <= eps:
        return 0.0, min(max(f / e, 0.0), 1.0)
    c = d1[0] * r[0] + d1[1] * r[1] + d1[2] * r[2]
    if e <= eps:
        return min(max(-c / a, 0.0), 1.0), 0.0
    b = d1[0] * d2[0] + d1[1] * d2[1] + d1[2] * d2[2]
    denom = a * e - b * b
    s = min(max((b * f - c * e) / denom, 0.0), 1.0) if denom > eps else 0.0
    t = (b * s + f) / e
    if t < 0.0:
        return min(max(-c / a, 0.0), 1.0), 0.0
    if t > 1.0:
        return min(max((b - c) / a, 0.0), 1.0), 1.0
    return s, t


@nb.njit(cache=True)
def _axis_ends(a, pos, rot, geo):
    """World end points of a sphere (a degenerate segment) or a capsule axis."""
    if geo[0][a] == SPHERE:
        p = (pos[a, 0], pos[a, 1], pos[a, 2])
        return p, p
    half = geo[2][a, 1]
    return to_world(a, pos, rot, 0.0, 0.0, -half), to_world(a, pos, rot, 0.0, 0.0, half)


@nb.njit(cache=True)
def _segment_segment(a, b, pos, rot, geo, margin, buf, count):
    param = geo[2]
    pa, qa = _axis_ends(a, pos, rot, geo)
    pb, qb = _axis_ends(b, pos, rot, geo)
    s, t = segment_params(pa, qa, pb, qb)
    cax, cay, caz = pa[0] + s * (qa[0] - pa[0]), pa[1] + s * (qa[1] - pa[1]), pa[2] + s * (qa[2] - pa[2])
    cbx, cby, cbz = pb[0] + t * (qb[0] - pb[0]), pb[1] + t * (qb[1] - pb[1]), pb[2] + t * (qb[2] - pb[2])
    dx, dy, dz = cax - cbx, cay - cby, caz - cbz
    dist = math.sqrt(dx * dx + dy * dy + dz * dz)
    gap = dist - param[a, 0] - param[b, 0]
    if gap > margin:
        return count
    if dist > 1e-12:
        nx, ny, nz = dx / dist, dy / dist, dz / dist
    else:
        nx, ny, nz = 0.0, 0.0, 1.0
    off = param[b, 0] + 0.5 * gap
    return _push(buf, count, a, b, cbx + nx * off, cby + ny * off, cbz + nz * off, nx, ny, nz, gap, -1, -1)


@nb.njit(cache=True, inline="always")
def _deepest_plane(lx, ly, lz, b, geo):
    """(largest signed distance of the body-frame point (lx, ly, lz) over polytope b's face
    planes, index of that plane): negative inside, an under-estimate of the distance outside."""
    pstart, planes = geo[6], geo[7]
    best = -math.inf
    face = -1
    for j in range(pstart[b], pstart[b + 1]):
        sd = planes[j, 0] * lx + planes[j, 1] * ly + planes[j, 2] * lz - planes[j, 3]
        if sd > best:
            best = sd
            face = j
    return best, face


@nb.njit(cache=True)
def _polytope_distance(x, y, z, b, pos, rot, geo):
    """Signed distance from the world point (x, y, z) to polytope b, the outward world normal
    at the closest point, and the index of the face plane or hull triangle reached."""
    pstart, planes, hstart, htris = geo[6], geo[7], geo[8], geo[9]
    lx, ly, lz = to_local(b, pos, rot, x, y, z)
    best, face = _deepest_plane(lx, ly, lz, b, geo)
    if best <= 0.0:
        nx, ny, nz = _rotate(b, rot, planes[face, 0], planes[face, 1], planes[face, 2])
        return best, nx, ny, nz, face - pstart[b]
    best_d2 = math.inf
    tri = -1
    qx = qy = qz = 0.0
    for t in range(hstart[b], hstart[b + 1]):
        u, v, w = triangle_weights(lx, ly, lz, htris, t)
        px, py, pz = triangle_point(htris, t, u, v, w)
        d2 = (lx - px) ** 2 + (ly - py) ** 2 + (lz - pz) ** 2
        if d2 < best_d2:
            best_d2, tri = d2, t
            qx, qy, qz = px, py, pz
    dist = math.sqrt(best_d2)
    if dist > 1e-12:
        nx, ny, nz = _rotate(b, rot, (lx - qx) / dist, (ly - qy) / dist, (lz - qz) / dist)
    else:
        nx, ny, nz = _rotate(b, rot, planes[face, 0], planes[face, 1], planes[face, 2])
    return dist, nx, ny, nz, tri - hstart[b]


@nb.njit(cache=True)
def _spheres_polytope(a, b, pos, rot, geo, margin, buf, count):
    for i in range(point_count(a, geo)):
        x, y, z, r = body_point(a, i, pos, rot, geo)
        lx, ly, lz = to_local(b, pos, rot, x, y, z)
        if _deepest_plane(lx, ly, lz, b, geo)[0] > r + margin:
            continue  # a face plane separates: the distance is larger still
        sd, nx, ny, nz, feature = _polytope_distance(x, y, z, b, pos, rot, geo)
        gap = sd - r
        if gap <= margin:
            count = _push_point(buf, count, a, b, x, y, z, r, nx, ny, nz, gap, -1, feature)
    return count


@nb.njit(cache=True)
def _plane_separates(a, b, pos, rot, geo, margin):
    """Whether one of polytope b's face planes has all of a's bounding sphere more than
    ``margin`` beyond it (then the two are further apart than margin: no contact)."""
    lx, ly, lz = to_local(b, pos, rot, pos[a, 0], pos[a, 1], pos[a, 2])
    return _deepest_plane(lx, ly, lz, b, geo)[0] > geo[3][a] + margin


@nb.njit(cache=True)
def _vertices_polytope(a, b, pos, rot, geo, margin, buf, count, flip):
    """Vertices of polytope a against polytope b (normal from b to a; reversed if flip)."""
    vstart, verts = geo[4], geo[5]
    pstart, planes = geo[6], geo[7]
    for v in range(vstart[a], vstart[a + 1]):
        x, y, z = to_world(a, pos, rot, verts[v, 0], verts[v, 1], verts[v, 2])
        lx, ly, lz = to_local(b, pos, rot, x, y, z)
        best, face = _deepest_plane(lx, ly, lz, b, geo)
        if best <= margin:
            nx, ny, nz = _rotate(b, rot, planes[face, 0], planes[face, 1], planes[face, 2])
            px, py, pz = x - 0.5 * best * nx, y - 0.5 * best * ny, z - 0.5 * best * nz
            fa, fb = v - vstart[a], face - pstart[b]
            if flip:
                count = _push(buf, count, b, a, px, py, pz, -nx, -ny, -nz, best, fb, fa)
            else:
                count = _push(buf, count, a, b, px, py, pz, nx, ny, nz, best, fa, fb)
    return count


@nb.njit(cache=True, inline="always")
def _point_id(a, i, geo):
    """Feature index of point i of body a: the vertex of a polytope, -1 for sphere centres."""
    return i if geo[0][a] > CAPSULE else -1


@nb.njit(cache=True)
def _against_plane(a, b, pos, rot, geo, margin, buf, count):
    param = geo[2]
    nx, ny, nz = _rotate(b, rot, param[b, 0], param[b, 1], param[b, 2])
    d = param[b, 3] + nx * pos[b, 0] + ny * pos[b, 1] + nz * pos[b, 2]
    for i in range(point_count(a, geo)):
        x, y, z, r = body_point(a, i, pos, rot, geo)
        gap = nx * x + ny * y + nz * z - d - r
        if gap <= margin:
            count = _push_point(buf, count, a, b, x, y, z, r, nx, ny, nz, gap, _point_id(a, i, geo), -1)
    return count


@nb.njit(cache=True)
def _against_mesh(a, b, pos, rot, geo, margin, buf, count):
    mesh_id, tri_off, tris, nrms, grid_f, grid_i, cell_off, starts, item_off, items = geo[10:20]
    m = mesh_id[b]
    thick, depth = geo[2][b, 0], geo[2][b, 1]
    t0, t1 = tri_off[m], tri_off[m + 1]
    mesh_tris, mesh_nrms, mesh_spheres = tris[t0:t1], nrms[t0:t1], geo[20][t0:t1]
    origin, cell, dims = grid_f[m, :3], grid_f[m, 3], grid_i[m]
    cell_starts, cell_items = starts[cell_off[m] : cell_off[m + 1]], items[item_off[m] : item_off[m + 1]]
    hint = buf[6]
    for i in range(point_count(a, geo)):
        x, y, z, r = body_point(a, i, pos, rot, geo)
        lx, ly, lz = to_local(b, pos, rot, x, y, z)
        reach = r + thick + max(margin, 0.0) + depth
        # the triangle this point was closest to last time bounds the distance: search only
        # that far (the result is the same; resting points search a cell or two)
        point = geo[21][a] + i
        near = hint[point] if hint[point] < t1 - t0 else 0
        hu, hv, hw = triangle_weights(lx, ly, lz, mesh_tris, near)
        qx, qy, qz = triangle_point(mesh_tris, near, hu, hv, hw)
        bound = math.sqrt((lx - qx) ** 2 + (ly - qy) ** 2 + (lz - qz) ** 2) * (1.0 + 1e-9) + 1e-12
        tri, d2, u, v, w = grid_closest(
            lx,
            ly,
            lz,
            min(reach, bound),
            mesh_tris,
            mesh_spheres,
            origin,
            cell,
            dims,
            cell_starts,
            cell_items,
        )
        if tri < 0:
            continue
        hint[point] = tri
        qx, qy, qz = triangle_point(mesh_tris, tri, u, v, w)
        dx, dy, dz = lx - qx, ly - qy, lz - qz
        dist = math.sqrt(d2)
        tnx, tny, tnz = mesh_nrms[tri, 0], mesh_nrms[tri, 1], mesh_nrms[tri, 2]
        if dist > 1e-12 and dx * tnx + dy * tny + dz * tnz > 0.0:
            sd = dist
            nx, ny, nz = _rotate(b, rot, dx / dist, dy / dist, dz / dist)
        else:
            if dist > r + thick + depth:
                continue  # further behind the surface than depth: it has passed (any margin)
            sd = -dist
            nx, ny, nz = _rotate(b, rot, tnx, tny, tnz)
        gap = sd - r - thick
        if gap <= margin:
            count = _push_point(
                buf, count, a, b, x, y, z, r, nx, ny, nz, gap, _point_id(a, i, geo), tri, u, v, w
            )
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
    if _plane_separates(a, b, pos, rot, geo, margin) or _plane_separates(b, a, pos, rot, geo, margin):
        return count
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
