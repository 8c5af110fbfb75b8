"""``bench_rod``: time of one contact-free implicit step against n, chained vs mixed model.

Rows: model ("chained" dense LU; "mixed": MixedRod.step, the KKT matrix assembled per element
straight into band storage and factored by a banded LU; "mixed_splu": the same step through the
sparse ``linear_system`` and SuperLU, the reference measured in the same run), n, ndof, median step
time (ms) and, for the mixed rows, the ratio splu / banded. Every step carries the previous step's
constraint impulses (geometric stiffness), as ``step`` does. Final rows give, per model, the
fitted log-log slope of step time against n (1 = linear) over all sizes and over n >= 100 (where
the fixed per-step overhead no longer dominates). The rod is a heavy cantilever (Gamma = 10)
stepped from rest at h = 1 ms. The chained model is run up to n = ``chained_max`` (O(n^3)). The
contact row of the talk (1000 elements, 100 contacts) is physics.rod.contact_bench.
"""

from __future__ import annotations

import time

import numpy as np

from physics.rod.chained import ChainedRod
from physics.rod.mixed import MixedRod
from physics.rod.model import RodModel


def _time_steps(form, method: str | None, steps: int, h: float = 1e-3) -> float:
    """Median time (ms) of a step: ``form.step``, or with ``method`` the sparse system and that
    kkt_factor method."""
    state = form.initial_state()
    times = []
    for _ in range(steps + 2):
        t0 = time.perf_counter()
        if method is None:
            state = form.step(state, h)
        else:
            A, b, C, c = form.linear_system(state, h)
            v, lam = form.kkt_factor(A, C, method=method).solve(b, c)
            state = form.advance(state, v, h, lam)
        times.append(time.perf_counter() - t0)
    return float(np.median(times[2:]) * 1e3)


def _slope(rows: list[dict]) -> float:
    n = np.array([r["n"] for r in rows], dtype=float)
    t = np.array([r["step_ms"] for r in rows])
    return float(np.polyfit(np.log(n), np.log(t), 1)[0])


def bench_rod(
    sizes=(10, 30, 100, 300, 1000, 2000), quick: bool = False, chained_max: int = 300
) -> list[dict]:
    """Median step time (ms) per model and n, SuperLU/banded ratio, fitted log-log slopes."""
    if quick:
        sizes = tuple(s for s in sizes if s <= 100)
    steps = 5 if quick else 20
    rows = []
    for n in sizes:
        model = RodModel(n=int(n), length=1.0, EI=1.0, rho_A=1.0, gravity=10.0)
        if n <= chained_max:
            form = ChainedRod(model)
            rows.append(
                {
                    "model": "chained",
                    "n": int(n),
                    "ndof": form.ndof,
                    "step_ms": _time_steps(form, None, steps),
                }
            )
        form = MixedRod(model)
        banded = _time_steps(form, None, steps)
        ref = _time_steps(form, "splu", steps)
        rows.append(
            {
                "model": "mixed",
                "n": int(n),
                "ndof": form.ndof,
                "step_ms": banded,
                "splu_over_banded": ref / banded,
            }
        )
        rows.append({"model": "mixed_splu", "n": int(n), "ndof": form.ndof, "step_ms": ref})
    for name in ("chained", "mixed", "mixed_splu"):
        for n_min in (0, 100):  # all sizes, and the range where per-step overhead no longer dominates
            sel = [r for r in rows if r["model"] == name and r.get("n", -1) >= n_min]
            if len(sel) > 1:
                rng = [sel[0]["n"], sel[-1]["n"]]
                rows.append({"model": name, "fit": "loglog_slope", "slope": _slope(sel), "n_range": rng})
    return rows


def print_rod(rows: list[dict]) -> None:
    print("rod: one implicit step (heavy cantilever, h = 1 ms), median over steps")
    for r in rows:
        if "slope" in r:
            print(f"  {r['model']:10s} log-log slope of time vs n over n = {r['n_range']}: {r['slope']:.2f}")
        else:
            extra = f"  (splu / banded = {r['splu_over_banded']:.2f})" if "splu_over_banded" in r else ""
            print(f"  {r['model']:10s} n = {r['n']:5d}: {r['step_ms']:8.3f} ms{extra}")


if __name__ == "__main__":
    print_rod(bench_rod())
