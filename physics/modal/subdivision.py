"""Sound texture maps on subdivision surfaces (FoleyAutomatic; van den Doel, Kry & Pai 2001).

Modal gains live on the control vertices of a triangle mesh and are interpolated
barycentrically inside each triangle (what ``ModalModel.gains_at`` does with a
``{vertices, weights}`` location, and JASS's ``setLocation(p1, p2, p3, b1, b2, b3)``).

* :func:`loop_subdivide` refines a mesh by Loop subdivision (trimesh's implementation), so
  gains can be sampled on a finer, smoother set of control vertices: near a nodal line a
  mode's gain (n . phi)^2 varies fast, and linear interpolation between coarse vertices
  would blur it.
* :func:`subdivide_values` refines per-vertex values (e.g. gains measured or fitted at the
  vertices of a coarse mesh) with the same Loop stencils as the geometry: subdivision is
  linear in the vertex data, so trimesh's own routine is applied to the values three columns
  at a time, which keeps values and refined vertices exactly consistent.
* :class:`SurfaceMap` finds the closest surface point to a 3D position and returns it as a
  patch location (three vertices and barycentric weights), or interpolates values there.
"""

from __future__ import annotations

import numpy as np

from jassy.errors import JassyError


def loop_subdivide(mesh, iterations: int = 1):
    """(refined mesh, per-iteration vertex counts): ``iterations`` Loop subdivisions.

    Each iteration splits every triangle into four; old vertices come first in the refined
    vertex list (so coarse vertex i is refined vertex i, moved by the even-vertex stencil).
    """
    import trimesh
    from trimesh.remesh import subdivide_loop

    if iterations < 0:
        raise JassyError(f"--subdivide: expected an integer >= 0, got {iterations}")
    vertices, faces = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    counts = [len(vertices)]
    for _ in range(iterations):
        vertices, faces = subdivide_loop(vertices, faces, iterations=1)
        counts.append(len(vertices))
    return trimesh.Trimesh(vertices=vertices, faces=faces, process=False), counts


def subdivide_values(mesh, values, iterations: int = 1) -> np.ndarray:
    """Per-vertex ``values`` (n_vertices, m) refined with the Loop stencils of ``mesh``.

    Row i of the result belongs to vertex i of ``loop_subdivide(mesh, iterations)[0]``.
    """
    from trimesh.remesh import subdivide_loop

    vals = np.asarray(values, dtype=np.float64)
    one_d = vals.ndim == 1
    vals = vals.reshape(len(mesh.vertices), -1)
    faces = np.asarray(mesh.faces)
    m = vals.shape[1]
    pad = (-m) % 3
    padded = np.hstack([vals, np.zeros((vals.shape[0], pad))])
    out = []
    for c in range(0, padded.shape[1], 3):
        v, f = padded[:, c : c + 3], faces
        for _ in range(iterations):
            v, f = subdivide_loop(v, f, iterations=1)
        out.append(v)
    res = np.hstack(out)[:, :m]
    return res[:, 0] if one_d else res


