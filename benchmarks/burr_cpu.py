"""CPU time of the burr's haptic update and of its moments call, this tree against other
checkouts, interleaved in one run.

Each round runs, once per tree (one child process each, that tree first on the path, its own
numba cache), the constant-force descent of ``jassy bench burr`` (256^3 phantom, 3000 steps
at 1 kHz, the burr in contact and eroding) with the octree at ``leaf`` 4 and 1, and times
every step in CPU time (``time.process_time``) and, in a call of its own just before each
step, the moments at that step's centre (``BurrSim.moments``, which a tree's step may or
may not call itself; it reads the voxels and blocks the step then reads, so the step is
timed with warm caches, alike in every tree); the first 50 steps (JIT warm-up) are left out.
Printed per tree and leaf: the medians over rounds of the per-round medians (us), the final
depth (mm), and the ratio to the first tree of each round.

    git archive 19a227f~1 | tar -x -C /tmp/burr_old   # the octree before the shallow refinement
    python benchmarks/burr_cpu.py . /tmp/burr_old --rounds 5
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time


def child(leaves: list[int]) -> list[dict]:
    """Run the descent at each leaf in this process; per-step CPU times in us."""
    import numpy as np

    from physics.burr import loop
    from physics.burr.volume import phantom

    base = phantom(256, 1e-4)
    rows = []
    for leaf in leaves:
        steps, moments = [], []
        step = loop.BurrSim.step

        def timed_step(self, centre, *a, step=step, steps=steps, moments=moments, **k):
            t0 = time.process_time()
            self.moments(centre)
            t1 = time.process_time()
            state = step(self, centre, *a, **k)
            steps.append(time.process_time() - t1)
            moments.append(t1 - t0)
            return state

        params = loop.BurrParams(radius=1.5e-3, method="octree", leaf=leaf)
        warm = type(base)(base.density[:64, :64, :64].copy(), base.voxel)
        loop.descent_experiment(warm, 0.05, 2.0, params=params)  # JIT warm-up
        loop.BurrSim.step = timed_step
        try:
            vol = type(base)(base.density.copy(), base.voxel, base.origin, base.rho_full)
            res, surface, _ = loop.descent_experiment(vol, 3.0, 2.0, params=params)
        finally:
            loop.BurrSim.step = step
        depth = surface - (res.centres[-1, 2] - params.radius)
        rows.append(
            {
                "leaf": leaf,
                "step_us": float(np.median(steps[50:]) * 1e6),
                "moments_us": float(np.median(moments[50:]) * 1e6),
                "depth_mm": float(depth * 1e3),
            }
        )
    return rows


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("trees", nargs="*", help="checkouts to time (the first is the reference)")
    p.add_argument("--rounds", type=int, default=5)
    p.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.child:
        print(json.dumps(child([4, 1])))
        return
    if len(args.trees) < 2 or args.rounds < 1:
        p.error("expected two or more checkout directories and --rounds >= 1")
    for tree in args.trees:
        if not os.path.isdir(os.path.join(tree, "physics", "burr")):
            p.error(f"{tree}: expected a jassy checkout (a directory holding physics/burr)")
    trees = [os.path.abspath(t) for t in args.trees]
    runs: dict[tuple[str, int], list[dict]] = {}
    for r in range(args.rounds):
        for tree in trees:
            env = dict(os.environ, PYTHONPATH=tree)
            out = subprocess.run([sys.executable, os.path.abspath(__file__), "--child"], cwd=tree, env=env,
                                 capture_output=True, text=True)  # fmt: skip
            if out.returncode:
                sys.exit(
                    f"burr_cpu.py: {tree}: the timing run exited {out.returncode}:\n{out.stderr[-2000:]}"
                )
            for row in json.loads(out.stdout.strip().splitlines()[-1]):
                runs.setdefault((tree, row["leaf"]), []).append(row)
            print(f"round {r + 1} {tree} done (load {os.getloadavg()[0]:.1f})", file=sys.stderr)
    for leaf in (4, 1):
        ref = runs[(trees[0], leaf)]
        for tree in trees:
            rows = runs[(tree, leaf)]
            step = statistics.median(x["step_us"] for x in rows)
            mom = statistics.median(x["moments_us"] for x in rows)
            ratio = statistics.median(x["step_us"] / y["step_us"] for x, y in zip(rows, ref, strict=True))
            mratio = statistics.median(
                x["moments_us"] / y["moments_us"] for x, y in zip(rows, ref, strict=True)
            )
            print(f"leaf {leaf} {tree}: step {step:.0f} us (x{ratio:.2f}), moments {mom:.1f} us "
                  f"(x{mratio:.2f}), depth {rows[-1]['depth_mm']:.3f} mm")  # fmt: skip


if __name__ == "__main__":
    main()
