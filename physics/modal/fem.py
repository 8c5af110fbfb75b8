"""Linear-elastic finite element modes of a solid from its surface mesh.

Pipeline (:func:`modes_from_mesh`): voxelise the watertight mesh into cubes of side ``pitch``
(a voxel belongs to the solid if its centre is inside), build the sparse stiffness K and mass M
of 8-node hexahedra, solve K phi = omega^2 M phi for the lowest modes by shift-invert Lanczos
(ARPACK through scipy, one sparse LU of K - sigma M, sigma < 0 because K is singular), drop the
six rigid-body modes and sample every mode's normal displacement on the surface.

Element choice: voxel hexahedra with Wilson's incompatible modes (Wilson, Taylor, Doherty &
Ghaboussi 1973, "Incompatible displacement models"; the Abaqus C3D8I element). Voxels need no
tetrahedraliser (none is installed), cope with any closed mesh, and are all the same cube, so
one 24x24 element stiffness and mass serve every element and assembly is one vectorised
scatter. Plain trilinear hexahedra lock in bending (a bar two elements thick is ~30 % too
stiff); the nine internal bubble modes (1 - xi^2 per axis and component, condensed out
statically) make a cube represent pure bending exactly, so thin bars, plates and shells are
accurate with a few elements through the thickness. On cubes the incompatible element passes
the patch test (the bubble derivatives integrate to zero). The voxel surface is a staircase,
which converges at first order in the pitch on curved shapes.

Mass is consistent (trilinear shape functions, exact 2x2x2 Gauss). Units: SI (metres, kg, s).

Gains convention (the project's: ModalModel gains are the displacement impulse response at the
contact point). With mass-normalised shapes (phi^T M phi = 1) a unit impulse (1 N s) along
the surface normal n at p, heard as the normal displacement at p, is
sum_k (n . phi_k(p))^2 / omega_k e^{-d_k t} sin(omega_k t). So by default

    a[p, k] = (n . phi_k(p))^2 / omega_k        (m per N s; ``radiation="displacement"``)

``radiation="velocity"`` multiplies by omega_k (normal surface velocity amplitude, m/s per N s)
and ``"acceleration"`` by omega_k^2 (m/s^2 per N s; a compact radiator's far-field pressure
follows the volume acceleration). The displacement form is what closed-loop contact models
need; the others are brighter and closer to what a microphone hears. ``normalise=True``
divides all gains by the largest |a| (the loudest gain becomes 1; the factor is stored in
:attr:`ModesReport.gain_scale`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numba as nb
import numpy as np

from jassy.errors import JassyError
from jassy.modal_model import ModalModel
from physics.modal._blas import single_threaded
from physics.modal.materials import RADIATION, Material
from physics.modal.solver import MultifrontalCholesky, eigsh_shift_invert, nested_dissection

# ------------------------------------------------------------------------------- element


#: Local node order of a hexahedron: node a = i + 2 j + 4 k at corner (i, j, k) of the cube.
CORNERS = np.array([[i, j, k] for k in (0, 1) for j in (0, 1) for i in (0, 1)], dtype=np.int64)


def elasticity_matrix(youngs: float, poisson: float) -> np.ndarray:
    """Isotropic 6x6 D (Voigt order xx, yy, zz, yz, xz, xy; engineering shear strains)."""
    lam = youngs * poisson / ((1 + poisson) * (1 - 2 * poisson))
    mu = youngs / (2 * (1 + poisson))
    d = np.zeros((6, 6))
    d[:3, :3] = lam
    d[[0, 1, 2], [0, 1, 2]] += 2 * mu
    d[[3, 4, 5], [3, 4, 5]] = mu
    return d


def _strain_operator(grads: np.ndarray) -> np.ndarray:
    """B (6, 3 n) from shape-function gradients grads (n, 3), dofs ordered (node, component)."""
    n = grads.shape[0]
    b = np.zeros((6, 3 * n))
    gx, gy, gz = grads[:, 0], grads[:, 1], grads[:, 2]
    b[0, 0::3], b[1, 1::3], b[2, 2::3] = gx, gy, gz
    b[3, 1::3], b[3, 2::3] = gz, gy
    b[4, 0::3], b[4, 2::3] = gz, gx
    b[5, 0::3], b[5, 1::3] = gy, gx
    return b


def hex_matrices(poisson: float, incompatible: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """(K1, M1): 24x24 stiffness of a unit cube for E = 1 and consistent mass for rho = 1.

    For a cube of side h, material E, rho: K_e = E h K1 and M_e = rho h^3 M1. With
    ``incompatible`` the nine bubble modes are condensed out (K = Kuu - Kua Kaa^-1 Kau).
    """
    d = elasticity_matrix(1.0, poisson)
    s = np.array([-1.0, 1.0]) / np.sqrt(3.0)
    signs = 2.0 * CORNERS - 1.0  # (8, 3) of +-1
    kuu = np.zeros((24, 24))
    kua = np.zeros((24, 9))
    kaa = np.zeros((9, 9))
    m1 = np.zeros((8, 8))
    det = 0.125  # (h/2)^3 for h = 1; d/dx = 2 d/dxi
    for xi in s:
        for eta in s:
            for zeta in s:
                q = np.array([xi, eta, zeta])
                f = 1.0 + signs * q  # (8, 3)
                n = f.prod(axis=1) / 8.0
                grads = np.empty((8, 3))
                grads[:, 0] = signs[:, 0] * f[:, 1] * f[:, 2] / 8.0
                grads[:, 1] = signs[:, 1] * f[:, 0] * f[:, 2] / 8.0
                grads[:, 2] = signs[:, 2] * f[:, 0] * f[:, 1] / 8.0
                bu = _strain_operator(2.0 * grads)
                kuu += bu.T @ d @ bu * det
                m1 += np.outer(n, n) * det
                if incompatible:
                    ga = np.diag(-2.0 * q * 2.0)  # bubble P_i = 1 - q_i^2: dP_i/dx_i = -2 q_i * 2/h
                    ba = _strain_operator(ga)
                    kua += bu.T @ d @ ba * det
                    kaa += ba.T @ d @ ba * det
    k1 = kuu - kua @ np.linalg.solve(kaa, kua.T) if incompatible else kuu
    k1 = 0.5 * (k1 + k1.T)
    mass = np.kron(m1, np.eye(3))
    return k1, mass


# ------------------------------------------------------------------------------- voxels


@nb.njit(cache=True)
def _ray_crossings(tri_yz, tri_x, y0, z0, pitch, ny, nz, count_only, col, xs):
    """Crossings of rays along +x (one per voxel column (j, k), through the column centre)
    with the triangles; returns the count, and fills col/xs unless ``count_only``."""
    m = 0
    for t in range(tri_yz.shape[0]):
        ay, az = tri_yz[t, 0, 0], tri_yz[t, 0, 1]
        by, bz = tri_yz[t, 1, 0], tri_yz[t, 1, 1]
        cy, cz = tri_yz[t, 2, 0], tri_yz[t, 2, 1]
        area = (by - ay) * (cz - az) - (bz - az) * (cy - ay)
        if area == 0.0:
            continue
        jlo = max(int(np.floor((min(ay, by, cy) - y0) / pitch - 0.5)), 0)
        jhi = min(int(np.ceil((max(ay, by, cy) - y0) / pitch - 0.5)), ny - 1)
        klo = max(int(np.floor((min(az, bz, cz) - z0) / pitch - 0.5)), 0)
        khi = min(int(np.ceil((max(az, bz, cz) - z0) / pitch - 0.5)), nz - 1)
        for j in range(jlo, jhi + 1):
            py = y0 + (j + 0.5) * pitch
            for k in range(klo, khi + 1):
                pz = z0 + (k + 0.5) * pitch
                w0 = ((by - py) * (cz - pz) - (bz - pz) * (cy - py)) / area
                w1 = ((cy - py) * (az - pz) - (cz - pz) * (ay - py)) / area
                w2 = 1.0 - w0 - w1
                if w0 >= 0.0 and w1 >= 0.0 and w2 >= 0.0:
                    if not count_only:
                        col[m] = j * nz + k
                        xs[m] = w0 * tri_x[t, 0] + w1 * tri_x[t, 1] + w2 * tri_x[t, 2]
                    m += 1
    return m


@nb.njit(cache=True)
def _fill_columns(col, xs, x0, pitch, nx, nz, filled):
    """Mark voxels whose centre lies between consecutive crossing pairs of their column."""
    i = 0
    n = col.shape[0]
    bad = 0
    while i < n:
        c = col[i]
        e = i
        while e < n and col[e] == c:
            e += 1
        if (e - i) % 2 == 1:
            bad += 1
        else:
            j = c // nz
            k = c % nz
            for p in range(i, e, 2):
                lo = int(np.ceil((xs[p] - x0) / pitch - 0.5))
                hi = int(np.floor((xs[p + 1] - x0) / pitch - 0.5))
                for q in range(max(lo, 0), min(hi, nx - 1) + 1):
                    filled[q, j, k] = True
        i = e
    return bad


@dataclass
class VoxelGrid:
    """Cubes of side ``pitch``; voxel (i, j, k) spans origin + pitch * [i, i+1] x ... ."""

    origin: np.ndarray
    pitch: float
    filled: np.ndarray  # bool (nx, ny, nz)
    dropped: int = 0  # voxels removed because they were not face-connected to the main body

    @property
    def n_elements(self) -> int:
        return int(self.filled.sum())

    def indices(self) -> np.ndarray:
        """(n, 3) integer indices of the filled voxels (C order)."""
        return np.argwhere(self.filled)

    def centres(self) -> np.ndarray:
        return self.origin + (self.indices() + 0.5) * self.pitch


def voxelize(mesh, pitch: float) -> VoxelGrid:
    """Voxels whose centre is inside the closed mesh (ray parity along x, one ray per column).

    The grid starts at the mesh's lower bounds, so a box whose sides are multiples of the pitch
    is voxelised exactly. Rays are offset by ~1e-6 pitch to avoid passing exactly through
    mesh edges. Only the largest face-connected component is kept (voxels touching the body
    along an edge or corner only would be hinges with spurious zero-frequency modes).
    """
    from scipy import ndimage

    if not (pitch > 0 and np.isfinite(pitch)):
        raise JassyError(f"pitch: expected a length > 0 m, got {pitch}")
    lo, hi = np.asarray(mesh.bounds, dtype=np.float64)
    counts = np.maximum(np.ceil((hi - lo) / pitch - 1e-9).astype(np.int64), 1)
    if np.prod(counts.astype(float)) > 2e8:
        raise JassyError(f"pitch {pitch:g} m: the grid would have {np.prod(counts.astype(float)):.3g} cells")
    nx, ny, nz = (int(c) for c in counts)
    origin = lo.copy()
    tri = np.asarray(mesh.triangles, dtype=np.float64)
    jitter = pitch * np.array([0.0, 1.2345e-6 * np.sqrt(2), 0.9876e-6 * np.sqrt(3)])
    o = origin + jitter
    tri_yz = np.ascontiguousarray(tri[:, :, 1:])
    tri_x = np.ascontiguousarray(tri[:, :, 0])
    empty_i = np.zeros(0, np.int64)
    empty_f = np.zeros(0, np.float64)
    m = _ray_crossings(tri_yz, tri_x, o[1], o[2], pitch, ny, nz, True, empty_i, empty_f)
    col = np.empty(m, np.int64)
    xs = np.empty(m, np.float64)
    _ray_crossings(tri_yz, tri_x, o[1], o[2], pitch, ny, nz, False, col, xs)
    order = np.lexsort((xs, col))
    filled = np.zeros((nx, ny, nz), dtype=np.bool_)
    bad = _fill_columns(col[order], xs[order], origin[0], pitch, nx, nz, filled)
    if bad:
        raise JassyError(
            f"mesh: {bad} ray(s) crossed the surface an odd number of times; the mesh is not a "
            "closed, consistently oriented surface"
        )
    labels, n = ndimage.label(filled)
    dropped = 0
    if n > 1:
        sizes = np.bincount(labels.ravel())[1:]
        keep = int(np.argmax(sizes)) + 1
        dropped = int(sizes.sum() - sizes.max())
        filled = labels == keep
    if not filled.any():
        raise JassyError(
            f"pitch {pitch:g} m: no voxel centre lies inside the mesh; use a smaller pitch "
            f"(the mesh spans {np.ptp(np.asarray(mesh.bounds), axis=0)} m)"
        )
    return VoxelGrid(origin, float(pitch), filled, dropped)


def pitch_for_elements(mesh, n_elements: int) -> float:
    """The pitch giving about ``n_elements`` voxels, (volume / n)^(1/3), adjusted (by at most
    35 %) so that the thinnest side of the bounding box is a whole number of voxels: then
    axis-aligned bars, plates and boxes are voxelised with their exact thickness."""
    if n_elements < 1:
        raise JassyError(f"--elements: expected an integer >= 1, got {n_elements}")
    p0 = float((abs(mesh.volume) / n_elements) ** (1.0 / 3.0))
    thin = float(np.min(np.ptp(np.asarray(mesh.bounds), axis=0)))
    k = max(1, round(thin / p0))
    p = thin / k
    return p if abs(p / p0 - 1.0) < 0.35 else p0


# ------------------------------------------------------------------------------- assembly


@dataclass
class FEModel:
    """Assembled voxel model: node coordinates, element connectivity, sparse K and M (CSR)."""

    grid: VoxelGrid
    material: Material
    nodes: np.ndarray  # (n_nodes, 3) coordinates in m
    elements: np.ndarray  # (n_el, 8) node indices (local order CORNERS)
    node_index: np.ndarray  # (nx+1, ny+1, nz+1) -> node id or -1
    stiffness: object
    mass: object
    timings: dict = field(default_factory=dict)

    @property
    def n_dofs(self) -> int:
        return 3 * self.nodes.shape[0]


def assemble(grid: VoxelGrid, material: Material, incompatible: bool = True) -> FEModel:
    """Sparse K (N/m) and M (kg) of the voxel solid (COO -> CSR, duplicates summed)."""
    from scipy import sparse

    t0 = time.perf_counter()
    vox = grid.indices()
    nx, ny, nz = grid.filled.shape
    corner_ids = vox[:, None, :] + CORNERS[None, :, :]  # (n_el, 8, 3)
    used = np.zeros((nx + 1, ny + 1, nz + 1), dtype=bool)
    used[corner_ids[..., 0], corner_ids[..., 1], corner_ids[..., 2]] = True
    node_index = np.full(used.shape, -1, dtype=np.int64)
    node_index[used] = np.arange(int(used.sum()))
    nodes = grid.origin + np.argwhere(used) * grid.pitch
    elements = node_index[corner_ids[..., 0], corner_ids[..., 1], corner_ids[..., 2]]
    dofs = (3 * elements[:, :, None] + np.arange(3)[None, None, :]).reshape(-1, 24)
    k1, m1 = hex_matrices(material.poisson, incompatible)
    n_el = elements.shape[0]
    n_dof = 3 * nodes.shape[0]
    idx_t = np.int32 if n_dof < 2**31 - 1 else np.int64
    rows = np.broadcast_to(dofs[:, :, None], (n_el, 24, 24)).astype(idx_t).ravel()
    cols = np.broadcast_to(dofs[:, None, :], (n_el, 24, 24)).astype(idx_t).ravel()
    h = grid.pitch
    kdata = np.broadcast_to(material.youngs * h * k1, (n_el, 24, 24)).ravel()
    mdata = np.broadcast_to(material.density * h**3 * m1, (n_el, 24, 24)).ravel()
    stiffness = sparse.coo_matrix((kdata, (rows, cols)), shape=(n_dof, n_dof)).tocsr()
    mass = sparse.coo_matrix((mdata, (rows, cols)), shape=(n_dof, n_dof)).tocsr()
    timings = {"assemble": time.perf_counter() - t0}
    return FEModel(grid, material, nodes, elements, node_index, stiffness, mass, timings)


# ------------------------------------------------------------------------------- eigenmodes


@dataclass
class Modes:
    """Elastic modes: frequencies (Hz), mass-normalised shapes (n_dofs, n_modes)."""

    frequencies: np.ndarray
    shapes: np.ndarray
    rigid: np.ndarray  # the dropped rigid-body eigenvalues omega^2 (should be ~0)
    timings: dict = field(default_factory=dict)
    info: dict = field(default_factory=dict)


def node_adjacency(fem: FEModel):
    """Node-level sparsity pattern (CSR, n_nodes^2): nodes sharing an element."""
    from scipy import sparse

    n_el = fem.elements.shape[0]
    inc = sparse.csr_matrix(
        (np.ones(8 * n_el), fem.elements.ravel(), np.arange(0, 8 * n_el + 1, 8)),
        shape=(n_el, fem.nodes.shape[0]),
    )
    return (inc.T @ inc).tocsr()


def default_shift(fem: FEModel) -> float:
    """sigma = -(2 pi f_s)^2 with f_s = 1e-3 c / L (c = sqrt(E/rho), L the largest extent):
    far below any elastic mode of the body, so the rigid modes are the first found."""
    extent = float(np.ptp(fem.nodes, axis=0).max())
    fs = 1e-3 * fem.material.bar_speed / extent
    return -((2 * np.pi * fs) ** 2)


def solve(fem: FEModel, n_modes: int, shift: float | None = None, tol: float = 1e-8) -> Modes:
    """The lowest ``n_modes`` elastic modes (six rigid modes solved for and dropped).

    Shift-invert block Krylov around sigma < 0 (:mod:`physics.modal.solver`): one multifrontal
    Cholesky of K - sigma M in nested-dissection order, then block solves. The starting block
    is seeded, so results are reproducible. Shapes are normalised to phi^T M phi = 1.
    """
    if n_modes < 1:
        raise JassyError(f"--modes: expected an integer >= 1, got {n_modes}")
    n_dof = fem.n_dofs
    k = n_modes + 6
    if k >= n_dof - 1:
        raise JassyError(
            f"--modes: {n_modes} modes asked but the model has only {n_dof} degrees of freedom; "
            "use a smaller pitch"
        )
    sigma = default_shift(fem) if shift is None else float(shift)
    with single_threaded():
        t0 = time.perf_counter()
        coords = np.rint((fem.nodes - fem.grid.origin) / fem.grid.pitch).astype(np.int64)
        order, tree = nested_dissection(coords)
        chol = MultifrontalCholesky(fem.stiffness - sigma * fem.mass, order, tree, node_adjacency(fem))
        t1 = time.perf_counter()
        res = eigsh_shift_invert(fem.stiffness, fem.mass, k, sigma, chol.solve, tol=tol, skip=6)
        t2 = time.perf_counter()
    vals, vecs = res.eigenvalues, res.vectors
    rigid, vals, vecs = vals[:6], vals[6:], vecs[:, 6:]
    if vals[0] <= 0 or np.max(np.abs(rigid)) > 1e-4 * vals[0]:
        raise JassyError(
            "modes: did not find exactly six rigid-body modes below the elastic ones "
            f"(lowest eigenvalues {np.sqrt(np.abs(np.r_[rigid, vals[:2]])) / (2 * np.pi)} Hz); "
            "the voxel model may be disconnected or the pitch too coarse"
        )
    norms = np.sqrt(np.einsum("ik,ik->k", vecs, fem.mass @ vecs))
    vecs = vecs / norms
    freqs = np.sqrt(vals) / (2 * np.pi)
    timings = {"factor": t1 - t0, "eigsh": t2 - t1}
    info = {
        "factor_nnz": chol.nnz,
        "cycles": res.cycles,
        "solves": res.solves,
        "residual": float(res.residuals.max()),
    }
    return Modes(freqs, vecs, rigid, timings, info)


# ------------------------------------------------------------------------------- surface sampling


def sample_displacements(fem: FEModel, shapes: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Displacement (n_points, 3, n_modes) of the modes at arbitrary points, trilinear in the
    voxel containing each point (or the nearest filled voxel, the point clamped onto it)."""
    from scipy.spatial import cKDTree

    grid = fem.grid
    pts = np.atleast_2d(np.asarray(points, dtype=np.float64))
    rel = (pts - grid.origin) / grid.pitch
    ijk = np.floor(rel).astype(np.int64)
    shape = np.array(grid.filled.shape)
    inside = np.all((ijk >= 0) & (ijk < shape), axis=1)
    ok = np.zeros(len(pts), dtype=bool)
    ok[inside] = grid.filled[ijk[inside, 0], ijk[inside, 1], ijk[inside, 2]]
    if not ok.all():
        centres = grid.centres()
        tree = cKDTree(centres)
        _, nearest = tree.query(pts[~ok])
        ijk[~ok] = grid.indices()[nearest]
    local = np.clip(rel - ijk, 0.0, 1.0)  # (n, 3) in [0, 1]
    corner = ijk[:, None, :] + CORNERS[None, :, :]  # (n, 8, 3)
    node = fem.node_index[corner[..., 0], corner[..., 1], corner[..., 2]]  # (n, 8)
    w = np.where(CORNERS[None, :, :] == 1, local[:, None, :], 1.0 - local[:, None, :]).prod(axis=2)
    u = shapes.reshape(-1, 3, shapes.shape[1])  # (n_nodes, 3, n_modes)
    return np.einsum("pa,paim->pim", w, u[node])


