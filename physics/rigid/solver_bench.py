"""``bench_solvers``: timings of the rigid-body solvers (ABA vs dense, Lemke, PGS), one core.

Contact problems are synthetic but physical in structure: c contacts between random pairs of
nb unit-mass, unit-inertia bodies, W = J M^-1 J^T with random 3x6 Jacobian blocks (so W is
sparse when nb ~ c), free velocity b with every normal approaching (b_N in [-2, -1] m/s) and
random tangential slip. Chains are uniform-rod pendulum chains at random states.
"""

from __future__ import annotations

import time

import numba
import numpy as np
import scipy.sparse as sp

from jassy.jit import drop_stale_cache
from physics.rigid import aba as aba_kernels
from physics.rigid.aba import aba_into, new_aba_data
from physics.rigid.articulated import aba, dense_forward_dynamics, pendulum_chain
from physics.rigid.lcp import lemke
from physics.rigid.pgs import solve_friction_pgs

drop_stale_cache(__file__, [aba_kernels])  # its cache holds copies of aba's kernels


def _best_time(fn, repeats: int) -> float:
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


@numba.njit(cache=True)
def _aba_calls(model, data, q, qd, tau, fext, calls: int) -> float:
    """``calls`` evaluations of the compiled ABA kernel (its cost without any Python)."""
    total = 0.0
    for _ in range(calls):
        aba_into(model, data, q, qd, tau, fext)
        total += data.qdd[0]
    return total


