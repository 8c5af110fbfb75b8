"""Narrow phase: contact points between two posed shapes.

Every contact is (point, normal, gap, feature of a, feature of b, barycentric weights on b)
with the normal pointing from b to a (pushing a along +n) and gap < 0 meaning penetration.
Pairs are ordered so that type(a) <= type(b) (sphere < capsule < box < convex < plane <
mesh < compound). Methods:

- sphere/capsule vs sphere/capsule: closest points of two segments (Ericson 5.1.9);
- sphere vs polytope (box, convex): inside by the face planes (deepest face), outside by the
  closest point on the hull triangles; a capsule is tested as its two end spheres and its
  middle sphere;
- polytope vs polytope: separating axes over both bodies' face normals and the cross
  products of their edges (Gottschalk, Lin, Manocha, "OBBTree", SIGGRAPH 1996; Ericson
  5.2.1), the edge pairs pruned on the Gauss map (Gregorius, GDC 2013: only pairs forming a
  face of the Minkowski difference) and tested only when no face axis separates the two by
  more than the margin; no contact if one separates them by more than the margin. If an edge axis
  beats every face axis (by EDGE_PREFERENCE), one contact between the two nearest edges with
  that axis's separation as gap (the true distance of two edges passing each other);
  otherwise each body against the other's reference face (the face plane that the other's
  vertices reach least deep behind): its vertices over that face, and the points where its
  hull edges cross the face's side planes (a face-face manifold: a cube on a cube turned or
  aligned gets the corners of the overlap);
- compound (concave) bodies: each of their convex pieces as a polytope (against another
  compound, piece by piece), against planes and meshes their surface vertices;
- anything vs plane: the sphere centres or vertices against the plane;
- anything vs triangle mesh: the same points against the mesh's triangle grid, keeping the
  side the triangle normals face; points up to the mesh's ``depth`` behind it penetrate.

``model`` is the world's :class:`physics.rigid.model.Geometry`; the method of each pair of shape
types comes from one table (PAIR_METHOD); the contact buffers (:class:`Contacts`) carry
what each body point last met of a mesh (_mesh_closest).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba as nb
import numpy as np

from jassy import unlinked
from jassy.jit import drop_stale_cache
from jassy.unlinked import Entry, call_apart, entries_of, unset
from physics.rigid import meshgrid, record_ref, shapes
from physics.rigid.meshgrid import (
    GridView,
    grid_closest,
    grid_within,
    triangle_distance2,
    triangle_point,
    triangle_weights,
)
from physics.rigid.record_ref import RefExample, deref, ref
from physics.rigid.shapes import CAPSULE, COMPOUND, MESH, PLANE, SPHERE

# its cache holds copies of their kernels and constants
drop_stale_cache(__file__, [meshgrid, record_ref, shapes, unlinked])

NO_BARY = (0.0, 0.0, 0.0)  # barycentric weights of a contact not on a mesh triangle
PIECE = 100000  # features of a compound's k-th convex piece are offset by PIECE * k
EDGE = 2000  # feature of an edge-edge contact: EDGE + the edge's row among its polytope's edges
EDGE_PREFERENCE = 1e-5  # m: an edge axis must beat every face axis by this to give the contact

# All kernels below use scalar arithmetic (3-vectors as float triples): no allocation per
# contact or per vertex.


class Contacts(NamedTuple):
    """Contact buffers (C rows) filled by the narrow phase, and the memory of the body points
    near meshes (_mesh_closest)."""

    points: np.ndarray  # (C, 3) world contact points, m
    normals: np.ndarray  # (C, 3) unit normals from b to a
    gaps: np.ndarray  # (C,) m, < 0 when penetrating
    pairs: np.ndarray  # (C, 2) bodies a, b
    features: np.ndarray  # (C, 2) feature of a, feature of b (vertex, face, edge row; -1 none)
    bary: np.ndarray  # (C, 3) barycentric weights on b's mesh triangle
    near: MeshMemory


def new_contacts(size: int, near: MeshMemory) -> Contacts:
    """Contact buffers of ``size`` rows sharing the mesh memory ``near`` (new_mesh_memory)."""
    return Contacts(
        np.empty((size, 3)),
        np.empty((size, 3)),
        np.empty(size),
        np.empty((size, 2), np.int64),
        np.empty((size, 2), np.int64),
        np.empty((size, 3)),
        near,
    )


@nb.njit(cache=True, inline="always")
def _push(buf, count, pair, point, normal, gap, features, bary):
    """Append one contact to the buffers: bodies (a, b), world point (x, y, z), unit normal from
    b to a, gap (m), features (of a, of b), barycentric weights on b; returns the new count
    (drops when full)."""
    a, b = pair
    px, py, pz = point
    nx, ny, nz = normal
    fa, fb = features
    u, v, w = bary
    pts, nrm, gaps, pair, feat, bar = buf.points, buf.normals, buf.gaps, buf.pairs, buf.features, buf.bary
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
def _push_point(buf, count, pair, point, r, normal, gap, features, bary):
    """Append the contact of a's point (x, y, z) of radius r (m) at the middle of the overlap,
    (x, y, z) - n (r + gap / 2) (the other arguments as _push's)."""
    off = r + 0.5 * gap
    x, y, z = point
    nx, ny, nz = normal
    return _push(buf, count, pair, (x - nx * off, y - ny * off, z - nz * off), normal, gap, features, bary)


@nb.njit(cache=True, inline="always")
def to_world(i, pos, rot, x, y, z):
    """World coordinates of the point (x, y, z) of body i's frame."""
    return (
        pos[i, 0] + rot[i, 0, 0] * x + rot[i, 0, 1] * y + rot[i, 0, 2] * z,
        pos[i, 1] + rot[i, 1, 0] * x + rot[i, 1, 1] * y + rot[i, 1, 2] * z,
        pos[i, 2] + rot[i, 2, 0] * x + rot[i, 2, 1] * y + rot[i, 2, 2] * z,
    )


@nb.njit(cache=True, inline="always")
def to_local(i, pos, rot, x, y, z):
    """Body i's frame coordinates of the world point (x, y, z)."""
    dx, dy, dz = x - pos[i, 0], y - pos[i, 1], z - pos[i, 2]
    return (
        rot[i, 0, 0] * dx + rot[i, 1, 0] * dy + rot[i, 2, 0] * dz,
        rot[i, 0, 1] * dx + rot[i, 1, 1] * dy + rot[i, 2, 1] * dz,
        rot[i, 0, 2] * dx + rot[i, 1, 2] * dy + rot[i, 2, 2] * dz,
    )


@nb.njit(cache=True, inline="always")
def _rotate(i, rot, x, y, z):
    """The body-frame direction (x, y, z) of body i in world coordinates."""
    return (
        rot[i, 0, 0] * x + rot[i, 0, 1] * y + rot[i, 0, 2] * z,
        rot[i, 1, 0] * x + rot[i, 1, 1] * y + rot[i, 1, 2] * z,
        rot[i, 2, 0] * x + rot[i, 2, 1] * y + rot[i, 2, 2] * z,
    )


@nb.njit(cache=True, inline="always")
def body_point(k, a, pos, rot, points):
    """World position and radius (m) of body a's point k: row k of the point table
    (Model.points: body-frame position and radius; body a's points are rows
    Model.point_start[a] to point_start[a + 1]: a sphere's centre, a capsule's axis ends and
    middle, a polytope's vertices)."""
    x, y, z = to_world(a, pos, rot, points[k, 0], points[k, 1], points[k, 2])
    return x, y, z, points[k, 3]


@nb.njit(cache=True, inline="always")
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


@nb.njit(cache=True, inline="always")
def _axis_ends(a, pos, rot, model):
    """World end points of a sphere (a degenerate segment) or a capsule axis."""
    if model.shape_type[a] == SPHERE:
        p = (pos[a, 0], pos[a, 1], pos[a, 2])
        return p, p
    half = model.param[a, 1]
    return to_world(a, pos, rot, 0.0, 0.0, -half), to_world(a, pos, rot, 0.0, 0.0, half)


@nb.njit(cache=True, inline="always")
def _segment_segment(a, b, pos, rot, model, margin, buf, count):
    param = model.param
    pa, qa = _axis_ends(a, pos, rot, model)
    pb, qb = _axis_ends(b, pos, rot, model)
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
    point = (cbx + nx * off, cby + ny * off, cbz + nz * off)
    return _push(buf, count, (a, b), point, (nx, ny, nz), gap, (-1, -1), NO_BARY)


@nb.njit(cache=True, inline="always")
def _deepest_plane(lx, ly, lz, b, pstart, planes):
    """(largest signed distance of the body-frame point (lx, ly, lz) over polytope b's face
    planes (Model.plane_start, planes), index of that plane): negative inside, an under-estimate of the
    distance outside."""
    best = -math.inf
    face = -1
    for j in range(pstart[b], pstart[b + 1]):
        sd = planes[j, 0] * lx + planes[j, 1] * ly + planes[j, 2] * lz - planes[j, 3]
        if sd > best:
            best = sd
            face = j
    return best, face


@nb.njit(cache=True, inline="always")
def _polytope_distance(x, y, z, b, sb, pos, rot, model):
    """Signed distance from the world point (x, y, z) to polytope b (geometry slot sb), the
    outward world normal at the closest point, and the index of the face plane or hull
    triangle reached."""
    pstart, planes, hstart, htris = model.plane_start, model.planes, model.hull_start, model.hull_tris
    lx, ly, lz = to_local(b, pos, rot, x, y, z)
    best, face = _deepest_plane(lx, ly, lz, sb, pstart, planes)
    if best <= 0.0:
        nx, ny, nz = _rotate(b, rot, planes[face, 0], planes[face, 1], planes[face, 2])
        return best, nx, ny, nz, face - pstart[sb]
    best_d2 = math.inf
    tri = -1
    qx = qy = qz = 0.0
    for t in range(hstart[sb], hstart[sb + 1]):
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
    return dist, nx, ny, nz, tri - hstart[sb]


@nb.njit(cache=True, _nrt=False)
def _spheres_polytope(a, b, sb, piece, pos, rot, gr, margin, br, count):
    """Contacts of sphere or capsule a with polytope b's geometry slot sb (its piece number
    ``piece``: features are offset by PIECE times it). Called apart (NarrowEntries), the
    Geometry and the Contacts by reference (``gr``, ``br``)."""
    model, buf = deref(gr), deref(br)
    pstart, planes, offsets, points = model.plane_start, model.planes, model.point_start, model.points
    for k in range(offsets[a], offsets[a + 1]):
        x, y, z, r = body_point(k, a, pos, rot, points)
        lx, ly, lz = to_local(b, pos, rot, x, y, z)
        if _deepest_plane(lx, ly, lz, sb, pstart, planes)[0] > r + margin:
            continue  # a face plane separates: the distance is larger still
        sd, nx, ny, nz, feature = _polytope_distance(x, y, z, b, sb, pos, rot, model)
        gap = sd - r
        if gap <= margin:
            features = (-1, feature + PIECE * piece)
            count = _push_point(buf, count, (a, b), (x, y, z), r, (nx, ny, nz), gap, features, NO_BARY)
    return count


@nb.njit(cache=True, inline="always")
def _plane_separates(a, b, sb, pos, rot, model, margin):
    """Whether one of the face planes of polytope b's geometry slot sb has all of a's bounding
    sphere more than ``margin`` beyond it (then the two are further apart than margin)."""
    lx, ly, lz = to_local(b, pos, rot, pos[a, 0], pos[a, 1], pos[a, 2])
    return _deepest_plane(lx, ly, lz, sb, model.plane_start, model.planes)[0] > model.bound[a] + margin


@nb.njit(cache=True, inline="always")
def _reference_face(a, sa, b, sb, pos, rot, model):
    """Polytope b's face plane that polytope a's vertices reach least deep behind (separating
    axes over b's face normals; sa, sb: their geometry slots): (plane index, separation = the
    smallest signed distance of a's vertices beyond it, m; above 0 the plane separates the
    two)."""
    vstart, verts, pstart, planes = model.vert_start, model.verts, model.plane_start, model.planes
    best, face = -math.inf, pstart[sb]
    for j in range(pstart[sb], pstart[sb + 1]):
        # plane j in a's frame (one transform per plane, not per plane and vertex)
        wx, wy, wz = _rotate(b, rot, planes[j, 0], planes[j, 1], planes[j, 2])
        offset = (
            planes[j, 3]
            + wx * (pos[b, 0] - pos[a, 0])
            + wy * (pos[b, 1] - pos[a, 1])
            + wz * (pos[b, 2] - pos[a, 2])
        )
        nx, ny, nz = to_local(a, pos, rot, pos[a, 0] + wx, pos[a, 1] + wy, pos[a, 2] + wz)
        sep = math.inf
        for v in range(vstart[sa], vstart[sa + 1]):
            sep = min(sep, nx * verts[v, 0] + ny * verts[v, 1] + nz * verts[v, 2] - offset)
            if sep <= best:
                break  # this plane cannot beat the best one found
        if sep > best:
            best, face = sep, j
    return face, best


@nb.njit(cache=True, inline="always")
def _beyond_sides(lx, ly, lz, b, face, pstart, planes):
    """How far (m) the body-frame point is beyond the face planes of b other than ``face``."""
    out = -math.inf
    for k in range(pstart[b], pstart[b + 1]):
        if k != face:
            out = max(out, planes[k, 0] * lx + planes[k, 1] * ly + planes[k, 2] * lz - planes[k, 3])
    return out


@nb.njit(cache=True, inline="always")
def _push_face(buf, count, pair, point, sd, normal, features, flip):
    """Append a's point (x, y, z) lying ``sd`` (m) beyond b's face of world normal n: the
    contact at the middle of the overlap, normal from b to a (reversed if flip). pair: (a, b);
    features: (of a, of b)."""
    a, b = pair
    x, y, z = point
    nx, ny, nz = normal
    fa, fb = features
    px, py, pz = x - 0.5 * sd * nx, y - 0.5 * sd * ny, z - 0.5 * sd * nz
    if flip:
        return _push(buf, count, (b, a), (px, py, pz), (-nx, -ny, -nz), sd, (fb, fa), NO_BARY)
    return _push(buf, count, (a, b), (px, py, pz), (nx, ny, nz), sd, (fa, fb), NO_BARY)


@nb.njit(cache=True, _nrt=False)
def _polytope_on_face(slots, face, pieces, pos, rot, model, margin, buf, count, flip):
    """Contacts of polytope a (geometry slot sa) on polytope b's (slot sb) reference face
    (_reference_face; normal from b to a, reversed if flip): a's vertices within margin of the
    face plane and over the face (within margin of b's other face planes), and the points
    where a's hull edges cross b's other face planes while within margin of the face plane
    (the corners of the overlap of two faces, where no vertex of either lies over the other).
    slots: (a, sa, b, sb); pieces: the piece numbers of a and b (features offset by PIECE
    times them)."""
    a, sa, b, sb = slots
    vstart, verts, pstart, planes, hstart, htris = (
        model.vert_start,
        model.verts,
        model.plane_start,
        model.planes,
        model.hull_start,
        model.hull_tris,
    )
    fnx, fny, fnz, fd = planes[face, 0], planes[face, 1], planes[face, 2], planes[face, 3]
    nx, ny, nz = _rotate(b, rot, fnx, fny, fnz)
    fb = face - pstart[sb] + PIECE * pieces[1]
    for v in range(vstart[sa], vstart[sa + 1]):
        x, y, z = to_world(a, pos, rot, verts[v, 0], verts[v, 1], verts[v, 2])
        lx, ly, lz = to_local(b, pos, rot, x, y, z)
        sd = fnx * lx + fny * ly + fnz * lz - fd
        if sd <= margin and _beyond_sides(lx, ly, lz, sb, face, pstart, planes) <= margin:
            fa = v - vstart[sa] + PIECE * pieces[0]
            count = _push_face(buf, count, (a, b), (x, y, z), sd, (nx, ny, nz), (fa, fb), flip)
    for t in range(hstart[sa], hstart[sa + 1]):
        for e in range(3):
            f = (e + 1) % 3
            if (htris[t, e, 0], htris[t, e, 1], htris[t, e, 2]) >= (
                htris[t, f, 0],
                htris[t, f, 1],
                htris[t, f, 2],
            ):
                continue  # each edge once (its two triangles run it in opposite directions)
            x, y, z = to_world(a, pos, rot, htris[t, e, 0], htris[t, e, 1], htris[t, e, 2])
            px, py, pz = to_local(b, pos, rot, x, y, z)
            x, y, z = to_world(a, pos, rot, htris[t, f, 0], htris[t, f, 1], htris[t, f, 2])
            qx, qy, qz = to_local(b, pos, rot, x, y, z)
            lo, hi = 0.0, 1.0  # clip p + s (q - p) to b's side half-spaces and the face's margin
            for k in range(pstart[sb], pstart[sb + 1]):
                limit = margin if k == face else 0.0
                d1 = planes[k, 0] * px + planes[k, 1] * py + planes[k, 2] * pz - planes[k, 3] - limit
                d2 = planes[k, 0] * qx + planes[k, 1] * qy + planes[k, 2] * qz - planes[k, 3] - limit
                if d1 > 0.0 and d2 > 0.0:
                    lo, hi = 1.0, 0.0
                    break
                if d1 > 0.0:
                    lo = max(lo, d1 / (d1 - d2))
                elif d2 > 0.0:
                    hi = min(hi, d1 / (d1 - d2))
            for end, s in ((0, lo), (1, hi)):
                if lo > hi or s <= 1e-9 or s >= 1.0 - 1e-9:
                    continue  # nothing inside, or an end vertex (its contact is above)
                lx, ly, lz = px + s * (qx - px), py + s * (qy - py), pz + s * (qz - pz)
                sd = fnx * lx + fny * ly + fnz * lz - fd
                x, y, z = to_world(b, pos, rot, lx, ly, lz)
                fa = 1000 + 6 * (t - hstart[sa]) + 2 * e + end + PIECE * pieces[0]
                count = _push_face(buf, count, (a, b), (x, y, z), sd, (nx, ny, nz), (fa, fb), flip)
    return count


@nb.njit(cache=True, inline="always")
def _b_in_a(a, b, pos, rot, x, y, z):
    """a's frame coordinates of the point (x, y, z) of b's frame."""
    wx, wy, wz = to_world(b, pos, rot, x, y, z)
    return to_local(a, pos, rot, wx, wy, wz)


@nb.njit(cache=True, inline="always")
def _b_dir_in_a(a, b, rot, x, y, z):
    """a's frame components of the direction (x, y, z) of b's frame."""
    wx, wy, wz = _rotate(b, rot, x, y, z)
    return (
        rot[a, 0, 0] * wx + rot[a, 1, 0] * wy + rot[a, 2, 0] * wz,
        rot[a, 0, 1] * wx + rot[a, 1, 1] * wy + rot[a, 2, 1] * wz,
        rot[a, 0, 2] * wx + rot[a, 1, 2] * wy + rot[a, 2, 2] * wz,
    )


@nb.njit(cache=True, inline="always")
def _edge_separation(a, sa, b, sb, pos, rot, model):
    """The best separating axis among the cross products of an edge of polytope a and an
    edge of polytope b (geometry slots sa, sb): (separation, m: b's smallest projection minus
    a's largest, the distance of the two edges when they are the nearest features; world
    axis from b to a; the two edge rows in model.edges); -inf if no pair qualifies.

    Only edge pairs that form a face of the Minkowski difference A - B are tested: the arc
    between an edge's two face normals on the Gauss map of a crosses the arc between the
    negated face normals of b's edge (Gregorius, "The Separating Axis Test between Convex
    Polyhedra", GDC 2013). Any other edge axis separates less than some face axis, and a
    qualifying pair's edges are the support features along its axis, so its separation is
    the difference of the edges' projections (O(1) per pair, no vertex loop). Computed in
    a's frame."""
    estart, edges = model.edge_start, model.edges
    best, bnx, bny, bnz, best_a, best_b = -math.inf, 0.0, 0.0, 1.0, -1, -1
    for eb in range(estart[sb], estart[sb + 1]):
        # b's negated face normals c, d (A - B's Gauss map), a's frame
        cx, cy, cz = _b_dir_in_a(a, b, rot, -edges[eb, 6], -edges[eb, 7], -edges[eb, 8])
        dx, dy, dz = _b_dir_in_a(a, b, rot, -edges[eb, 9], -edges[eb, 10], -edges[eb, 11])
        dcx, dcy, dcz = dy * cz - dz * cy, dz * cx - dx * cz, dx * cy - dy * cx  # d x c
        posed = False  # b's edge in a's frame, computed once a pair qualifies
        px = py = pz = fx = fy = fz = f2 = 0.0
        for ea in range(estart[sa], estart[sa + 1]):
            # a2 x a1, stored with the hull: the arc test is two dot products before any other load
            cba = cx * edges[ea, 12] + cy * edges[ea, 13] + cz * edges[ea, 14]
            dba = dx * edges[ea, 12] + dy * edges[ea, 13] + dz * edges[ea, 14]
            if cba * dba >= 0.0:
                continue  # b's arc lies on one side of a's arc plane: they do not cross
            a1x, a1y, a1z = edges[ea, 6], edges[ea, 7], edges[ea, 8]
            a2x, a2y, a2z = edges[ea, 9], edges[ea, 10], edges[ea, 11]
            adc = a1x * dcx + a1y * dcy + a1z * dcz
            bdc = a2x * dcx + a2y * dcy + a2z * dcz
            if adc * bdc >= 0.0 or cba * bdc <= 0.0:
                continue  # the arcs do not cross: not a face of A - B
            if not posed:
                px, py, pz = _b_in_a(a, b, pos, rot, edges[eb, 0], edges[eb, 1], edges[eb, 2])
                qx, qy, qz = _b_in_a(a, b, pos, rot, edges[eb, 3], edges[eb, 4], edges[eb, 5])
                fx, fy, fz = qx - px, qy - py, qz - pz
                f2 = fx * fx + fy * fy + fz * fz
                posed = True
            ex, ey, ez = edges[ea, 15], edges[ea, 16], edges[ea, 17]
            nx, ny, nz = ey * fz - ez * fy, ez * fx - ex * fz, ex * fy - ey * fx
            length = math.sqrt(nx * nx + ny * ny + nz * nz)
            if length < 1e-6 * math.sqrt((ex * ex + ey * ey + ez * ez) * f2):
                continue  # parallel edges: a face axis covers them
            if nx * (a1x + a2x) + ny * (a1y + a2y) + nz * (a1z + a2z) < 0.0:
                length = -length  # outward from a
            nx, ny, nz = nx / length, ny / length, nz / length
            sep = nx * (px - edges[ea, 0]) + ny * (py - edges[ea, 1]) + nz * (pz - edges[ea, 2])
            if sep > best:
                best, bnx, bny, bnz, best_a, best_b = sep, nx, ny, nz, ea, eb
    wx, wy, wz = _rotate(a, rot, bnx, bny, bnz)
    return best, -wx, -wy, -wz, best_a, best_b


@nb.njit(cache=True, inline="always")
def _edge_contact(slots, axis, rows, pieces, pos, rot, model, buf, count):
    """One contact where a's edge row ea and b's edge row eb (_edge_separation, facing each
    other across the axis n from b to a) come closest: the middle of their closest points, gap
    ``sep``, features EDGE + the edge rows (offset by PIECE times the piece numbers).
    slots: (a, sa, b, sb); axis: (sep, world axis n); rows: (ea, eb)."""
    a, sa, b, sb = slots
    sep, nx, ny, nz = axis
    ea, eb = rows
    estart, edges = model.edge_start, model.edges
    pa = to_world(a, pos, rot, edges[ea, 0], edges[ea, 1], edges[ea, 2])
    qa = to_world(a, pos, rot, edges[ea, 3], edges[ea, 4], edges[ea, 5])
    pb = to_world(b, pos, rot, edges[eb, 0], edges[eb, 1], edges[eb, 2])
    qb = to_world(b, pos, rot, edges[eb, 3], edges[eb, 4], edges[eb, 5])
    s, t = segment_params(pa, qa, pb, qb)
    px = 0.5 * (pa[0] + s * (qa[0] - pa[0]) + pb[0] + t * (qb[0] - pb[0]))
    py = 0.5 * (pa[1] + s * (qa[1] - pa[1]) + pb[1] + t * (qb[1] - pb[1]))
    pz = 0.5 * (pa[2] + s * (qa[2] - pa[2]) + pb[2] + t * (qb[2] - pb[2]))
    fa = EDGE + ea - estart[sa] + PIECE * pieces[0]
    fb = EDGE + eb - estart[sb] + PIECE * pieces[1]
    return _push(buf, count, (a, b), (px, py, pz), (nx, ny, nz), sep, (fa, fb), NO_BARY)


@nb.njit(cache=True, _nrt=False)
def _polytopes(slots, pieces, pos, rot, gr, margin, br, count):
    """Contacts of two polytopes (geometry slots sa, sb; piece numbers ``pieces``) by
    separating axes: the face normals of each (_reference_face) and the cross products of
    their edge directions (_edge_separation). No contact when an axis separates them by more
    than margin; one edge-edge contact when an edge axis separates (or overlaps) them by
    EDGE_PREFERENCE more than every face axis; else the face manifolds of each on the other.
    slots: (a, sa, b, sb). Called apart (NarrowEntries), the Geometry and the Contacts by
    reference (``gr``, ``br``)."""
    model, buf = deref(gr), deref(br)
    a, sa, b, sb = slots
    face_ab, sep_ab = _reference_face(a, sa, b, sb, pos, rot, model)
    if sep_ab > margin:
        return count  # separated by one of b's face planes: no need for a's
    face_ba, sep_ba = _reference_face(b, sb, a, sa, pos, rot, model)
    face_sep = max(sep_ab, sep_ba)
    if face_sep > margin:
        return count
    sep, nx, ny, nz, ea, eb = _edge_separation(a, sa, b, sb, pos, rot, model)
    if sep > margin:
        return count
    if sep > face_sep + EDGE_PREFERENCE:
        return _edge_contact(slots, (sep, nx, ny, nz), (ea, eb), pieces, pos, rot, model, buf, count)
    # flags and zeros as np types: a literal argument would compile a callee once per value
    count = _polytope_on_face(slots, face_ab, pieces, pos, rot, model, margin, buf, count, np.bool_(False))
    flipped = (pieces[1], pieces[0])
    return _polytope_on_face(
        (b, sb, a, sa), face_ba, flipped, pos, rot, model, margin, buf, count, np.bool_(True)
    )


@nb.njit(cache=True, inline="always")
def _against_plane(a, b, pos, rot, model, margin, buf, count):
    param, offsets, points = model.param, model.point_start, model.points
    nx, ny, nz = _rotate(b, rot, param[b, 0], param[b, 1], param[b, 2])
    d = param[b, 3] + nx * pos[b, 0] + ny * pos[b, 1] + nz * pos[b, 2]
    vertices = model.shape_type[a] > CAPSULE
    for k in range(offsets[a], offsets[a + 1]):
        x, y, z, r = body_point(k, a, pos, rot, points)
        gap = nx * x + ny * y + nz * z - d - r
        if gap <= margin:
            feature = k - offsets[a] if vertices else -1
            count = _push_point(buf, count, (a, b), (x, y, z), r, (nx, ny, nz), gap, (feature, -1), NO_BARY)
    return count


@nb.njit(cache=True, _nrt=False)
def _against_mesh(a, b, pos, rot, gr, margin, br, count):
    """Contacts of body a's points (sphere centres or vertices) with mesh b (module doc).
    Called apart (NarrowEntries), the Geometry and the Contacts by reference (``gr``, ``br``)."""
    model, buf = deref(gr), deref(br)
    tris, nrms, offsets, points = model.tris, model.tri_normals, model.point_start, model.points
    m = model.mesh_of[b]
    t0 = model.tri_start[m]
    thick, depth = model.param[b, 0], model.param[b, 1]
    vertices = model.shape_type[a] > CAPSULE
    for k in range(offsets[a], offsets[a + 1]):
        x, y, z, r = body_point(k, a, pos, rot, points)
        lx, ly, lz = to_local(b, pos, rot, x, y, z)
        reach = r + thick + max(margin, 0.0) + depth
        tri, d2, u, v, w = _mesh_closest(k, m, lx, ly, lz, reach, model, buf.near)
        if tri < 0:
            continue
        qx, qy, qz = triangle_point(tris, t0 + tri, u, v, w)
        dx, dy, dz = lx - qx, ly - qy, lz - qz
        dist = math.sqrt(d2)
        tnx, tny, tnz = nrms[t0 + tri, 0], nrms[t0 + tri, 1], nrms[t0 + tri, 2]
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
            feature = k - offsets[a] if vertices else -1
            count = _push_point(
                buf, count, (a, b), (x, y, z), r, (nx, ny, nz), gap, (feature, tri), (u, v, w)
            )
    return count


FAR = 1.5  # a point with nothing within reach of a mesh searches this many times as far
SKIN = 0.25  # a point's list of triangles holds those up to this many grid cells beyond its nearest
LISTED = 32  # at most this many triangles in a point's list (more: no list, the grid is searched)


class MeshMemory(NamedTuple):
    """What each body point (P rows) remembers of the meshes it was near (_mesh_closest)."""

    hint: np.ndarray  # (P,) the triangle it was nearest
    clear: np.ndarray  # (P, 5) where it was last searched (m), a lower bound of its distance
    #   to the mesh there (m), the mesh number + 1
    listed: np.ndarray  # (P, LISTED) its list of the triangles that can be nearest
    listed_dist: np.ndarray  # (P, LISTED) their distances when listed, m
    anchor: np.ndarray  # (P, 5) where the list was made (m), its length, the mesh number + 1


def new_mesh_memory(n_points: int) -> MeshMemory:
    """An empty MeshMemory of n_points body points."""
    return MeshMemory(
        np.zeros(n_points, np.int64),
        np.zeros((n_points, 5)),
        np.zeros((n_points, LISTED), np.int64),
        np.zeros((n_points, LISTED)),
        np.zeros((n_points, 5)),
    )


@nb.njit(cache=True, inline="always")
def _closest_listed(k, n, lx, ly, lz, t0, tris, spheres, listed):
    """Closest of the first n triangles of point k's list (mesh triangles from t0) to (lx, ly,
    lz): (triangle of the mesh, squared distance, barycentric weights)."""
    best = -1
    best_d2 = best_d = math.inf
    bu = bv = bw = 0.0
    for e in range(n):
        t = t0 + listed[k, e]
        d2, u, v, w = triangle_distance2(lx, ly, lz, tris, spheres, t, best_d)
        if d2 < best_d2:
            best_d2, best_d, best = d2, math.sqrt(d2), t - t0
            bu, bv, bw = u, v, w
    return best, best_d2, bu, bv, bw


@nb.njit(cache=True, _nrt=False)
def _mesh_closest(k, m, lx, ly, lz, reach, model, near):
    """Closest triangle of mesh m within ``reach`` (m) of body point k at (lx, ly, lz) in the
    mesh's frame: (triangle of the mesh or -1, squared distance, barycentric weights).

    ``near`` (new_mesh_memory) makes repeated queries of a point cheap; the mesh is rigid:

    - where the point was last searched, with a lower bound of its distance to the mesh there:
      a point that has since moved less than that bound minus reach has nothing within reach
      and is not searched. A point finding nothing within reach searches FAR times as far (or
      as far as the triangle it was last nearest), so that its bound lasts;
    - a point found within reach lists the triangles within its distance d0 + s (s = SKIN
      grid cells): while it stays within s / 2 of where the list was made, its nearest
      triangle is on the list (any other is further than d0 + s / 2 from it, its old nearest
      nearer), so only the list is searched (a Verlet list)."""
    hint, clear, listed, listed_dist, anchor = (
        near.hint,
        near.clear,
        near.listed,
        near.listed_dist,
        near.anchor,
    )
    tri_off, tris, grid_f, grid_i = model.tri_start, model.tris, model.grid_origin_cell, model.grid_dims
    cell_off, starts, item_off, items = (
        model.cell_start,
        model.cell_items_start,
        model.item_start,
        model.cell_items,
    )
    spheres = model.tri_spheres
    t0, n_tris = tri_off[m], tri_off[m + 1] - tri_off[m]
    if clear[k, 4] == m + 1:
        moved = math.sqrt((lx - clear[k, 0]) ** 2 + (ly - clear[k, 1]) ** 2 + (lz - clear[k, 2]) ** 2)
        if clear[k, 3] - moved > reach + 1e-12:
            return -1, 0.0, 0.0, 0.0, 0.0
    skin = SKIN * grid_f[m, 3]
    dx, dy, dz = lx - anchor[k, 0], ly - anchor[k, 1], lz - anchor[k, 2]
    if anchor[k, 4] == m + 1 and dx * dx + dy * dy + dz * dz < 0.25 * skin * skin:
        tri, d2, u, v, w = _closest_listed(k, int(anchor[k, 3]), lx, ly, lz, t0, tris, spheres, listed)
        radius = 0.0  # the lower bound if the list is empty (it is not: it holds the old nearest)
    else:
        origin = (grid_f[m, 0], grid_f[m, 1], grid_f[m, 2])
        dims = (grid_i[m, 0], grid_i[m, 1], grid_i[m, 2])
        offsets = (t0, cell_off[m], item_off[m])
        last = t0 + (hint[k] if hint[k] < n_tris else 0)
        hu, hv, hw = triangle_weights(lx, ly, lz, tris, last)
        qx, qy, qz = triangle_point(tris, last, hu, hv, hw)
        bound = math.sqrt((lx - qx) ** 2 + (ly - qy) ** 2 + (lz - qz) ** 2) * (1.0 + 1e-9) + 1e-12
        radius = min(FAR * reach, bound)
        grid = GridView(tris, spheres, origin, grid_f[m, 3], dims, starts, items, offsets)
        tri, d2, u, v, w = grid_closest(lx, ly, lz, radius, grid)
        anchor[k, 4] = 0.0
        if tri >= 0 and d2 < reach * reach:  # it will be asked again: list its candidates
            within = (math.sqrt(d2) + skin) * (1.0 + 1e-9)
            n = grid_within(lx, ly, lz, within, grid, listed, listed_dist, k)
            if n > 0:
                anchor[k, 0], anchor[k, 1], anchor[k, 2], anchor[k, 3], anchor[k, 4] = lx, ly, lz, n, m + 1
    clear[k, 0], clear[k, 1], clear[k, 2] = lx, ly, lz
    clear[k, 3] = math.sqrt(d2) if tri >= 0 else radius
    clear[k, 4] = m + 1
    if tri < 0 or d2 >= reach * reach:  # nothing within reach (the nearest is further)
        return -1, 0.0, 0.0, 0.0, 0.0
    hint[k] = tri
    return tri, d2, u, v, w


# Shape-pair methods, one per entry of PAIR_METHOD (the dispatch table of pair_contacts)
NO_CONTACT, SEGMENTS, SPHERES_POLYTOPE, POLYTOPES, POINTS_PLANE, POINTS_MESH, PIECES = range(7)


def _pair_methods() -> np.ndarray:
    """PAIR_METHOD[type a, type b] (shapes.SPHERE ... COMPOUND) for type a <= type b: sphere
    and capsule axes as segments; spheres against a polytope; two polytopes; a body's points
    against a plane or a mesh (a compound's surface points too); a compound's convex pieces
    against a sphere, capsule, polytope or compound; planes and meshes are both environment."""
    table = np.full((COMPOUND + 1, COMPOUND + 1), NO_CONTACT, np.int64)
    for ta in range(COMPOUND + 1):
        for tb in range(ta, COMPOUND + 1):
            if tb == COMPOUND:
                method = {PLANE: POINTS_PLANE, MESH: POINTS_MESH}.get(ta, PIECES)
            elif ta >= PLANE:
                method = NO_CONTACT
            elif tb >= PLANE:
                method = POINTS_PLANE if tb == PLANE else POINTS_MESH
            elif tb <= CAPSULE:
                method = SEGMENTS
            else:
                method = SPHERES_POLYTOPE if ta <= CAPSULE else POLYTOPES
            table[ta, tb] = method
    return table


PAIR_METHOD = _pair_methods()


class NarrowEntries(NamedTuple):
    """The narrow phase's kernels called apart (jassy.unlinked.call_apart), each compiled
    alone, not linked into another: their entry points (narrow_entries). Its callers pass
    the Geometry and the Contacts by reference (physics.rigid.record_ref)."""

    contacts: Entry  # pair_contacts
    polytopes: Entry  # _polytopes
    spheres_polytope: Entry  # _spheres_polytope
    against_mesh: Entry  # _against_mesh
    with_compound: Entry  # _with_compound


@nb.njit(cache=True, _nrt=False)
def pair_contacts(a, b, pos, rot, gr, margin, br, count, entries):
    """Append the contacts of bodies a and b (any order) within ``margin`` (m) to the Contacts
    ``br`` refers to; returns count. ``gr``: a reference to the Geometry; ``entries``: the
    NarrowEntries through which the larger methods are called apart (compiled alone, so no
    kernel optimises them again). The method comes from PAIR_METHOD. Compiled without
    reference counting (_nrt=False: it allocates nothing)."""
    model, buf = deref(gr), deref(br)
    btype = model.shape_type
    if btype[a] > btype[b]:
        a, b = b, a
    method = PAIR_METHOD[btype[a], btype[b]]
    if btype[a] >= PLANE:
        a, b = b, a  # a compound's surface points against a plane or mesh
    if method == POINTS_PLANE:
        return _against_plane(a, b, pos, rot, model, margin, buf, count)
    if method == POINTS_MESH:
        return call_apart(entries.against_mesh, (a, b, pos, rot, gr, margin, br, count), nb.int64)
    if method == SEGMENTS:
        return _segment_segment(a, b, pos, rot, model, margin, buf, count)
    if method == SPHERES_POLYTOPE:
        where = (a, b, b, np.int64(0), pos, rot, gr, margin, br, count)
        return call_apart(entries.spheres_polytope, where, nb.int64)
    if method == POLYTOPES:
        if _plane_separates(a, b, b, pos, rot, model, margin) or _plane_separates(
            b, a, a, pos, rot, model, margin
        ):
            return count
        whole = (np.int64(a), np.int64(a), np.int64(b), np.int64(b))
        where = (whole, (np.int64(0), np.int64(0)), pos, rot, gr, margin, br, count)
        return call_apart(entries.polytopes, where, nb.int64)
    if method == PIECES:
        where = (a, b, pos, rot, gr, margin, br, count, entries)
        return call_apart(entries.with_compound, where, nb.int64)
    return count  # NO_CONTACT


@nb.njit(cache=True, _nrt=False)
def pair_contacts_of(a, b, pos, rot, model, margin, buf, count, entries):
    """:func:`pair_contacts` for a caller holding the Geometry ``model`` and the Contacts
    ``buf`` themselves rather than references (tests, benchmarks); ``entries``:
    narrow_entries for these types."""
    where = (a, b, pos, rot, ref(model), margin, ref(buf), count, entries)
    return call_apart(entries.contacts, where, nb.int64)


@nb.njit(cache=True, _nrt=False)
def _with_compound(a, b, pos, rot, gr, margin, br, count, entries):
    """Contacts of body a (a sphere, capsule, polytope or compound) with compound b: with each
    convex piece of b (geometry slots Model.piece_slots[piece_start[b]:piece_start[b + 1]]),
    piece by piece for a compound a too; the pieces' methods called apart (``entries``)."""
    model = deref(gr)
    ta, first, slots = model.shape_type[a], model.piece_start, model.piece_slots
    for j in range(first[b], first[b + 1]):
        sb, pb = slots[j], j - first[b]
        if _plane_separates(a, b, sb, pos, rot, model, margin):
            continue  # a's bounding sphere is beyond this piece of b
        if ta <= CAPSULE:
            where = (a, b, sb, pb, pos, rot, gr, margin, br, count)
            count = call_apart(entries.spheres_polytope, where, nb.int64)
            continue
        for i in range(first[a], first[a + 1]):
            sa, pa = slots[i], i - first[a]
            where = ((a, sa, b, sb), (pa, pb), pos, rot, gr, margin, br, count)
            count = call_apart(entries.polytopes, where, nb.int64)
    return count


def narrow_calls(pos, rot, geo, buf) -> dict:
    """The narrow phase's kernels called apart, for poses ``pos``, ``rot`` (arrays of the
    types the caller passes), Geometry ``geo`` and Contacts ``buf``: NarrowEntries' field ->
    (kernel, example arguments of the types they are called with)."""
    whole, dt = np.int64(0), 0.0
    gr, br, entries = RefExample(geo), RefExample(buf), unset(NarrowEntries)
    posed = (pos, rot, gr, dt, br, whole)
    return {
        "contacts": (pair_contacts, (whole, whole, *posed, entries)),
        "polytopes": (_polytopes, ((whole,) * 4, (whole, whole), *posed)),
        "spheres_polytope": (_spheres_polytope, (whole, whole, whole, whole, *posed)),
        "against_mesh": (_against_mesh, (whole, whole, *posed)),
        "with_compound": (_with_compound, (whole, whole, *posed, entries)),
    }


def narrow_entries(pos, rot, geo, buf) -> NarrowEntries:
    """The NarrowEntries for calls with arguments of the types of ``pos``, ``rot``, ``geo``,
    ``buf`` (narrow_calls), each kernel compiled (or loaded from numba's cache) on first use."""
    return entries_of(NarrowEntries, narrow_calls(pos, rot, geo, buf))
