"""8-bit bone density volumes on a regular grid (Agus et al., IEEE VR 2002/2003).

A :class:`Volume` holds ``density`` (uint8, shape (nx, ny, nz), 0 = empty, 255 = the
reference bone density ``rho_full`` kg/m^3), the voxel side ``voxel`` (m) and ``origin``,
the world position (m) of the centre of voxel (0, 0, 0): voxel (i, j, k) is centred at
``origin + voxel * (i, j, k)``. The z axis points up (out of the bone in the phantom).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from jassy.errors import JassyError

#: Maximum edge length of a volume (voxels).
MAX_SIDE = 512


@dataclass
class Volume:
    """Bone density counters (uint8) on a grid of cubic voxels of side ``voxel`` (m)."""

    density: np.ndarray
    voxel: float
    origin: np.ndarray = field(default_factory=lambda: np.zeros(3))
    rho_full: float = 2000.0  # kg/m^3 represented by a counter of 255

    def __post_init__(self):
        d = np.asarray(self.density)
        if d.ndim != 3 or d.dtype != np.uint8:
            raise JassyError(f"Volume.density: expected a 3-D uint8 array, got {d.dtype} {d.shape}")
        if max(d.shape) > MAX_SIDE or min(d.shape) < 1:
            raise JassyError(f"Volume.density: sides must be 1..{MAX_SIDE} voxels, got {d.shape}")
        if not (np.isfinite(self.voxel) and self.voxel > 0):
            raise JassyError(f"Volume.voxel: expected a size > 0 m, got {self.voxel!r}")
        if not (np.isfinite(self.rho_full) and self.rho_full > 0):
            raise JassyError(f"Volume.rho_full: expected a density > 0 kg/m^3, got {self.rho_full!r}")
        self.density = np.ascontiguousarray(d)
        self.voxel = float(self.voxel)
        self.origin = np.asarray(self.origin, dtype=np.float64).reshape(3)

    @property
    def shape(self) -> tuple[int, int, int]:
        return self.density.shape

    @property
    def mass_per_count(self) -> float:
        """Mass (kg) of one counter unit in one voxel."""
        return self.rho_full / 255.0 * self.voxel**3

    def total_mass(self) -> float:
        return float(self.density.sum(dtype=np.int64)) * self.mass_per_count

    def to_grid(self, x) -> np.ndarray:
        """World position (m) -> grid coordinates (voxel units, voxel centres at integers)."""
        return (np.asarray(x, dtype=np.float64) - self.origin) / self.voxel

    def to_world(self, g) -> np.ndarray:
        return self.origin + self.voxel * np.asarray(g, dtype=np.float64)

    def save(self, path: str | os.PathLike) -> None:
        """Write an NPZ with density, voxel, origin and rho_full."""
        with open(path, "wb") as fh:
            np.savez_compressed(
                fh, density=self.density, voxel=self.voxel, origin=self.origin, rho_full=self.rho_full
            )

    @classmethod
    def load(
        cls,
        path: str | os.PathLike,
        shape: tuple[int, int, int] | None = None,
        voxel: float | None = None,
        rho_full: float = 2000.0,
    ) -> Volume:
        """Load an NPZ (keys density, voxel[, origin, rho_full]) or a raw uint8 file
        (C order, x slowest; ``shape`` and ``voxel`` required)."""
        path = Path(path)
        if path.suffix.lower() == ".npz":
            with np.load(path) as z:
                if "density" not in z or "voxel" not in z:
                    raise JassyError(f"{path}: expected arrays 'density' and 'voxel'")
                return cls(
                    z["density"].astype(np.uint8, copy=False),
                    float(z["voxel"]),
                    z["origin"] if "origin" in z else np.zeros(3),
                    float(z["rho_full"]) if "rho_full" in z else rho_full,
                )
        if shape is None or voxel is None:
            raise JassyError(f"{path}: a raw volume needs shape=(nx, ny, nz) and voxel=size in m")
        data = np.fromfile(path, dtype=np.uint8)
        if data.size != int(np.prod(shape)):
            raise JassyError(f"{path}: {data.size} bytes, expected {int(np.prod(shape))} for shape {shape}")
        return cls(data.reshape(shape), voxel, rho_full=rho_full)


def uniform_block(shape, voxel: float, level: int = 255, top: float | None = None) -> Volume:
    """A uniform slab of counter ``level`` filling z <= ``top`` (grid units; default all)."""
    d = np.zeros(shape, dtype=np.uint8)
    nz = shape[2]
    kmax = nz if top is None else int(np.floor(top)) + 1
    d[:, :, : max(0, min(nz, kmax))] = level
    return Volume(d, voxel)


def phantom(n: int = 256, voxel: float = 1.0e-4, seed: int = 0) -> Volume:
    """A layered temporal-bone-like phantom of n^3 voxels (z up, surface near the top).

    From the top: air (0), an outer cortical table (255, ~12 % of n), trabecular bone (a
    random porous network: 100-200 with pores of 0), an inner cortical table (255, ~8 %),
    a soft region (counter 25, dura-like) below it; inside the trabecular layer a few air
    cells (0, spheres) and a soft ellipsoid (40, a vessel-like canal). Deterministic in
    ``seed``. Works for n up to 512 (uses n^3 bytes plus a coarse float field).
    """
    if not (8 <= n <= MAX_SIDE):
        raise JassyError(f"phantom: n must be in [8, {MAX_SIDE}], got {n}")
    rng = np.random.default_rng(seed)
    d = np.zeros((n, n, n), dtype=np.uint8)
    z_top = int(0.85 * n)  # bone surface
    c_outer = max(2, int(0.12 * n))
    c_inner = max(2, int(0.08 * n))
    z_trab_top = z_top - c_outer
    z_inner_top = int(0.25 * n)
    z_inner_bot = z_inner_top - c_inner
    d[:, :, z_trab_top:z_top] = 255
    d[:, :, z_inner_bot:z_inner_top] = 255
    d[:, :, :z_inner_bot] = 25
    # trabecular network: a smooth random field on a coarse grid, thresholded, upsampled
    from scipy.ndimage import gaussian_filter

    f = 4 if n >= 64 else 2
    nc = -(-n // f)
    field_c = gaussian_filter(rng.standard_normal((nc, nc, nc)).astype(np.float32), 1.2, mode="wrap")
    field_c /= field_c.std()
    level = np.clip(150.0 + 60.0 * field_c, 100.0, 200.0).astype(np.uint8)
    level[field_c < -0.6] = 0  # pores (~27 % of the volume)
    trab = np.repeat(np.repeat(np.repeat(level, f, 0)[:n], f, 1)[:, :n], f, 2)[:, :, :n]
    d[:, :, z_inner_top:z_trab_top] = trab[:, :, z_inner_top:z_trab_top]
    # air cells and a soft canal inside the trabecular layer
    ii = np.arange(n, dtype=np.float32)
    span = max(1, z_trab_top - z_inner_top)
    for _ in range(4):
        c = np.array([rng.uniform(0.15, 0.85) * n, rng.uniform(0.15, 0.85) * n, z_inner_top + span * 0.5])
        r = rng.uniform(0.12, 0.3) * span
        _paint(d, ii, c, (r, r, r), 0)
    c = np.array([0.75 * n, 0.5 * n, z_inner_top + 0.35 * span])
    _paint(d, ii, c, (0.08 * n, 0.45 * n, 0.12 * span), 40)
    return Volume(d, voxel)


def _paint(d, ii, centre, radii, value) -> None:
    """Set voxels inside the axis-aligned ellipsoid (centre, radii) to ``value``."""
    lo = [max(0, int(np.floor(c - r))) for c, r in zip(centre, radii, strict=True)]
    hi = [min(d.shape[a], int(np.ceil(centre[a] + radii[a])) + 1) for a in range(3)]
    x = ((ii[lo[0] : hi[0]] - centre[0]) / radii[0])[:, None, None]
    y = ((ii[lo[1] : hi[1]] - centre[1]) / radii[1])[None, :, None]
    z = ((ii[lo[2] : hi[2]] - centre[2]) / radii[2])[None, None, :]
    mask = x * x + y * y + z * z <= 1.0
    d[lo[0] : hi[0], lo[1] : hi[1], lo[2] : hi[2]][mask] = value