def closest_points(mesh, points) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(closest points (n, 3), triangle ids (n,), barycentric weights (n, 3)) on the mesh.

    Exact without an R-tree: the exact distance u to the triangles of the few nearest
    centroids bounds the answer, and a triangle of radius r (largest centroid-to-vertex
    distance) can be closer only if its centroid lies within u + r. Triangles are grouped
    by radius (each group within a factor 2), one k-d tree per group, so a few large
    triangles (the fan of a bowl's base) do not widen every point's search to the whole mesh.
    """
    from scipy.spatial import cKDTree
    from trimesh.triangles import closest_point, points_to_barycentric

    tris = np.asarray(mesh.triangles, dtype=np.float64)
    pts = np.atleast_2d(np.asarray(points, dtype=np.float64))
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise JassyError(f"point: expected x, y, z coordinates, got shape {pts.shape}")
    centroids = tris.mean(axis=1)
    radius = np.linalg.norm(tris - centroids[:, None, :], axis=2).max(axis=1)
    n_pts = len(pts)
    near = min(8, len(tris))
    _, first = cKDTree(centroids).query(pts, k=near)
    first = np.asarray(first).reshape(n_pts, near)
    owner = np.repeat(np.arange(n_pts), near)
    cp = closest_point(tris[first.ravel()], pts[owner])
    bound = np.sqrt(np.einsum("ij,ij->i", cp - pts[owner], cp - pts[owner]).reshape(n_pts, near).min(axis=1))
    level = np.floor(np.log2(np.maximum(radius, 1e-300) / max(float(radius.max()), 1e-300))).astype(np.int64)
    flat, owners = [first.ravel()], [owner]
    for lv in np.unique(level):
        group = np.flatnonzero(level == lv)
        cand = cKDTree(centroids[group]).query_ball_point(
            pts, bound + radius[group].max() * (1 + 1e-9) + 1e-12
        )
        counts = np.array([len(c) for c in cand])
        if counts.sum():
            flat.append(group[np.concatenate([np.asarray(c, dtype=np.int64) for c in cand if len(c)])])
            owners.append(np.repeat(np.arange(n_pts), counts))
    flat, owner = np.concatenate(flat), np.concatenate(owners)
    cp = closest_point(tris[flat], pts[owner])
    d = np.einsum("ij,ij->i", cp - pts[owner], cp - pts[owner])
    order = np.lexsort((flat, d, owner))  # per point, nearest first (ties: the lowest triangle id)
    best = order[np.searchsorted(owner[order], np.arange(n_pts))]
    tri_id = flat[best]
    close = cp[best]
    bary = points_to_barycentric(tris[tri_id], close)
    bary = np.clip(bary, 0.0, None)
    bary /= bary.sum(axis=1, keepdims=True)
    return close, tri_id, bary


def corner_normals(mesh, crease_degrees: float = 30.0) -> np.ndarray:
    """(n_faces, 3, 3) unit normals at each face's corners, averaged (area-weighted) over the
    faces around the corner's vertex whose normals are within ``crease_degrees`` of the face's:
    smooth on curved surfaces, exact face normals on the flat faces of boxes (sharp edges
    are creases)."""
    faces = np.asarray(mesh.faces)
    fn = np.asarray(mesh.face_normals)
    area = np.asarray(mesh.area_faces)
    vf = np.asarray(mesh.vertex_faces)  # (n_vertices, max valence), padded with -1
    nbr = vf[faces]  # (F, 3, valence)
    valid = nbr >= 0
    nb = np.where(valid, nbr, 0)
    cos = np.einsum("fcvi,fi->fcv", fn[nb], fn)
    w = np.where(valid & (cos >= np.cos(np.radians(crease_degrees))), area[nb], 0.0)
    n = np.einsum("fcv,fcvi->fci", w, fn[nb])
    return n / np.maximum(np.linalg.norm(n, axis=2, keepdims=True), 1e-300)


def surface_frames(mesh, points, crease_degrees: float = 30.0) -> tuple[np.ndarray, np.ndarray]:
    """(closest surface points, unit normals there) for arbitrary points: normals are the
    barycentric blend of :func:`corner_normals` of the closest triangle."""
    close, tri, bary = closest_points(mesh, points)
    cn = corner_normals(mesh, crease_degrees)[tri]  # (n, 3, 3)
    n = np.einsum("nc,nci->ni", bary, cn)
    return close, n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)


class SurfaceMap:
    """Barycentric lookup of per-vertex values (a texture map) on a triangle mesh."""

    def __init__(self, mesh):
        self.mesh = mesh
        self.faces = np.asarray(mesh.faces)

    def location(self, point) -> dict:
        """The closest surface point as a patch location {vertices, weights} (weights sum to 1)."""
        _, tri, bary = closest_points(self.mesh, point)
        verts = [int(v) for v in self.faces[tri[0]]]
        w = [float(x) for x in bary[0]]
        w[-1] = 1.0 - sum(w[:-1])
        return {"vertices": verts, "weights": w}

    def interpolate(self, values, point) -> np.ndarray:
        """values (n_vertices, ...) interpolated barycentrically at the closest surface point."""
        _, tri, bary = closest_points(self.mesh, point)
        vals = np.asarray(values)
        if vals.shape[0] != len(self.mesh.vertices):
            raise JassyError(
                f"expected one row of values per vertex ({len(self.mesh.vertices)}), got {vals.shape[0]}"
            )
        return np.tensordot(bary[0], vals[self.faces[tri[0]]], axes=1)
