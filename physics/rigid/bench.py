"""``bench_rigid``: world steps per second of settled piles of 10, 100 and 1000 bodies in
contact (the wok scene's rows are added by patches.wok_bench: physics does not import
patches)."""

from __future__ import annotations

import math
import time

import numpy as np


def pile(n: int, seed: int = 0, h: float = 1e-3):
    """n spheres and boxes (radius/half-size 2 cm) dropped in a square pen of four walls on a
    floor, settled for 1 s: a (world, state) with every body in contact."""
    from physics.rigid.shapes import Box, Plane, Sphere
    from physics.rigid.world import MATERIALS, Body, Placement, StepParams, World, simulate

    rng = np.random.default_rng(seed)
    world = World(StepParams(h=h, iterations=20))
    side = 0.05 * math.ceil(math.sqrt(n / 2.0)) + 0.05
    wood = MATERIALS["wood"]
    world.add(Body("floor", Plane((0, 0, 1), 0.0), wood, kind="static"))
    for k, (normal, offset) in enumerate(
        (((1, 0, 0), -side), ((-1, 0, 0), -side), ((0, 1, 0), -side), ((0, -1, 0), -side))
    ):
        world.add(Body(f"wall{k}", Plane(normal, offset), wood, kind="static"))
    per_layer = max(1, int((2 * side / 0.05) ** 2))
    for i in range(n):
        layer, cell = divmod(i, per_layer)
        cols = int(2 * side / 0.05)
        x = -side + 0.025 + 0.05 * (cell % cols)
        y = -side + 0.025 + 0.05 * (cell // cols)
        shape = Sphere(0.02) if i % 2 == 0 else Box((0.018, 0.018, 0.018))
        place = Placement(position=(x, y, 0.03 + 0.05 * layer), quaternion=tuple(rng.normal(size=4)))
        world.add(Body(f"b{i}", shape, MATERIALS["plastic"]), place)
    state = simulate(world, 1.0, sample_every=0).state
    return world, state


def bench_rigid(
    sizes=(10, 100, 1000), seconds: float = 0.5, quick: bool = False, progress=lambda message: None
) -> list[dict]:
    """Rows: bodies, contacts per step, PGS sweeps per solve, steps/s and real-time factor of
    each settled pile. ``progress(message)`` is told which case starts."""
    from physics.rigid.world import simulate

    if quick:
        sizes, seconds = tuple(s for s in sizes if s <= 100), 0.2
    rows = []
    for n in sizes:
        progress(f"pile of {n} bodies, {seconds:g} s")
        world, state = pile(n)
        t0 = time.perf_counter()
        result = simulate(world, seconds, state=state, sample_every=0)
        wall = time.perf_counter() - t0
        steps = int(round(seconds / world.params.h))
        rows.append(
            {
                "case": f"pile of {n}",
                "bodies": n,
                "contacts_per_step": result.stats["contacts"] / max(result.stats["solves"], 1),
                "sweeps_per_solve": result.stats["sweeps"] / max(result.stats["solves"], 1),
                "steps_per_s": steps / wall,
                "real_time_factor": seconds / wall,
            }
        )
    return rows


def print_rigid(rows: list[dict]) -> None:
    print(f"{'case':32s} {'contacts/step':>14s} {'steps/s':>10s} {'x real time':>12s}")
    for r in rows:
        contacts = f"{r['contacts_per_step']:.0f}" if "contacts_per_step" in r else "-"
        steps = f"{r['steps_per_s']:.0f}" if "steps_per_s" in r else "-"
        split = f"  (physics {r['physics_s']:.2f} s, sound {r['sound_s']:.2f} s)" if "sound_s" in r else ""
        if "sweeps_per_solve" in r:
            split = f"  ({r['sweeps_per_solve']:.1f} PGS sweeps per solve)"
        print(f"{r['case']:32s} {contacts:>14s} {steps:>10s} {r['real_time_factor']:12.1f}{split}")
