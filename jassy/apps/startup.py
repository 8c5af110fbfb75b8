"""First-render time as a user meets it, and compiling the kernels ahead of it.

A fresh install has no compiled kernels: the first process to render a scene compiles every
numba kernel it calls (``cache=True`` then keeps them on disk), later processes load them.
:func:`bench_startup` times both in fresh processes (``jassy render`` in a subprocess, wall
and CPU time from the child's resource usage): *cold* with numba's cache pointed at an empty
folder (``NUMBA_CACHE_DIR``), which is what a fresh install meets, and *warm* with that folder
filled by the cold run. :func:`warm` compiles the shipped scenes' kernels ahead (``jassy
warm``), one scene per core, by rendering a short piece of each.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from typing import NamedTuple

from jassy.engines.coldstart import kernels_cached

#: Scenes timed by default: the smallest patch users meet first and the heaviest physics scene.
STARTUP_SCENES = ("bell", "wok")
#: Seconds rendered per scene by ``jassy warm`` (enough to reach every kernel of the render).
WARM_SECONDS = 0.5


class RunTime(NamedTuple):
    """One fresh process: wall time, CPU time (user + system, s) with its helper processes
    and of the main process alone, and its exit code."""

    wall_s: float
    cpu_s: float
    returncode: int
    main_cpu_s: float


#: ``python -m jassy`` that also writes the main process's own CPU time (s, without its
#: helpers') to the file named by its first argument.
_MAIN_CPU = """import resource, sys
from jassy.apps.cli import main
status = main(sys.argv[2:])
own = resource.getrusage(resource.RUSAGE_SELF)
with open(sys.argv[1], "w") as out:
    out.write(repr(own.ru_utime + own.ru_stime))
