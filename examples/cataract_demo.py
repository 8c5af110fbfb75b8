"""The cataract-surgery experiment: capsulorhexis of the anterior capsule with forceps, then
phacoemulsification along a cross groove until the lens splits into fragments that fall and
collide in the capsule bag (physics/deform/cataract.py).

    python examples/cataract_demo.py                      # 2500 steps of 1 ms, ~20 s
    python examples/cataract_demo.py --steps 1300 --seed 3 --json cataract.json

Prints the fragments (count and particles each), the split time, the tets removed (per
removal primitive), the impacts (with the bag, between fragments), the torn membrane
springs and the median step timings; --json writes the same summary atomically.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

from jassy.apps.cli_checks import LineParser
from jassy.errors import JassyError
from jassy.files import atomic_path
from physics.deform.cataract import cataract_demo

#: The per-event and per-tet lists left out of the printed and written summary.
DETAIL_KEYS = ("impact_events", "tear_events", "removed_tets")


def int_at_least(minimum: int):
    """argparse type: an integer >= ``minimum``."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            value = None
        if value is None or value < minimum:
            raise argparse.ArgumentTypeError(f"expected an integer >= {minimum}, got {text!r}")
        return value

    return parse


def summary(result: dict) -> dict:
    """The result without its per-event and per-tet lists; refuses non-finite numbers."""
    out = {k: v for k, v in result.items() if k not in DETAIL_KEYS}
    for key, value in out.items():
        if isinstance(value, float) and not math.isfinite(value):
            raise JassyError(f"cataract_demo: {key} is {value}; expected a finite number")
    return out


def print_summary(s: dict) -> None:
    split = "none" if s["split_time_s"] is None else f"{s['split_time_s']:.3f} s"
    kinds = ", ".join(f"{n} with {k} external faces" for k, n in s["removed_by_external_faces"].items())
    print(f"lens: {s['lens_particles']} particles, {s['lens_tets']} tets")
    print(f"fragments: {s['fragments']} (particles each: {s['fragment_sizes']}), split at {split}")
    print(f"tets removed: {s['tets_removed']} ({kinds})")
    print(
        f"impacts: {s['impacts']} ({s['impacts_boundary']} with the bag, "
        f"{s['impacts_fragment']} between fragments)"
    )
    print(f"torn springs: {s['torn_springs']} of {s['membrane_springs']}")
    print(
        f"median step (ms): fragments {s['fragment_step_ms']:.3f}, erode {s['erode_ms']:.3f}, "
        f"membrane {s['membrane_step_ms']:.3f}; wall {s['wall_s']:.1f} s"
    )


def main(argv: list[str] | None = None) -> int:
    parser = LineParser(prog="cataract_demo", description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int_at_least(1), default=2500, help="1 ms steps (default 2500)")
    parser.add_argument("--seed", type=int_at_least(0), default=0, help="hand tremor seed (default 0)")
    parser.add_argument("--json", metavar="OUT", help="write the summary as JSON to OUT (atomically)")
    args = parser.parse_args(argv)
    if args.json and not (Path(args.json).parent.is_dir() and not Path(args.json).is_dir()):
        print(
            f"cataract_demo: error: --json: {args.json}: expected a file in an existing directory",
            file=sys.stderr,
        )
        return 2
    try:
        s = summary(cataract_demo(steps=args.steps, seed=args.seed))
        if args.json:
            with atomic_path(args.json) as tmp, open(tmp, "w") as fh:
                json.dump(s, fh, indent=2, allow_nan=False)
    except JassyError as exc:
        print(f"cataract_demo: error: {exc}", file=sys.stderr)
        return 2
    print_summary(s)
    return 0


if __name__ == "__main__":
    sys.exit(main())
