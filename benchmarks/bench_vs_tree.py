"""A ``jassy bench`` of this tree against another checkout of jassy, interleaved in one run.

Each round runs ``python -m jassy bench NAME --json`` once per tree (one child process each,
the order alternating from round to round, each tree's own numba cache), so drifts in the
machine's speed hit both trees alike. Every number in the benches' JSON that is a speed
(mode-samples per second, or anything else measured in CPU time by the bench itself) is
collected per round; printed are the per-key medians and the median of the rounds' ratios
this tree / other tree (for rates above 1 is faster here; for times in seconds, keys
ending in ``_s``, below 1 is).

    git archive main | tar -x -C /tmp/main_tree
    python benchmarks/bench_vs_tree.py --old /tmp/main_tree modal --quick --rounds 5

The first round of each tree also compiles its kernels if its cache is cold: run with
``--rounds 1`` once first, or read the medians of several rounds.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys

HERE = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def leaves(value, prefix: str = "") -> dict[str, float]:
    """The numeric leaves of a JSON value by dotted path (list items by their ``modes`` or
    index), booleans and strings left out."""
    found = {}
    if isinstance(value, dict):
        for key, item in value.items():
            found.update(leaves(item, f"{prefix}{key}."))
    elif isinstance(value, list):
        for i, item in enumerate(value):
            tag = item.get("modes", i) if isinstance(item, dict) else i
            found.update(leaves(item, f"{prefix}{tag}."))
    elif isinstance(value, (int, float)) and not isinstance(value, bool):
        found[prefix[:-1]] = float(value)
    return found


def run_bench(tree: str, bench: list[str], timeout: float) -> dict[str, float]:
    """One child process: ``jassy bench`` with ``tree`` first on the path; its numbers."""
    env = dict(os.environ, PYTHONPATH=tree)
    command = [sys.executable, "-m", "jassy", "bench", *bench, "--json"]
    done = subprocess.run(command, cwd=tree, env=env, capture_output=True, text=True, timeout=timeout)
    if done.returncode != 0:
        raise SystemExit(f"bench in {tree} failed ({done.returncode}): {done.stderr.strip()[-400:]}")
    return leaves(json.loads(done.stdout))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--old", required=True, help="the other checkout (a directory holding jassy/)")
    parser.add_argument("--rounds", type=int, default=3, help="rounds of one run per tree (default 3)")
    parser.add_argument("--timeout", type=float, default=1800.0, help="seconds per child run")
    parser.add_argument("bench", nargs=argparse.REMAINDER, help="the bench's name and options")
    args = parser.parse_args(argv)
    if not args.bench:
        parser.error("bench: expected the bench's name, e.g. modal --quick")
    if not os.path.isdir(os.path.join(args.old, "jassy")):
        parser.error(f"--old: {args.old} holds no jassy/ package")
    trees = {"new": HERE, "old": os.path.abspath(args.old)}
    samples: dict[str, dict[str, list[float]]] = {"new": {}, "old": {}}
    for r in range(args.rounds):
        order = ("new", "old") if r % 2 == 0 else ("old", "new")
        for label in order:
            for key, value in run_bench(trees[label], args.bench, args.timeout).items():
                samples[label].setdefault(key, []).append(value)
        print(f"round {r + 1}/{args.rounds} done", file=sys.stderr, flush=True)
    print(f"{'key':44s} {'old':>11s} {'new':>11s} {'new/old':>8s}  (range over rounds)")
    for key in sorted(samples["new"].keys() & samples["old"].keys()):
        old, new = samples["old"][key], samples["new"][key]
        ratios = [b / a if a else float("nan") for a, b in zip(old, new, strict=True)]  # same round
        span = f"{min(ratios):.3f}-{max(ratios):.3f}"
        print(
            f"{key:44s} {statistics.median(old):11.4g} {statistics.median(new):11.4g} "
            f"{statistics.median(ratios):8.3f}  {span}"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
