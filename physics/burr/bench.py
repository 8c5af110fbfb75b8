"""``bench_burr``: per-update time of the haptic loop on a phantom, octree vs brute force."""

from __future__ import annotations

import time

import numpy as np


def bench_burr(n: int = 256, seconds: float = 3.0, rate: float = 1000.0, radius: float = 1.5e-3,
               voxel: float = 1e-4, leaf: int = 4, push: float = 2.0,
    compare: bool = True) -> list[dict]:  # fmt: skip
    """Run the constant-force descent (in contact and eroding) for ``seconds`` of simulated
    time on an n^3 phantom, with the octree (partial-volume leaf ``leaf``; and ``leaf=1``,
    exact) and, if ``compare``, the brute-force voxel sum, each on a fresh copy of the
    phantom. Returns rows: method, leaf, steps, median/p99/max update time (us), achievable
    rate (1/median, Hz), final depth (mm). The first 50 steps (JIT warm-up) are excluded."""
    from physics.burr.loop import BurrParams, descent_experiment
    from physics.burr.volume import phantom

    base = phantom(n, voxel)
    configs = [("octree", leaf), ("octree", 1)] + ([("brute", 1)] if compare else [])
    rows = []
    for method, lf in configs:
        vol = type(base)(base.density.copy(), base.voxel, base.origin, base.rho_full)
        params = BurrParams(radius=radius, method=method, leaf=lf)
        warm = type(base)(base.density[:64, :64, :64].copy(), base.voxel)
        descent_experiment(warm, 0.05, push, rate=rate, params=params)  # JIT warm-up
        t0 = time.perf_counter()
        res, surface, sim = descent_experiment(vol, seconds, push, rate=rate, params=params)
        wall = time.perf_counter() - t0
        st = res.step_seconds[50:] * 1e6
        depth = surface - (res.centres[-1, 2] - radius)
        rows.append(
            {
                "method": method,
                "leaf": lf,
                "n": n,
                "steps": int(res.times.size),
                "median_us": float(np.median(st)),
                "p99_us": float(np.percentile(st, 99)),
                "max_us": float(np.max(st)),
                "rate_hz": float(1e6 / np.median(st)),
                "depth_mm": float(depth * 1e3),
                "wall_s": wall,
            }
        )
    return rows


def print_burr(rows: list[dict]) -> None:
    print("burr haptic loop: constant-force descent, eroding, one core")
    for r in rows:
        print(
            f"  {r['n']}^3 {r['method']:6s} leaf {r['leaf']}: {r['steps']} steps, "
            f"median {r['median_us']:.0f} us, "
            f"p99 {r['p99_us']:.0f} us, max {r['max_us']:.0f} us -> {r['rate_hz']:.0f} Hz; "
            f"depth {r['depth_mm']:.2f} mm"
        )


if __name__ == "__main__":
    import sys

    print_burr(bench_burr(int(sys.argv[1]) if len(sys.argv) > 1 else 256))