sys.exit(status)
"""


def run_fresh(argv: Sequence[str], cache_dir: str | None = None) -> RunTime:
    """Run ``python -m jassy *argv`` in a new process (numba's cache in ``cache_dir`` when given)
    and time it: wall clock around the process, CPU from its resource usage (with that of
    the compile helper it may fork, jassy.engines.coldstart) and from its own report."""
    env = dict(os.environ)
    if cache_dir is not None:
        env["NUMBA_CACHE_DIR"] = cache_dir
    with tempfile.TemporaryFile() as errors, tempfile.NamedTemporaryFile("r") as own:
        t0 = time.perf_counter()
        child = subprocess.Popen(
            [sys.executable, "-c", _MAIN_CPU, own.name, *argv],
            env=env,
            stdout=subprocess.DEVNULL,
            stderr=errors,
        )
        _, status, usage = os.wait4(child.pid, 0)
        wall = time.perf_counter() - t0
        child.returncode = os.waitstatus_to_exitcode(status)
        if child.returncode != 0:
            errors.seek(0)
            raise RuntimeError(f"jassy {' '.join(argv)} failed: {errors.read().decode()[-500:]}")
        cpu = usage.ru_utime + usage.ru_stime
        return RunTime(wall, cpu, child.returncode, float(own.read() or cpu))


def cached_kernels(cache_dir: str) -> tuple[int, int]:
    """(kernels, compiled specialisations) held by numba's cache folder ``cache_dir``: index
    files (one per cached function) and data files (one per type signature)."""
    kernels = specialisations = 0
    for _, _, files in os.walk(cache_dir):
        kernels += sum(name.endswith(".nbi") for name in files)
        specialisations += sum(name.endswith(".nbc") for name in files)
    return kernels, specialisations


def render_argv(scene: str, folder: str, seconds: float | None = None) -> list[str]:
    """``jassy render`` arguments for ``scene`` into ``folder`` (the patch's duration unless
    ``seconds`` is given)."""
    argv = ["render", scene, "-o", os.path.join(folder, f"{scene}.wav"), "-q"]
    return argv + (["--duration", repr(seconds)] if seconds is not None else [])


def bench_startup(
    scenes: Sequence[str] = STARTUP_SCENES,
    warm_runs: int = 3,
    progress: Callable[[str], None] = lambda m: None,
) -> list[dict]:
    """Per scene: its first render in a fresh process with an empty kernel cache (cold: every
    kernel compiled), the kernels that render compiled, and the best of ``warm_runs`` later
    renders in fresh processes (warm: kernels loaded). A first row times ``import jassy.apps.cli``."""
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        imports = [run_fresh(["--help"], cache_dir=folder) for _ in range(warm_runs)]
        rows.append(_row("import + --help", None, min(imports), (0, 0)))
        for scene in scenes:
            cache = os.path.join(folder, f"cache-{scene}")
            os.mkdir(cache)
            progress(f"{scene}: first render with an empty kernel cache")
            cold = run_fresh(render_argv(scene, folder), cache_dir=cache)
            progress(f"{scene}: {warm_runs} renders with the cache filled")
            warm = min(
                (run_fresh(render_argv(scene, folder), cache_dir=cache) for _ in range(warm_runs)),
                key=lambda r: r.wall_s,
            )
            rows.append(_row(scene, cold, warm, cached_kernels(cache)))
    return rows


def _row(case: str, cold: RunTime | None, warm: RunTime, kernels: tuple[int, int]) -> dict:
    row = {"case": case, "warm_wall_s": warm.wall_s, "warm_cpu_s": warm.cpu_s}
    if cold is not None:
        row.update(cold_wall_s=cold.wall_s, cold_cpu_s=cold.cpu_s, cold_main_cpu_s=cold.main_cpu_s)
        row.update(kernels=kernels[0], specialisations=kernels[1])
    return row


def print_startup(rows: list[dict]) -> None:
    """The table of :func:`bench_startup`."""
    print("first render in a fresh process (cold: empty numba cache, as after install; warm: cache filled)")
    print(
        f"{'case':16s} {'cold wall':>10s} {'cold CPU':>9s} {'main CPU':>9s} {'kernels':>8s} "
        f"{'warm wall':>10s} {'warm CPU':>9s}"
    )
    for r in rows:
        cold = (
            f"{r['cold_wall_s']:9.2f}s {r['cold_cpu_s']:8.2f}s {r['cold_main_cpu_s']:8.2f}s "
            f"{r['kernels']:4d}/{r['specialisations']:<3d}"
            if "cold_wall_s" in r
            else f"{'-':>10s} {'-':>9s} {'-':>9s} {'-':>8s}"
        )
        print(f"{r['case']:16s} {cold} {r['warm_wall_s']:9.2f}s {r['warm_cpu_s']:8.2f}s")
    print("kernels: functions/type specialisations compiled by the first render; CPU: the render's")
    print("processes together; main CPU: its main process alone (the compile helper of")
    print("jassy.engines.coldstart runs beside it: on an idle machine the cold wall is about this,")
    print("plus any wait for the helper)")


def warm(
    scenes: Sequence[str] = STARTUP_SCENES, jobs: int | None = None, say: Callable[[str], None] = print
) -> int:
    """Compile (or load) the kernels of ``scenes`` into numba's cache by rendering
    ``WARM_SECONDS`` of each in fresh processes, ``jobs`` at a time (default: one per core).
    Returns the number of scenes that failed."""
    jobs = jobs or len(os.sched_getaffinity(0))
    failed = 0
    with tempfile.TemporaryDirectory() as folder:
        pending = list(scenes)
        running: dict[int, tuple] = {}
        while pending or running:
            while pending and len(running) < jobs:
                scene = pending.pop(0)
                log = open(os.path.join(folder, f"{scene}.log"), "w+b")  # noqa: SIM115 (closed below)
                child = subprocess.Popen(
                    [sys.executable, "-m", "jassy", *render_argv(scene, folder, WARM_SECONDS)],
                    stdout=subprocess.DEVNULL,
                    stderr=log,
                )
                running[child.pid] = (scene, time.perf_counter(), child, log)
                say(f"warm: {scene}: compiling ...")
            pid, status, usage = os.wait4(-1, 0)
            if pid not in running:
                continue
            scene, t0, child, log = running.pop(pid)
            code = os.waitstatus_to_exitcode(status)
            cpu = usage.ru_utime + usage.ru_stime
            if code == 0:
                say(f"warm: {scene}: ready ({time.perf_counter() - t0:.1f} s wall, {cpu:.1f} s CPU)")
            else:
                failed += 1
                log.seek(0)
                last = (log.read().decode().strip().splitlines() or ["no message"])[-1]
                say(f"warm: {scene}: failed ({last})")
            child.returncode = code
            log.close()
    return failed


def first_run_notice(say: Callable[[str], None]) -> None:
    """Tell the user, before a render on a cold cache, why it is slow and that it is once."""
    if not kernels_cached():
        say(
            "jassy: first run: compiling numba kernels (once: seconds for a patch, minutes for a "
            "physics scene; later runs load them from the cache; `jassy warm` compiles them ahead)"
        )
