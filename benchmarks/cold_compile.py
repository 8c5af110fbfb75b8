"""Where a cold render's CPU goes: every function numba compiles in this process, with its
CPU time inclusive and exclusive of the functions it compiles on the way (numba's
``numba:compile`` events), LLVM's share (``numba:llvm_lock``), and the CPU of the helper
processes the render forked and reaped (jassy.forked_compile). Point numba's cache at an
empty folder to see a fresh install's first render:

    NUMBA_CACHE_DIR=$(mktemp -d) python benchmarks/cold_compile.py OUT.txt render wok -o /tmp/wok.wav -q

OUT.txt: a summary line, then one line per function (exclusive s, inclusive s, compiles,
qualified name), the most expensive first, and the timeline of the outermost compiles (wall
seconds from this process's start at their start and end, name); then the same for each
forked helper (its compile events, written by the helper as it goes to OUT.txt.helper-PID
and gathered here), on the same clock: where one process waits for the other shows there."""

from __future__ import annotations

import argparse
import glob
import os
import resource
import sys
import time
from collections import defaultdict

from numba.core import event

#: The clock of the timelines (time.monotonic is one clock for the process and its forks).
START = time.monotonic()


class CompileTimes(event.Listener):
    """CPU time per compiled function, exclusive of the compiles nested in it."""

    def __init__(self, out: str):
        self.out = out
        self.helper_file = ""  # set in a forked helper: where it writes its table
        self.stack: list[list] = []  # [name, start CPU, CPU of nested compiles]
        self.inclusive: dict[str, float] = defaultdict(float)
        self.exclusive: dict[str, float] = defaultdict(float)
        self.count: dict[str, int] = defaultdict(int)
        self.outermost: list[str] = []  # the timeline: start, end (wall s from START), name
        os.register_at_fork(after_in_child=self._forked)

    def _forked(self):
        """In a forked helper: count its compiles alone, into OUT.txt.helper-PID (a helper
        leaves with os._exit, so the table is rewritten after each outermost compile)."""
        self.helper_file = f"{self.out}.helper-{os.getpid()}"
        self.stack.clear()
        for table in (self.inclusive, self.exclusive, self.count):
            table.clear()
        self.outermost.clear()

    def table(self) -> list[str]:
        """One line per function: exclusive s, inclusive s, compiles, name; costliest first;
        then the timeline of the outermost compiles."""
        return [
            f"{self.exclusive[name]:8.2f} {self.inclusive[name]:8.2f} {self.count[name]:3d} {name}\n"
            for name in sorted(self.exclusive, key=lambda k: -self.exclusive[k])
        ] + ["  timeline (wall s from start: start, end, outermost compile):\n", *self.outermost]

    def on_start(self, ev):
        function = ev.data["dispatcher"].py_func
        name = f"{function.__module__}.{function.__qualname__}"
        self.stack.append([name, time.process_time(), 0.0, time.monotonic() - START])

    def on_end(self, ev):
        name, start, nested, wall_start = self.stack.pop()
        spent = time.process_time() - start
        self.inclusive[name] += spent
        self.exclusive[name] += spent - nested
        self.count[name] += 1
        if self.stack:
            self.stack[-1][2] += spent
            return
        self.outermost.append(f"  {wall_start:8.2f} {time.monotonic() - START:8.2f} {name}\n")
        if self.helper_file:
            with open(self.helper_file, "w") as f:
                f.writelines(self.table())


class LockTime(event.Listener):
    """CPU time spent holding numba's LLVM lock (LLVM's optimisation and code generation).
    The lock is re-entrant: a nested hold is counted once, from the outermost start to its
    end (a depth counter)."""

    def __init__(self):
        self.total = 0.0
        self.depth = 0

    def on_start(self, ev):
        if self.depth == 0:
            self.start = time.process_time()
        self.depth += 1

    def on_end(self, ev):
        self.depth -= 1
        if self.depth == 0:
            self.total += time.process_time() - self.start


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("out", metavar="OUT.txt", help="where the summary and per-function table go")
    parser.add_argument("jassy_args", nargs=argparse.REMAINDER, metavar="JASSY ARGS",
                        help="the jassy command to run, e.g. render wok -o /tmp/wok.wav -q")  # fmt: skip
    args = parser.parse_args(argv)
    if not args.jassy_args:
        parser.error("expected a jassy command after OUT.txt, e.g. render bell -o /tmp/bell.wav")
    out, jassy_args = args.out, args.jassy_args
    for stale in glob.glob(f"{out}.helper-*"):
        os.remove(stale)
    compiles, llvm = CompileTimes(out), LockTime()
    event.register("numba:compile", compiles)
    event.register("numba:llvm_lock", llvm)
    cpu0, wall0 = time.process_time(), time.perf_counter()
    from jassy.apps.cli import main as jassy_main

    status = jassy_main(jassy_args)
    cpu, wall = time.process_time() - cpu0, time.perf_counter() - wall0
    helpers = resource.getrusage(resource.RUSAGE_CHILDREN)
    with open(out, "w") as f:
        f.write(
            f"main process CPU {cpu:.2f} s, helpers CPU {helpers.ru_utime + helpers.ru_stime:.2f} s, "
            f"wall {wall:.1f} s, LLVM {llvm.total:.2f} s, {len(compiles.count)} functions / "
            f"{sum(compiles.count.values())} specialisations compiled\n"
        )
        f.writelines(compiles.table())
        for helper in sorted(glob.glob(f"{out}.helper-*")):
            with open(helper) as lines:
                f.write(f"helper {helper.rsplit('-', 1)[1]}:\n" + lines.read())
            os.remove(helper)
    return status


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
