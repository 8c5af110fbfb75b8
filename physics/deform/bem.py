"""3-D linear elastostatic boundary elements: linear triangles collocated at the vertices.

Displacement u (m) and traction p (Pa, force per area exerted on the body) are linear over
each flat triangle, with one value per vertex; the collocation points are the vertices, so
H u = G p with 3n x 3n matrices (3x3 block (i, j): source vertex i, field vertex j). The
diagonal blocks of H (free term c_ij plus the Cauchy principal value) come from the
rigid-body trick H_ii = -sum_{j != i} H_ij (a translation gives no traction), valid for a
closed surface bounding the body (outward normals). Quadrature: physics.deform.quadrature.

Since the traction is linear on each triangle, the total force on a set of vertices is
exactly sum_j a_j p_j with the vertex area a_j = one third of the adjacent triangle areas.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla

from jassy.errors import JassyError
from physics.deform.quadrature import integrate
from physics.modal.materials import Material

#: Density (kg/m^3) given to soft-gel materials: elastostatics does not use it.
SOFT_GEL_DENSITY = 1000.0


def mesh_arrays(vertices, faces) -> tuple[np.ndarray, np.ndarray]:
    """Checked (float64 (n, 3) vertices in m, int64 (f, 3) faces) of a closed, outward-oriented
    triangle mesh in which every vertex is used."""
    V = np.ascontiguousarray(vertices, dtype=np.float64)
    F = np.ascontiguousarray(faces, dtype=np.int64)
    if V.ndim != 2 or V.shape[1] != 3 or V.shape[0] < 4 or not np.all(np.isfinite(V)):
        raise JassyError(f"vertices: expected a finite (n >= 4, 3) array, got shape {V.shape}")
    if F.ndim != 2 or F.shape[1] != 3 or F.size == 0 or F.min() < 0 or F.max() >= V.shape[0]:
        raise JassyError(f"faces: expected an (f, 3) array of vertex indices < {V.shape[0]}")
    if np.unique(F).size != V.shape[0]:
        raise JassyError("faces: every vertex must belong to a triangle (collocation at vertices)")
    normals, areas = face_geometry(V, F)
    if np.any(areas <= 0):
        raise JassyError("faces: degenerate (zero-area) triangles")
    edges = np.sort(F[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    if np.any(np.unique(edges, axis=0, return_counts=True)[1] != 2):
        raise JassyError("faces: expected a closed (watertight) surface, each edge shared by two faces")
    volume = np.sum(np.einsum("ij,ij->i", V[F[:, 0]], np.cross(V[F[:, 1]], V[F[:, 2]]))) / 6.0
    if volume <= 0:
        raise JassyError("faces: expected outward (counter-clockwise seen from outside) orientation")
    return V, F


def face_geometry(V: np.ndarray, F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(unit normals (f, 3), areas (f,) in m^2) of the triangles."""
    cross = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    norm = np.linalg.norm(cross, axis=1)
    return cross / np.maximum(norm, 1e-300)[:, None], 0.5 * norm


def vertex_areas(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """a_j = integral of the shape function of vertex j = sum of adjacent areas / 3 (m^2)."""
    _, areas = face_geometry(V, F)
    return np.bincount(F.ravel(), np.repeat(areas / 3.0, 3), minlength=V.shape[0])


def assemble(vertices, faces, material: Material) -> tuple[np.ndarray, np.ndarray]:
    """(H, G), each 3n x 3n (row/column 3 i + k: vertex i, component k) with H u = G p for
    the mesh's displacements u (m) and tractions p (Pa); H's diagonal by the rigid-body trick."""
    V, F = mesh_arrays(vertices, faces)
    normals, areas = face_geometry(V, F)
    n = V.shape[0]
    H, G = integrate(V, np.arange(n), V, F, normals, areas, material.shear_modulus, material.poisson)
    blocks = H.reshape(n, 3, n, 3)
    sums = blocks.sum(axis=2)  # the diagonal blocks are still zero here
    idx = np.arange(n)
    blocks[idx, :, idx, :] = -sums
    return H, G


def dof_columns(n: int, nodes: np.ndarray) -> np.ndarray:
    """Matrix columns (3 i + k) of the given vertices."""
    return (3 * np.asarray(nodes)[:, None] + np.arange(3)).ravel()


def solve_mixed(H, G, displacement_nodes, values) -> tuple[np.ndarray, np.ndarray]:
    """Solve the mixed problem: at vertices where ``displacement_nodes`` (bool, n) is True the
    displacement ``values[i]`` (m) is given, elsewhere the traction ``values[i]`` (Pa).
    Returns (u (n, 3) in m, p (n, 3) in Pa). Needs at least one displacement vertex."""
    n = H.shape[0] // 3
    fixed = np.asarray(displacement_nodes, dtype=bool)
    vals = np.asarray(values, dtype=np.float64)
    if fixed.shape != (n,):
        raise JassyError(f"displacement_nodes: expected {n} booleans, got shape {fixed.shape}")
    if vals.shape != (n, 3) or not np.all(np.isfinite(vals)):
        raise JassyError(f"values: expected a finite ({n}, 3) array, got shape {vals.shape}")
    if not fixed.any():
        raise JassyError("displacement_nodes: a mixed problem needs at least one displacement vertex")
    cf, ct = dof_columns(n, np.flatnonzero(fixed)), dof_columns(n, np.flatnonzero(~fixed))
    A = np.empty_like(H)
    A[:, cf], A[:, ct] = -G[:, cf], H[:, ct]
    rhs = G[:, ct] @ vals.ravel()[ct] - H[:, cf] @ vals.ravel()[cf]
    v = sla.solve(A, rhs, check_finite=False)
    u, p = vals.ravel().copy(), vals.ravel().copy()
    u[ct], p[cf] = v[ct], v[cf]
    return u.reshape(n, 3), p.reshape(n, 3)


def rigid_modes(vertices) -> np.ndarray:
    """(3n, 6) orthonormal basis of the rigid displacements (3 translations, 3 rotations)."""
    V = np.asarray(vertices, dtype=np.float64)
    c = V - V.mean(axis=0)
    R = np.zeros((V.shape[0], 3, 6))
    for k in range(3):
        R[:, k, k] = 1.0
        axis = np.zeros(3)
        axis[k] = 1.0
        R[:, :, 3 + k] = np.cross(axis, c)
    q, _ = np.linalg.qr(R.reshape(-1, 6))
    return q


def solve_traction(H, G, vertices, tractions) -> np.ndarray:
    """Displacements (n, 3) in m of the pure traction problem (tractions (n, 3) in Pa, in
    equilibrium), with the rigid modes removed: [H R; R^T 0] [u; l] = [G p; 0]."""
    n = H.shape[0] // 3
    p = np.asarray(tractions, dtype=np.float64)
    if p.shape != (n, 3) or not np.all(np.isfinite(p)):
        raise JassyError(f"tractions: expected a finite ({n}, 3) array, got shape {p.shape}")
    R = rigid_modes(vertices)
    K = np.zeros((3 * n + 6, 3 * n + 6))
    K[: 3 * n, : 3 * n] = H
    K[: 3 * n, 3 * n :] = R * np.abs(H).max()
    K[3 * n :, : 3 * n] = R.T
    rhs = np.concatenate([G @ p.ravel(), np.zeros(6)])
    return sla.solve(K, rhs, check_finite=False)[: 3 * n].reshape(n, 3)
