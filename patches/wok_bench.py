"""The wok scene's rows of ``jassy bench rigid``: its physics alone and its full render
against real time (rows in the format of physics.rigid.bench.print_rigid)."""

from __future__ import annotations

import os
import tempfile
import time

from jassy.engines.offline import OFFLINE_BLOCK
from patches.wok import render_wok, simulate_wok

#: Seconds of the wok rendered once before timing (loads the compiled kernels).
WARM_UP = 0.3


def wok_rows(duration: float, repeats: int = 3) -> list[dict]:
    """The wok's physics alone and its full render (physics, events, sound, haptic and CSV
    files) at the CLI's default block (OFFLINE_BLOCK) and at 64 frames, the best of
    ``repeats`` runs, pinned to one core."""
    cores = os.sched_getaffinity(0)
    os.sched_setaffinity(0, {min(cores)})
    try:
        with tempfile.TemporaryDirectory() as tmp:
            wav, force = os.path.join(tmp, "wok.wav"), os.path.join(tmp, "force.csv")
            render_wok(wav, force, duration=WARM_UP)
            physics = []
            for _ in range(repeats):
                t0 = time.perf_counter()
                world, _, _ = simulate_wok(duration)
                physics.append(time.perf_counter() - t0)
            bodies = len(world.bodies)
            rows = [
                {
                    "case": "wok physics",
                    "bodies": bodies,
                    "steps_per_s": duration / world.params.h / min(physics),
                    "real_time_factor": duration / min(physics),
                }
            ]
            for block in (OFFLINE_BLOCK, 64):
                best = None
                for _ in range(repeats):
                    t0 = time.perf_counter()
                    summary = render_wok(wav, force, duration=duration, block=block)
                    wall = time.perf_counter() - t0
                    if best is None or wall < best[0]:
                        best = (wall, summary["physics_seconds"])
                rows.append(
                    {
                        "case": f"wok render, block {block}",
                        "bodies": bodies,
                        "real_time_factor": duration / best[0],
                        "physics_s": best[1],
                        "sound_s": best[0] - best[1],
                    }
                )
    finally:
        os.sched_setaffinity(0, cores)
    return rows
