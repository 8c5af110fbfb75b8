"""How many of numba's call typings in a cold ``jassy render wok`` repeat an earlier one
(same callee type, typing context, target and argument types), with jassy.remembered_typing
left out and no helper forked (every typing in this process): the figure behind that
module. Counts every ``BaseFunction.get_call_type`` call and the CPU time (s) inside the
outermost ones.

    NUMBA_CACHE_DIR=$(mktemp -d) PYTHONPATH=. python benchmarks/typing_repeats.py
"""

from __future__ import annotations

import sys
import time

from numba.core.target_extension import get_local_target
from numba.core.types import functions

from jassy import forked_compile, remembered_typing


def main() -> None:
    remembered_typing.shaped_as_expected = lambda: False  # numba's typing as it is
    forked_compile.may_fork_helper = lambda units: False  # every typing in this process
    seen: set = set()
    counts = {"calls": 0, "repeats": 0, "depth": 0, "cpu": 0.0, "repeat_cpu": 0.0}
    get_call_type = functions.BaseFunction.get_call_type

    def counted(self, context, args, kws):
        try:
            key = (self, context, get_local_target(context), tuple(args), tuple(sorted(kws.items())))
            repeat = key in seen
            seen.add(key)
        except TypeError:
            repeat = False
        counts["calls"] += 1
        counts["repeats"] += repeat
        counts["depth"] += 1
        start = time.process_time()
        try:
            return get_call_type(self, context, args, kws)
        finally:
            counts["depth"] -= 1
            if counts["depth"] == 0:
                spent = time.process_time() - start
                counts["cpu"] += spent
                counts["repeat_cpu"] += spent if repeat else 0.0

    functions.BaseFunction.get_call_type = counted
    from jassy.apps.cli import main as cli

    cli(["render", "wok", "-o", "/tmp/typing_repeats.wav", "-q"])
    print(
        f"{counts['repeats']} of {counts['calls']} resolutions repeat an earlier one; "
        f"outermost: {counts['cpu']:.1f} s CPU, {counts['repeat_cpu']:.1f} s of it in repeats",
        file=sys.stderr,
    )


if __name__ == "__main__":
    main()
