"""``bench_rod_contact``: step time of a long mixed rod resting on pegs, split into detection /
assembly / Delassus / DFCP solve, against the direct Delassus (2c solves with one band LU of the
whole KKT matrix) in the same run."""

from __future__ import annotations

import time

import numpy as np

from jassy.errors import JassyError


def peg_scene(
    n: int = 1000,
    contacts: int = 100,
    length: float = 1.0,
    radius: float = 5e-4,
    peg_radius: float = 2e-3,
    mu: float = 0.3,
    schur: bool = True,
):
    """(RodSystem, state): a horizontal MixedRod (n elements, clamped at x = 0, EI 1e-2 N m^2,
    rho_A 0.1 kg/m) just touching ``contacts`` static pegs under element midpoints spread evenly
    along it; gravity presses it onto them, so every peg is an active frictional contact.
    ``schur``: Delassus by the partitioned Schur complement (else the direct 2c KKT solves)."""
    from physics.rod.mixed import MixedRod
    from physics.rod.model import RodModel
    from physics.rod.system import Disk, RodSystem

    if not (isinstance(contacts, int) and 1 <= contacts <= n):
        raise JassyError(f"contacts: expected an integer in [1, n = {n}], got {contacts!r}")
    rod = MixedRod(RodModel(n, length, 1e-2, 0.1, radius=radius))
    el = length / n
    elems = np.linspace(n / contacts, n - 1, contacts).astype(int)
    pegs = [Disk(((e + 0.5) * el, -radius - peg_radius), peg_radius) for e in elems]
    margin = min(1e-5, 0.1 * el * el / peg_radius)
    system = RodSystem([rod], obstacles=pegs, mu=mu, margin=margin, tol=1e-8, schur=schur)
    return system, system.initial_state()


def _run(system, state, steps, h):
    rows = []
    for _ in range(steps):
        t0 = time.perf_counter()
        state, info = system.step(state, h)
        rows.append(
            {
                "total": time.perf_counter() - t0,
                **info.timings,
                "active": int(np.sum(info.r[:, 0] > 0)),
                "sweeps": info.iterations,
                "residual": info.residual,
            }
        )
    return rows


def bench_rod_contact(
    n: int = 1000,
    contacts: int = 100,
    steps: int = 20,
    h: float = 1e-3,
    reference_steps: int = 3,
    quick: bool = False,
) -> dict:
    """Median step time (ms) of ``peg_scene(n, contacts)`` over ``steps`` steps of h (s), after two
    warm-up steps (JIT, contacts settle), split into detection / assembly (rod linear systems,
    constraint and contact rows) / Delassus (factorisations, Schur complement, W) / DFCP solve, with
    the active-contact count, PGS sweeps and the largest natural-map residual; and the same scene with
    the direct Delassus (2c solves with one band LU of the whole KKT matrix) over ``reference_steps``
    steps from the same state, as the reference (``direct_step_ms``, ``speedup``). ``quick``: 5 steps
    and 1 reference step."""
    if quick:
        steps, reference_steps = 5, 1
    system, state = peg_scene(n, contacts)
    for _ in range(2):
        state, _ = system.step(state, h)
    rows = _run(system, state, steps, h)
    med = {k: float(np.median([r[k] for r in rows])) for k in rows[0]}
    out = {
        "n": n,
        "contacts": contacts,
        "steps": steps,
        "step_ms": med["total"] * 1e3,
        "detect_ms": med["detect"] * 1e3,
        "assemble_ms": med["assemble"] * 1e3,
        "delassus_ms": med["delassus"] * 1e3,
        "dfcp_ms": med["solve"] * 1e3,
        "active_contacts": int(med["active"]),
        "median_sweeps": med["sweeps"],
        "max_residual": float(max(r["residual"] for r in rows)),
        "target_ms": 10.0,
    }
    if reference_steps:
        direct, _ = peg_scene(n, contacts, schur=False)
        ref = _run(direct, state, reference_steps, h)
        out["direct_step_ms"] = float(np.median([r["total"] for r in ref])) * 1e3
        out["direct_delassus_ms"] = float(np.median([r["delassus"] for r in ref])) * 1e3
        out["speedup"] = out["direct_step_ms"] / out["step_ms"]
    return out


def print_rod_contact(row: dict) -> None:
    print(f"rod contact step: {row['n']} elements, {row['active_contacts']} active contacts")
    print(
        f"  step {row['step_ms']:.1f} ms (target {row['target_ms']:.0f} ms): "
        f"detect {row['detect_ms']:.1f}, assemble {row['assemble_ms']:.1f}, "
        f"Delassus {row['delassus_ms']:.1f}, DFCP {row['dfcp_ms']:.2f} ms; "
        f"{row['median_sweeps']:.0f} sweeps, residual <= {row['max_residual']:.1e}"
    )
    if "direct_step_ms" in row:
        print(
            f"  direct Delassus reference: step {row['direct_step_ms']:.1f} ms "
            f"-> speed-up {row['speedup']:.1f}x"
        )


if __name__ == "__main__":
    print_rod_contact(bench_rod_contact())