def _aba_row(n: int, rng, rounds: int = 5) -> dict:
    """ABA at n links: the compiled kernel (called in a numba loop), the public ``aba`` and
    Pinocchio's ``aba`` (when installed), CPU time per call, the best of ``rounds``
    interleaved rounds; the dense CRBA + RNEA + Cholesky route as the accuracy reference."""
    from physics.rigid.peers import pinocchio_aba, pinocchio_chain

    ch = pendulum_chain(n)
    q, qd, tau = rng.uniform(-1, 1, (3, n))
    fext, data = np.zeros((n, 6)), new_aba_data(n)
    qa, qdn = aba(ch, q, qd, tau), dense_forward_dynamics(ch, q, qd, tau)  # JIT warm-up
    _aba_calls(ch.model, data, q, qd, tau, fext, 1)
    reference = pinocchio_chain(ch)
    calls = max(20, 200_000 // n)
    best = {"kernel": np.inf, "public": np.inf, "pinocchio": np.inf}
    for _ in range(rounds):
        t0 = time.process_time()
        _aba_calls(ch.model, data, q, qd, tau, fext, calls)
        best["kernel"] = min(best["kernel"], (time.process_time() - t0) / calls)
        t0 = time.process_time()
        for _ in range(calls):
            aba(ch, q, qd, tau)
        best["public"] = min(best["public"], (time.process_time() - t0) / calls)
        if reference is not None:
            t0 = time.process_time()
            for _ in range(calls):
                pinocchio_aba(reference, q, qd, tau)
            best["pinocchio"] = min(best["pinocchio"], (time.process_time() - t0) / calls)
    t_dense = _best_time(lambda: dense_forward_dynamics(ch, q, qd, tau), 3)
    row = {"solver": "aba", "n": n, "aba_us": best["public"] * 1e6, "kernel_us": best["kernel"] * 1e6,
           "dense_us": t_dense * 1e6, "ratio": t_dense / best["public"],
           "max_diff": float(np.abs(qa - qdn).max())}  # fmt: skip
    if reference is not None:
        row["pinocchio_us"] = best["pinocchio"] * 1e6
        row["pinocchio_max_diff"] = float(np.abs(qa - pinocchio_aba(reference, q, qd, tau)).max())
    return row


def _contact_problem(c: int, nb: int, seed: int = 0, rows: int = 3):
    """Sparse Delassus W (rows*c square, CSR), free velocity b (rows*c,) of a random contact set.
    rows = 3: (n, t1, t2) per contact; rows = 1: normals only."""
    rng = np.random.default_rng(seed)
    pairs = np.array([rng.choice(nb, 2, replace=False) for _ in range(c)])
    blocks = rng.standard_normal((c, 2, rows, 6))
    r_idx = np.repeat(np.arange(rows * c).reshape(c, 1, rows, 1), 2, axis=1) * np.ones((1, 1, 1, 6), int)
    c_idx = (6 * pairs[:, :, None, None] + np.arange(6)) * np.ones((1, 1, rows, 1), int)
    J = sp.csr_matrix((blocks.ravel(), (r_idx.ravel(), c_idx.ravel())), shape=(rows * c, 6 * nb))
    W = (J @ J.T).tocsr()
    b = rng.uniform(-1.0, 1.0, (c, rows))
    b[:, 0] = -1.0 - rng.random(c)
    return W, b.ravel()


def bench_solvers(quick: bool = False) -> list[dict]:
    """Rows (dicts, key "solver"):
    - "aba": n links; the compiled ABA kernel, the public ``aba`` and the dense (CRBA + RNEA +
      Cholesky) forward dynamics (us per call), ratio dense/aba, max |qdd_aba - qdd_dense|, and
      Pinocchio's ABA (us, max difference) where installed; n = 10, 100, 300, 1000 (quick: 10, 100).
    - "lemke": frictionless contact LCP on c = 10, 50, 100 contacts (quick: 10, 50): time (ms),
      pivots, complementarity error max(|z w|, -z, -w).
    - "pgs": frictional PGS (mu = 0.5, tol 1e-8, max 10000 sweeps) on c = 10, 100, 1000
      contacts (quick: 10, 100), dense and sparse W: time (ms), sweeps, residual, us per sweep."""
    rows = []
    rng = np.random.default_rng(1)
    for n in (10, 100) if quick else (10, 100, 300, 1000):
        rows.append(_aba_row(n, rng))
    for c in (10, 50) if quick else (10, 50, 100):
        W, b = _contact_problem(c, max(2, c // 2), seed=c, rows=1)
        M = W.toarray()
        lemke(M, b)
        res = lemke(M, b)
        t = _best_time(lambda M=M, b=b: lemke(M, b), 5)
        err = max(float(np.abs(res.z * res.w).max()), float(-res.z.min()), float(-res.w.min()))
        rows.append({"solver": "lemke", "contacts": c, "ms": t * 1e3, "pivots": res.pivots, "comp_err": err})
    for c in (10, 100) if quick else (10, 100, 1000):
        Ws, b = _contact_problem(c, c, seed=c)
        for kind, W in (("dense", Ws.toarray()), ("sparse", Ws)):
            solve_friction_pgs(W, b, 0.5, tol=1e-8, max_iter=2)  # JIT warm-up
            t0 = time.perf_counter()
            res = solve_friction_pgs(W, b, 0.5, tol=1e-8, max_iter=10000)
            t = time.perf_counter() - t0
            rows.append(
                {"solver": "pgs", "contacts": c, "W": kind, "ms": t * 1e3, "sweeps": res.iterations,
                 "residual": res.residual, "us_per_sweep": t * 1e6 / max(1, res.iterations)}
            )  # fmt: skip
    return rows


def print_solvers(rows: list[dict]) -> None:
    print("rigid solvers, one core")
    for r in rows:
        if r["solver"] == "aba":
            pin = "Pinocchio not installed (pip install pin)"
            if "pinocchio_us" in r:
                ratio_kernel = r["pinocchio_us"] / r["kernel_us"]
                ratio_public = r["pinocchio_us"] / r["aba_us"]
                pin = (
                    f"Pinocchio {r['pinocchio_us']:.2f} us -> kernel {ratio_kernel:.2f}x, public "
                    f"{ratio_public:.2f}x Pinocchio's speed (|dqdd| {r['pinocchio_max_diff']:.0e})"
                )
            elif r["n"] > 300:
                pin = "Pinocchio skipped (its Data needs O(n^3) memory: 1.8 GB at 300 joints)"
            print(
                f"  ABA n={r['n']}: kernel {r['kernel_us']:.2f} us, aba() {r['aba_us']:.2f} us; dense "
                f"CRBA+RNEA+Cholesky {r['dense_us']:.1f} us -> dense/ABA {r['ratio']:.1f}x; max |dqdd| "
                f"{r['max_diff']:.1e}; {pin}"
            )
        elif r["solver"] == "lemke":
            print(
                f"  Lemke {r['contacts']} contacts: {r['ms']:.2f} ms, {r['pivots']} pivots, "
                f"err {r['comp_err']:.1e}"
            )
        else:
            print(
                f"  PGS {r['contacts']} contacts ({r['W']} W): {r['ms']:.2f} ms, {r['sweeps']} sweeps "
                f"({r['us_per_sweep']:.1f} us/sweep), residual {r['residual']:.1e}"
            )
