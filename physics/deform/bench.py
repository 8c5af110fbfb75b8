"""``bench_deform``: Green's function precomputation and haptic update times (BEM + CMA)."""

from __future__ import annotations

import tempfile
import time

import numpy as np


def _median_us(fn, reps: int) -> float:
    t = np.empty(reps)
    for i in range(reps):
        t0 = time.perf_counter()
        fn(i)
        t[i] = time.perf_counter() - t0
    return float(np.median(t) * 1e6)


def bench_deform(quick: bool = False, contacts=(1, 5, 10), reps: int = 2000) -> list[dict]:
    """Rows of timings on soft balls (icospheres, radius 5 cm, bottom cap fixed, E = 200 kPa,
    nu = 0.45): for subdivisions 3 and 4 (642 / 2562 vertices; quick: 2 and 3) the BEM
    assembly time, the cold Green's function precomputation (assembly + LU + solve + cache
    write) and the cache load, in a temporary cache directory; then at the largest mesh,
    for s contact vertices (nearest the top), the median haptic update with the contact
    set unchanged (set check + O(s^2) solve), with the set changed (gather + LU + solve),
    the O(ns) full deformation, headroom = 1 ms / update, and the median step of the
    sliding poke gesture (PokeSim.step incl. contact detection)."""
    from physics.deform.bem import SOFT_GEL_DENSITY, assemble
    from physics.deform.capacitance import CapacitanceSolver
    from physics.deform.greens import reference_greens
    from physics.deform.haptic import PokeSim, poke_path, run_poke, soft_ball
    from physics.modal.materials import Material

    material = Material("soft gel", 2e5, 0.45, SOFT_GEL_DENSITY)
    rows = []
    greens = None
    with tempfile.TemporaryDirectory() as cache:
        for sub in (2, 3) if quick else (3, 4):
            V, F, fixed = soft_ball(0.05, sub)
            t0 = time.perf_counter()
            assemble(V, F, material)
            t_asm = time.perf_counter() - t0
            cold = reference_greens(V, F, material, fixed, cache_dir=cache)
            warm = reference_greens(V, F, material, fixed, cache_dir=cache)
            rows.append(
                {
                    "case": "greens",
                    "vertices": int(V.shape[0]),
                    "free": int(cold.free.size),
                    "assemble_s": t_asm,
                    "precompute_s": cold.seconds,
                    "load_s": warm.seconds,
                    "loaded": bool(warm.from_cache and not cold.from_cache),
                    "xi_mb": cold.xi.nbytes / 2**20,
                }
            )
            greens = warm
            del cold
        rng = np.random.default_rng(0)
        V = greens.vertices
        order = greens.free[np.argsort(np.linalg.norm(V[greens.free] - V[np.argmax(V[:, 2])], axis=1))]
        solver = CapacitanceSolver(greens, 0.0, max(contacts) + 1)
        for s in contacts:
            sets = [np.sort(order[:s]), np.sort(order[1 : s + 1])]
            disp = rng.normal(0.0, 1e-3, (s, 3))
            solver.set_contacts(sets[0])
            unchanged = _median_us(
                lambda i, a=sets[0], d=disp: (solver.set_contacts(a), solver.solve(d)), reps
            )
            changed = _median_us(
                lambda i, ss=sets, d=disp: (solver.set_contacts(ss[i % 2]), solver.solve(d)), reps
            )
            forces = solver.solve(disp)
            solver.displacements(forces)
            full = _median_us(lambda i, f=forces: solver.displacements(f), max(20, reps // 20))
            rows.append(
                {
                    "case": "update",
                    "vertices": greens.n,
                    "contacts": s,
                    "unchanged_us": unchanged,
                    "changed_us": changed,
                    "deformation_us": full,
                    "headroom": 1000.0 / unchanged,
                }
            )
        sim = PokeSim(greens, 0.015)
        res = run_poke(sim, poke_path(0.05, 0.015, 0.008), 4.0)
        st = res.step_seconds * 1e6
        rows.append(
            {
                "case": "poke",
                "vertices": greens.n,
                "steps": int(st.size),
                "max_contacts": int(res.counts.max()),
                "median_us": float(np.median(st)),
                "p99_us": float(np.percentile(st, 99)),
                "refactors": int(res.refactored.sum()),
            }
        )
    return rows


def print_deform(rows: list[dict]) -> None:
    print("deform: BEM Green's functions and capacitance-matrix haptics (soft ball, bottom cap fixed)")
    for r in rows:
        if r["case"] == "greens":
            print(
                f"  greens {r['vertices']} vertices: assemble {r['assemble_s']:.2f} s, precompute "
                f"{r['precompute_s']:.2f} s (Xi {r['xi_mb']:.0f} MB), cache load {r['load_s']:.3f} s"
            )
        elif r["case"] == "update":
            print(
                f"  update {r['vertices']} vertices, s={r['contacts']}: {r['unchanged_us']:.1f} us (set "
                f"unchanged, {r['headroom']:.0f}x headroom at 1 kHz), {r['changed_us']:.1f} us (changed), "
                f"full deformation {r['deformation_us']:.0f} us"
            )
        else:
            print(
                f"  poke gesture {r['vertices']} vertices: {r['steps']} steps, "
                f"median {r['median_us']:.1f} us, "
                f"p99 {r['p99_us']:.0f} us, up to {r['max_contacts']} contacts, {r['refactors']} refactors"
            )


if __name__ == "__main__":
    import sys

    print_deform(bench_deform(quick="--quick" in sys.argv))
