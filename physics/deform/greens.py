"""Green's functions of a reference boundary-value problem, cached on disk.

Reference BVP (James & Pai): the ``fixed`` vertices have prescribed displacement (zero: the
object rests on a rigid base), every other ("free") vertex has prescribed traction. Per
vertex slot the unknown v is the traction (fixed) or the displacement (free), the
prescribed value v_bar the other one, and A v = -A_bar v_bar, so v = Xi v_bar with
Xi = -A^{-1} A_bar (A = [-G_fixed, H_free], A_bar = [H_fixed, -G_free] by columns).

What is stored: only the columns of Xi for the free vertices' tractions, Xi[:, free] =
A^{-1} G[:, free], shape (3n, 3 n_free), since the fixed vertices' prescribed displacement is
always zero. Row block i is the response of vertex i: displacement (m per Pa) if i is free,
reaction traction (Pa per Pa) if i is fixed. Column block c is the unit traction at vertex
``free[c]``. The free-free 3x3 block (i, i) is vertex i's point compliance.

Cache: ``<dir>/<sha256>.npz`` with dir = ``cache_dir``, else $JASSY_CACHE/greens, else
~/.cache/jassy/greens; the key hashes the vertex and face arrays, E, nu, the fixed set and
the format version. Files are written atomically; an unreadable or mismatched file is
recomputed and replaced.
"""

from __future__ import annotations

import hashlib
import os
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.linalg as sla

from jassy.errors import JassyError
from jassy.files import atomic_path
from physics.deform.bem import assemble, dof_columns, mesh_arrays, vertex_areas
from physics.modal.materials import Material

FORMAT = "jassy-greens-v1"


@dataclass(frozen=True)
class GreensFunctions:
    """Reference Green's functions of one mesh, material and fixed set (read-only arrays).

    vertices (n, 3) m; faces (f, 3); fixed (n,) bool; free: indices of the free vertices;
    col_of (n,): column block of each free vertex in ``xi`` (-1 for fixed); areas (n,) m^2
    vertex areas; xi (3n, 3 n_free) as in the module doc; key: the cache key; seconds: time
    to compute (s) or to load it; from_cache: True if it was loaded.
    """

    vertices: np.ndarray
    faces: np.ndarray
    material: Material
    fixed: np.ndarray
    free: np.ndarray
    col_of: np.ndarray
    areas: np.ndarray
    xi: np.ndarray
    key: str
    seconds: float
    from_cache: bool

    @property
    def n(self) -> int:
        return self.vertices.shape[0]


def default_cache_dir() -> Path:
    """$JASSY_CACHE/greens, else ~/.cache/jassy/greens."""
    root = os.environ.get("JASSY_CACHE")
    return (Path(root) if root else Path.home() / ".cache" / "jassy") / "greens"


def fixed_mask(n: int, fixed) -> np.ndarray:
    """Bool (n,) mask from a bool mask or an index list; needs 3 to n - 1 fixed vertices."""
    f = np.asarray(fixed)
    if f.dtype == bool:
        if f.shape != (n,):
            raise JassyError(f"fixed: expected {n} booleans or vertex indices, got shape {f.shape}")
        mask = f.copy()
    else:
        idx = f.astype(np.int64).ravel()
        if idx.size and (idx.min() < 0 or idx.max() >= n):
            raise JassyError(f"fixed: vertex indices must lie in [0, {n}), got {idx.min()}..{idx.max()}")
        mask = np.zeros(n, dtype=bool)
        mask[idx] = True
    if not 3 <= mask.sum() < n:
        raise JassyError(
            f"fixed: expected 3 to {n - 1} fixed vertices (to remove rigid motion), got {mask.sum()}"
        )
    return mask


def cache_key(V: np.ndarray, F: np.ndarray, material: Material, fixed: np.ndarray) -> str:
    h = hashlib.sha256(FORMAT.encode())
    for arr in (V.astype("<f8"), F.astype("<i8"), np.array([material.youngs, material.poisson], "<f8"),
                np.flatnonzero(fixed).astype("<i8")):  # fmt: skip
        h.update(str(arr.shape).encode())
        h.update(np.ascontiguousarray(arr).tobytes())
    return h.hexdigest()


def compute_xi(V: np.ndarray, F: np.ndarray, material: Material, fixed: np.ndarray) -> np.ndarray:
    """Xi[:, free] (module doc) by assembly and one dense LU of A (3n x 3n)."""
    n = V.shape[0]
    H, G = assemble(V, F, material)
    cf, ct = dof_columns(n, np.flatnonzero(fixed)), dof_columns(n, np.flatnonzero(~fixed))
    H[:, cf] = -G[:, cf]  # H becomes A
    rhs = np.asfortranarray(G[:, ct])
    del G
    lu = sla.lu_factor(H, overwrite_a=True, check_finite=False)
    del H
    xi = sla.lu_solve(lu, rhs, overwrite_b=True, check_finite=False)
    if not np.all(np.isfinite(xi)):
        raise JassyError("fixed: the reference problem is singular (Green's functions not finite)")
    return np.ascontiguousarray(xi)


def reference_greens(vertices, faces, material: Material, fixed, cache_dir=None, use_cache: bool = True
                     ) -> GreensFunctions:  # fmt: skip
    """Green's functions of the reference BVP (module doc) for a closed outward mesh
    (vertices in m), ``material`` and ``fixed`` (bool mask or vertex indices). Loaded from
    the cache if present (and ``use_cache``), else computed and, if ``use_cache``, stored."""
    if not isinstance(material, Material):
        raise JassyError(
            f"material: expected a physics.modal.materials.Material, got {type(material).__name__}"
        )
    V, F = mesh_arrays(vertices, faces)
    mask = fixed_mask(V.shape[0], fixed)
    key = cache_key(V, F, material, mask)
    path = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    path = path / f"{key}.npz"
    free = np.flatnonzero(~mask)
    t0 = time.perf_counter()
    xi = _load(path, key, (3 * V.shape[0], 3 * free.size)) if use_cache else None
    from_cache = xi is not None
    if xi is None:
        xi = compute_xi(V, F, material, mask)
        if use_cache:
            _store(path, key, xi)
    col_of = np.full(V.shape[0], -1, dtype=np.int64)
    col_of[free] = np.arange(free.size)
    arrays = (V, F, mask, free, col_of, xi)
    for a in arrays:
        a.setflags(write=False)
    areas = vertex_areas(V, F)
    areas.setflags(write=False)
    return GreensFunctions(
        V, F, material, mask, free, col_of, areas, xi, key, time.perf_counter() - t0, from_cache
    )


def _load(path: Path, key: str, shape: tuple[int, int]) -> np.ndarray | None:
    if not path.is_file():
        return None
    try:
        with np.load(path, allow_pickle=False) as data:
            if str(data["key"]) != key or data["xi"].shape != shape:
                return None
            xi = np.ascontiguousarray(data["xi"], dtype=np.float64)
    except (OSError, ValueError, KeyError, EOFError):
        return None
    return xi if np.all(np.isfinite(xi)) else None


def _store(path: Path, key: str, xi: np.ndarray) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        np.savez(fh, key=np.array(key), xi=xi)
