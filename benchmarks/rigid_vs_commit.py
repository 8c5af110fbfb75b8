"""Rigid world step time of this tree against another checkout (e.g. an older commit), in CPU
time, interleaved: each round runs one child process per tree (order alternating), each child
loads its tree's cached kernels with a short warm-up and then times every scene once with
``time.process_time``. Prints per-scene medians over the rounds and the ratio new/old.

    git worktree add --detach /tmp/old <commit>
    python benchmarks/rigid_vs_commit.py --old /tmp/old --warm   # compile the old kernels once
    python benchmarks/rigid_vs_commit.py --old /tmp/old --rounds 5
    python benchmarks/rigid_vs_commit.py --old /tmp/old --rounds 5 --only wok --repeat 3

Only the public API both trees share is used (World, Body, shapes, simulate, the bench pile
and the wok patch)."""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _ball(seconds: float):
    """A 5 cm ball dropped from 1 m on a floor, e = 0.6, default integrator, 1 ms steps."""
    from physics.rigid.shapes import Plane, Sphere
    from physics.rigid.world import Body, Material, Placement, StepParams, World, simulate

    w = World(StepParams(h=1e-3, bounce_threshold=0.05))
    w.add(Body("ground", Plane(), Material("g", 1000, 0.6, 0.0), kind="static"))
    w.add(Body("ball", Sphere(0.05), Material("b", 1000, 0.6, 0.0)), Placement(position=(0, 0, 1.05)))
    simulate(w, seconds, sample_every=0)


def _tower(seconds: float):
    """Four 2 cm cubes stacked, each turned 0.3 rad about the vertical from the one below:
    only edges cross faces (box-box narrow phase with edge-edge axes)."""
    from physics.rigid.shapes import Box, Plane
    from physics.rigid.world import Body, Material, Placement, StepParams, World, simulate

    w = World(StepParams(h=1e-3))
    w.add(Body("ground", Plane(), Material("g", 1000, 0, 0.5), kind="static"))
    for level in range(4):
        angle = 0.3 * level
        place = Placement(
            position=(0, 0, 0.01 * (2 * level + 1)),
            quaternion=(math.cos(angle / 2), 0, 0, math.sin(angle / 2)),
        )
        w.add(Body(f"cube{level}", Box((0.01, 0.01, 0.01)), Material("b", 800, 0, 0.5)), place)
    simulate(w, seconds, sample_every=100)


_PILES = {}


def _pile_settle(n: int):
    """The bench pile: n spheres and boxes dropped into a pen, settling for 1 s (many
    impacts); the settled (world, state) is kept for ``_pile_run``."""
    from physics.rigid.bench import pile

    _PILES[n] = pile(n)


def _pile_run(n: int, seconds: float):
    """The settled pile of n bodies run on for ``seconds`` (as in ``jassy bench rigid``)."""
    from physics.rigid.world import simulate

    if n not in _PILES:
        _pile_settle(n)
    world, state = _PILES[n]
    return lambda: simulate(world, seconds, state=state, sample_every=0)


def _wok(seconds: float):
    from patches.wok import simulate_wok

    simulate_wok(seconds)


def _scenes():
    """(name, warm-up call, timed call factory): a factory does untimed set-up and returns the
    call to time."""
    return [
        ("bouncing ball, 3 s", lambda: _ball(0.2), lambda: lambda: _ball(3.0)),
        ("tower of 4 turned cubes, 1 s", lambda: _tower(0.05), lambda: lambda: _tower(1.0)),
        ("pile of 100 settling, 1 s", lambda: _pile_settle(10), lambda: lambda: _pile_settle(100)),
        ("pile of 10 settled, 0.5 s", lambda: _pile_run(10, 0.05)(), lambda: _pile_run(10, 0.5)),
        ("pile of 100 settled, 0.5 s", lambda: _pile_run(100, 0.05)(), lambda: _pile_run(100, 0.5)),
        ("wok physics, 6 s", lambda: _wok(0.2), lambda: lambda: _wok(6.0)),
    ]


def child(warm_only: bool, only: str = "", repeat: int = 1) -> None:
    """Run in a tree (its root first on sys.path): print {scene: CPU seconds} as JSON, the
    best of ``repeat`` runs of each scene whose name contains ``only``."""
    times = {}
    for name, warm, factory in _scenes():
        if only not in name:
            continue
        warm()
        if warm_only:
            continue
        best = math.inf
        for _ in range(repeat):
            call = factory()
            t0 = time.process_time()
            call()
            best = min(best, time.process_time() - t0)
        times[name] = best
    print(json.dumps(times))


def _run_tree(
    tree: str, warm_only: bool = False, timeout: float = 1800, only: str = "", repeat: int = 1
) -> dict:
    env = dict(os.environ, PYTHONPATH=tree, OMP_NUM_THREADS="1", NUMBA_NUM_THREADS="1")
    args = [sys.executable, os.path.abspath(__file__), "--child", "--only", only, "--repeat", str(repeat)]
    args += ["--warm"] if warm_only else []
    out = subprocess.run(args, cwd=tree, env=env, capture_output=True, text=True, timeout=timeout)
    if out.returncode != 0:
        raise SystemExit(f"{tree}: child failed:\n{out.stderr[-2000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--old", help="root of the checkout to compare against")
    p.add_argument("--new", default=HERE, help="root of the new checkout (default: this tree)")
    p.add_argument("--rounds", type=int, default=5)
    p.add_argument("--warm", action="store_true", help="only compile/load both trees' kernels")
    p.add_argument("--only", default="", help="time only the scenes whose name contains this")
    p.add_argument("--repeat", type=int, default=1, help="best of this many runs per scene and round")
    p.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.child:
        child(args.warm, args.only, args.repeat)
        return
    if not args.old or not os.path.isdir(os.path.join(args.old, "physics", "rigid")):
        print("--old: expected the root of a jassy checkout (with physics/rigid)", file=sys.stderr)
        raise SystemExit(2)
    trees = {"old": os.path.abspath(args.old), "new": os.path.abspath(args.new)}
    if args.warm:
        for label, tree in trees.items():
            t0 = time.perf_counter()
            _run_tree(tree, warm_only=True, only=args.only)
            print(f"{label}: kernels ready in {time.perf_counter() - t0:.0f} s", flush=True)
        return
    samples = {"old": [], "new": []}
    for r in range(args.rounds):
        order = ("old", "new") if r % 2 == 0 else ("new", "old")
        for label in order:
            samples[label].append(_run_tree(trees[label], only=args.only, repeat=args.repeat))
        print(f"round {r + 1}: " + json.dumps({k: samples[k][-1] for k in order}), flush=True)
    print(f"\nCPU seconds, median of {args.rounds} interleaved rounds")
    print(f"{'scene':32s} {'old':>8s} {'new':>8s} {'new/old':>8s}  (new/old per round)")
    for name in samples["old"][0]:
        old = [s[name] for s in samples["old"]]
        new = [s[name] for s in samples["new"]]
        per_round = " ".join(f"{n / o:.2f}" for n, o in zip(new, old, strict=True))
        old_s, new_s = statistics.median(old), statistics.median(new)
        print(f"{name:32s} {old_s:8.3f} {new_s:8.3f} {new_s / old_s:8.2f}  ({per_round})")


if __name__ == "__main__":
    main()
