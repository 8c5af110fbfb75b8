"""``bench_dfcp``: small 2D frictional contact problems solved by jassy's PGS and, where the
library is installed, by Siconos's NSGS (``physics.rod.peers``), timed in the same run.

Problems: c contacts with W = I + k B B^T / 2c (B standard normal (2c, 2c)), w standard normal,
mu uniform in [0.1, 1]: k = 0.05 converges in a few sweeps (a well-separated contact set),
k = 20 needs tens (strongly coupled contacts). Both solvers start from r = 0, stop at the same
tolerance 1e-10 on their own error measures, and their answers are compared on jassy's
natural-map residual. CPU time per solve, the best of interleaved rounds, Python call included
for both (Siconos through ctypes).
"""

from __future__ import annotations

import time
from functools import partial

import numpy as np

from physics.rod.dfcp import natural_map_residual, solve_dfcp
from physics.rod.peers import siconos_solver


def _problem(c: int, coupling: float, seed: int):
    rng = np.random.default_rng(seed)
    B = rng.standard_normal((2 * c, 2 * c))
    W = np.eye(2 * c) + coupling * (B @ B.T) / (2 * c)
    return W, rng.standard_normal(2 * c), rng.uniform(0.1, 1.0, c)


def _cpu_per_call(fn, calls: int) -> float:
    t0 = time.process_time()
    for _ in range(calls):
        fn()
    return (time.process_time() - t0) / calls


def bench_dfcp(
    cases=((10, 0.05), (10, 20.0), (100, 0.05)), rounds: int = 5, tol: float = 1e-10
) -> list[dict]:
    """One row per (contacts, coupling): us per solve and sweeps of each solver, the residual of
    each answer, and jassy's time over Siconos's."""
    rows = []
    for c, coupling in cases:
        W, w, mu = _problem(c, coupling, seed=c)
        ours = solve_dfcp(W, w, mu, tol=tol)
        peer = siconos_solver(W, w, mu, tol=tol)
        theirs = peer.solve() if peer is not None else None
        calls = max(50, 20000 // c)
        best_ours = best_theirs = np.inf
        ours_call = partial(solve_dfcp, W, w, mu, tol=tol)
        for _ in range(rounds):
            best_ours = min(best_ours, _cpu_per_call(ours_call, calls))
            if peer is not None:
                best_theirs = min(best_theirs, _cpu_per_call(peer.solve, calls))
        row = {"contacts": c, "coupling": coupling, "jassy_us": best_ours * 1e6,
               "jassy_sweeps": ours.iterations, "jassy_residual": ours.residual}  # fmt: skip
        if theirs is not None:
            row |= {"siconos_us": best_theirs * 1e6, "siconos_sweeps": theirs.iterations,
                    "siconos_residual": natural_map_residual(W, w, theirs.r, mu),
                    "max_impulse_diff": float(np.abs(theirs.r - ours.r).max()),
                    "time_ratio": best_ours / best_theirs}  # fmt: skip
        rows.append(row)
    return rows


def print_dfcp(rows: list[dict]) -> None:
    print("DFCP, small problems (CPU time per solve, Python call included; tol 1e-10)")
    for r in rows:
        line = (
            f"  {r['contacts']:4d} contacts, coupling {r['coupling']:5.2f}: jassy {r['jassy_us']:8.1f} us "
            f"({r['jassy_sweeps']} sweeps, residual {r['jassy_residual']:.0e})"
        )
        if "siconos_us" in r:
            line += (
                f"; Siconos NSGS {r['siconos_us']:8.1f} us ({r['siconos_sweeps']} sweeps, residual "
                f"{r['siconos_residual']:.0e}) -> jassy time / Siconos {r['time_ratio']:.2f}"
            )
        else:
            line += "; Siconos not installed (apt-get install libsiconos-numerics7)"
        print(line)
