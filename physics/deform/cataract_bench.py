"""``bench_cataract``: step times of the cataract models (shape matching with many fragments,
erosion update, membrane step at ~2000 particles), with Horn vs SVD rotations as reference."""

from __future__ import annotations

import time

import numpy as np


def _median_us(fn, reps):
    fn()  # JIT warm-up
    t = []
    for _ in range(reps):
        t0 = time.perf_counter()
        fn()
        t.append(time.perf_counter() - t0)
    return float(np.median(t) * 1e6)


def _svd_rotations(p, q, k, size):
    """Reference: batched Kabsch (numpy SVD with the reflection fix) for k equal-size sets."""
    a = p.reshape(k, size, 3)
    b = q.reshape(k, size, 3)
    a = a - a.mean(1, keepdims=True)
    b = b - b.mean(1, keepdims=True)
    u, _, vt = np.linalg.svd(np.einsum("kia,kib->kab", a, b))
    d = np.sign(np.linalg.det(np.einsum("kba,kcb->kac", vt, u)))
    vt[:, 2, :] *= d[:, None]
    return np.einsum("kba,kcb->kac", vt, u)


def bench_cataract(quick: bool = False) -> list[dict]:
    """Rows: case, size, median time per call (us) and, for the rotations, the ratio Horn /
    numpy-SVD on the same sets. Cases: 'rotations' (K sets of 8 points), 'shape_matching'
    (one step of K falling 8-particle fragments in a bag), 'erode' (one erosion call on a
    lens, including fragment recognition and the shape-matching rebuild), 'membrane' (one
    1 ms step of a ~2000-particle sheet, with its substep count)."""
    from physics.deform.fragments import FragmentParams, FragmentSim, lens_mesh
    from physics.deform.membrane import grid_mesh, membrane_from_mesh
    from physics.deform.shape_matching import Boundaries, ShapeMatching, horn_rotations

    reps = 20 if quick else 200
    rng = np.random.default_rng(0)
    rows = []
    for k in (100,) if quick else (100, 1000):
        size = 8
        p = rng.normal(size=(k * size, 3))
        q = p + 0.1 * rng.normal(size=p.shape)
        starts = np.arange(k + 1) * size
        t_h = _median_us(lambda p=p, q=q, s=starts: horn_rotations(p, q, None, s), reps)
        t_s = _median_us(lambda p=p, q=q, k=k, size=size: _svd_rotations(p, q, k, size), reps)
        rows.append(
            {"case": "rotations", "size": k, "median_us": t_h, "reference_us": t_s, "ratio": t_h / t_s}
        )
    for k in (100,) if quick else (100, 1000):
        cube = np.array([[i, j, m] for i in (0, 1) for j in (0, 1) for m in (0, 1)], float) * 0.5e-3
        rest = (cube[None] + rng.uniform(-4e-3, 4e-3, (k, 1, 3))).reshape(-1, 3)
        sm = ShapeMatching(
            rest, np.full(len(rest), 1e-7), np.repeat(np.arange(k), 8), radius=0.1e-3, damping=1.0
        )
        st = sm.initial_state()
        bag = Boundaries(bag_radius=6e-3)
        t = _median_us(
            lambda sm=sm, st=st, bag=bag: sm.step(st, 1e-3, gravity=(0, 0, -9.81), boundaries=bag), reps
        )
        rows.append({"case": "shape_matching", "size": k, "median_us": t})
    sim = FragmentSim(
        lens_mesh(spacing=0.8e-3 if quick else 0.5e-3), FragmentParams(), Boundaries(bag_radius=6e-3)
    )
    path = iter(np.column_stack([np.linspace(-5e-3, 5e-3, 10 * reps + 10), np.zeros((10 * reps + 10, 2))]))
    rows.append(
        {
            "case": "erode",
            "size": int(sim.mesh.tets.shape[0]),
            "median_us": _median_us(lambda: sim.erode(next(path), 0.7e-3, 30), reps),
        }
    )
    pts, tri = grid_mesh(45, 45, 9e-3, 9e-3)
    mem = membrane_from_mesh(
        pts,
        tri,
        thickness=15e-6,
        stiffness=0.01,
        tear_strain=0.25,
        viscosity=20.0,
        anchored=np.flatnonzero(pts[:, 1] == 0),
    )
    mst = mem.initial_state()
    t = _median_us(lambda: mem.step(mst, 1e-3), reps)
    nsub = int(np.ceil(1e-3 / mem.max_substep))
    rows.append(
        {
            "case": "membrane",
            "size": len(pts),
            "springs": int(mem.springs.shape[0]),
            "substeps": nsub,
            "median_us": t,
            "per_substep_us": t / nsub,
        }
    )
    return rows


def print_cataract(rows: list[dict]) -> None:
    print("cataract models: median wall time per call, one core")
    for r in rows:
        extra = f", SVD reference {r['reference_us']:.0f} us (ratio {r['ratio']:.2f})" if "ratio" in r else ""
        if r["case"] == "membrane":
            extra = f", {r['springs']} springs, {r['substeps']} substeps ({r['per_substep_us']:.1f} us each)"
        print(f"  {r['case']:15s} size {r['size']:5d}: {r['median_us']:.0f} us{extra}")


if __name__ == "__main__":
    import sys

    print_cataract(bench_cataract(quick="--quick" in sys.argv))