def normal_displacements(fem: FEModel, modes: Modes, points: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """n_p . phi_k(p) (m per sqrt(kg)), shape (n_points, n_modes)."""
    disp = sample_displacements(fem, modes.shapes, points)
    n = np.asarray(normals, dtype=np.float64)
    n = n / np.linalg.norm(n, axis=1, keepdims=True)
    return np.einsum("pi,pim->pm", n, disp)


def gains_from_displacements(
    un: np.ndarray, frequencies: np.ndarray, radiation: str = "displacement"
) -> np.ndarray:
    """a[p, k] = (n_p . phi_k(p))^2 / omega_k, times omega_k^r for radiation r = 0, 1, 2."""
    if radiation not in RADIATION:
        raise JassyError(f"--radiation: expected one of {', '.join(RADIATION)}, got {radiation!r}")
    omega = 2 * np.pi * np.asarray(frequencies)
    return un**2 * omega ** (RADIATION.index(radiation) - 1)


def degenerate_groups(frequencies: np.ndarray, rtol: float = 1e-6) -> list[np.ndarray]:
    """Indices of the modes (frequencies ascending) grouped by equal frequency within
    ``rtol``: a group of m > 1 is a degenerate family of multiplicity m (a sphere's 2l + 1
    modes of degree l, the mode pairs of anything with a symmetry axis)."""
    groups = [[0]] if len(frequencies) else []
    for i in range(1, len(frequencies)):
        if frequencies[i] - frequencies[groups[-1][0]] <= rtol * frequencies[i]:
            groups[-1].append(i)
        else:
            groups.append([i])
    return [np.array(g) for g in groups]


def group_sizes(groups: list[np.ndarray], n_modes: int) -> np.ndarray:
    """Per mode, the size of its group in ``groups`` (index arrays, as
    :func:`degenerate_groups` returns them; 1 for a mode in none)."""
    out = np.ones(n_modes, dtype=np.int64)
    for g in groups:
        out[g] = g.size
    return out


def multiplicities(frequencies: np.ndarray, rtol: float = 1e-6) -> np.ndarray:
    """Per mode (in any order), the size of its degenerate family (1: a simple mode), the
    families as :func:`degenerate_groups` finds them."""
    frequencies = np.asarray(frequencies)
    order = np.argsort(frequencies, kind="stable")
    groups = [order[g] for g in degenerate_groups(frequencies[order], rtol)]
    return group_sizes(groups, frequencies.size)


def align_degenerate(un: np.ndarray, groups: list[np.ndarray]) -> np.ndarray:
    """Normal displacements (n_points, n_modes) with each degenerate family's basis rotated so
    that at the first point only the family's first mode moves along the normal.

    Within a degenerate eigenspace any orthonormal basis is an equally valid set of mode
    shapes, and a solver returns an arbitrary one; this basis is reproducible and physical:
    struck at the first point, one mode of the family rings and the others (orthogonal
    shapes, their own gains elsewhere) stay silent there."""
    out = np.array(un, dtype=np.float64, copy=True)
    for g in groups:
        if g.size < 2:
            continue
        u = out[0, g]
        norm = float(np.linalg.norm(u))
        if norm <= 1e-12 * max(float(np.abs(out[:, g]).max()), 1e-300):
            continue
        q = np.linalg.qr(np.column_stack([u / norm, np.eye(g.size)]))[0][:, : g.size]
        q[:, 0] *= np.sign(q[:, 0] @ u)
        out[:, g] = out[:, g] @ q
    return out


# ------------------------------------------------------------------------------- whole pipeline


@dataclass
class ModesReport:
    """What :func:`modes_from_mesh` did: sizes, timings (s), the gain normalisation factor."""

    pitch: float
    n_elements: int
    n_nodes: int
    n_dofs: int
    dropped_voxels: int
    n_surface_points: int
    gain_scale: float
    multiplicity: tuple[int, ...]  # per kept mode: the size of its degenerate family (1 = simple)
    timings: dict
    voxel_volume: float
    mesh_volume: float

    def summary(self) -> str:
        t = self.timings
        steps = ", ".join(f"{k} {v:.2f} s" for k, v in t.items())
        return (
            f"pitch {self.pitch * 1e3:.3g} mm, {self.n_elements} elements, {self.n_nodes} nodes, "
            f"{self.n_dofs} dofs (voxel volume {self.voxel_volume / self.mesh_volume:.3f} of the mesh's); "
            f"{self.n_surface_points} surface points; {steps}"
        )

    def families(self) -> str:
        """The degenerate families kept, e.g. "4 pairs, 1 family of 5 (kept as separate modes)"."""
        sizes = []
        k = 0
        while k < len(self.multiplicity):
            m = self.multiplicity[k]
            if m > 1:
                sizes.append(m)
            k += max(m, 1)
        if not sizes:
            return ""
        counts = {m: sizes.count(m) for m in sorted(set(sizes))}
        parts = [f"{c} pair{'s' if c > 1 else ''}" if m == 2 else f"{c} famil{'ies' if c > 1 else 'y'} of {m}"
                 for m, c in counts.items()]  # fmt: skip
        return "degenerate modes: " + ", ".join(parts) + " (kept as separate modes, each with its own gains)"


def modes_from_mesh(
    mesh,
    material: Material,
    n_modes: int = 50,
    pitch: float | None = None,
    elements: int | None = None,
    subdivide: int = 0,
    points: dict[str, tuple[float, float, float]] | None = None,
    radiation: str = "displacement",
    normalise: bool = False,
    name: str = "",
    incompatible: bool = True,
    f_max: float | None = None,
) -> tuple[ModalModel, ModesReport, object]:
    """A ModalModel of the solid bounded by ``mesh`` (SI units) made of ``material``.

    Give ``pitch`` (m) or ``elements`` (target voxel count; default 4000).

    Without ``points``, the model has one row per control vertex of the texture map: the
    vertices of the surface refined by ``subdivide`` Loop subdivisions, each projected onto the
    original surface (Loop subdivision rounds sharp edges off), with the original surface's
    normal there. That sampled surface is returned third: its vertex i is model row i, and its
    triangles interpolate gains barycentrically (:class:`physics.modal.subdivision.SurfaceMap`).
    With ``points`` (name -> x, y, z in m), the model has one named row per point, sampled
    directly from the finite element solution at the closest surface point (third value None).
    Decays follow the material's damping law. Degenerate families (equal frequencies) are
    kept as separate modes, each with its own shape and gains, in the basis of
    :func:`align_degenerate`; the report lists their multiplicities. Modes at or above
    ``f_max`` Hz are dropped.
    """
    import trimesh

    from physics.modal.meshes import check_closed
    from physics.modal.subdivision import loop_subdivide, surface_frames

    t0 = time.perf_counter()
    check_closed(mesh)
    if pitch is None:
        pitch = pitch_for_elements(mesh, elements or 4000)
    grid = voxelize(mesh, pitch)
    t1 = time.perf_counter()
    fem = assemble(grid, material, incompatible)
    t2 = time.perf_counter()
    modes = solve(fem, n_modes)
    t3 = time.perf_counter()
    point_names: tuple[str, ...] = ()
    if points:
        where, normals = surface_frames(mesh, np.array([tuple(p) for p in points.values()], dtype=float))
        un = normal_displacements(fem, modes, where, normals)
        point_names = tuple(points)
        surface = None
    else:
        refined = loop_subdivide(mesh, subdivide)[0] if subdivide else mesh
        where, normals = surface_frames(mesh, np.asarray(refined.vertices))
        un = normal_displacements(fem, modes, where, normals)
        surface = trimesh.Trimesh(where, np.asarray(refined.faces), process=False)
    groups = degenerate_groups(modes.frequencies)
    freqs = modes.frequencies
    gains = gains_from_displacements(align_degenerate(un, groups), freqs, radiation)
    multiplicity = group_sizes(groups, freqs.size)
    if f_max is not None:
        keep = freqs < f_max
        freqs, gains, multiplicity = freqs[keep], gains[:, keep], multiplicity[keep]
        if freqs.size == 0:
            raise JassyError(
                f"--fmax: no mode below {f_max:g} Hz (the lowest is {modes.frequencies[0]:g} Hz)"
            )
    scale = 1.0
    if normalise:
        peak = float(np.max(np.abs(gains)))
        scale = 1.0 / peak if peak > 0 else 1.0
        gains = gains * scale
    t4 = time.perf_counter()
    model = ModalModel(freqs, material.decay(freqs), gains, point_names, name or material.name)
    timings = {
        "voxelise": t1 - t0,
        "assemble": t2 - t1,
        "factor": modes.timings["factor"],
        "eigsh": modes.timings["eigsh"],
        "gains": t4 - t3,
        "total": t4 - t0,
    }
    report = ModesReport(
        pitch=float(pitch),
        n_elements=grid.n_elements,
        n_nodes=fem.nodes.shape[0],
        n_dofs=fem.n_dofs,
        dropped_voxels=grid.dropped,
        n_surface_points=gains.shape[0],
        gain_scale=scale,
        multiplicity=tuple(int(m) for m in multiplicity),
        timings=timings,
        voxel_volume=grid.n_elements * pitch**3,
        mesh_volume=float(abs(mesh.volume)),
    )
    return model, report, surface
