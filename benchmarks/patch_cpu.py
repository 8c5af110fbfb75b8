"""CPU time of built-in patches rendered as ``jassy bench contact`` renders them (48 kHz,
block 64, one process), interleaved, best of ``--repeats``; prints x real time and the ratio
to the first patch named (the reference timed in the same run).

    python benchmarks/patch_cpu.py bell wok-sizzle wok-room

Run it with another checkout first on the path (``PYTHONPATH=/path/to/checkout``) to time
that tree's code, alternating the two for a before/after comparison."""

from __future__ import annotations

import argparse
import json

from jassy.apps.bench import SAMPLE_RATE, _best_times
from jassy.engines.offline import OfflineEngine
from jassy.patchfile import builtin_patches, load_patch


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("patches", nargs="+", help="built-in patch names; the first is the reference")
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--json", action="store_true")
    args = p.parse_args()
    unknown = [name for name in args.patches if name not in builtin_patches()]
    if unknown:
        p.error(f"patches: no built-in patch {', '.join(unknown)}")
    runs, durations = [], []
    for name in args.patches:
        patch = load_patch(name)
        durations.append(patch.duration or 5.0)
        runs.append(
            lambda patch=patch, d=durations[-1]: OfflineEngine(
                patch.graph, patch.score, SAMPLE_RATE, 64
            ).render(d)
        )
    best = _best_times(runs, repeats=args.repeats)
    rows = {
        name: {"cpu_s": t, "x_real_time": d / t, "vs_first": (d / t) / (durations[0] / best[0])}
        for name, t, d in zip(args.patches, best, durations, strict=True)
    }
    if args.json:
        print(json.dumps(rows))
        return
    first = args.patches[0]
    for name, r in rows.items():
        cpu, factor, ratio = r["cpu_s"] * 1e3, r["x_real_time"], r["vs_first"]
        print(f"{name:14s} {cpu:8.1f} ms CPU {factor:8.1f} x real time {ratio:6.3f} of {first}")


if __name__ == "__main__":
    main()
