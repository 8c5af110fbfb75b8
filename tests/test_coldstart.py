"""A cold render's compile units run on two cores (jassy.forked_compile, with the units of
jassy.engines.coldstart): every unit runs, the two processes share them, the helper is always
reaped, and a render whose kernels came from the helper sounds the same as one that compiled
them itself."""

from __future__ import annotations

import os
import subprocess
import sys
import threading

import pytest

from jassy.forked_compile import may_fork_helper

TWO_CORES = len(os.sched_getaffinity(0)) >= 2

#: Run in a fresh process: earlier tests may have left a thread here (e.g. pyfftw's cache
#: thread), and then no helper is forked.
UNITS = """
import os, sys
from jassy.forked_compile import compile_on_two_cores

folder = sys.argv[1]
here = os.getpid()


def record(i):
    open(os.path.join(folder, f"{i}.{os.getpid()}"), "w").close()


def fail():
    raise ValueError("unit failed")


def no_children_left():
    try:
        return os.waitpid(-1, os.WNOHANG) is None
    except ChildProcessError:
        return True


if sys.argv[2] == "share":
    print(compile_on_two_cores([lambda i=i: record(i) for i in range(40)]), here, no_children_left())
else:
    try:
        compile_on_two_cores([fail, lambda: record(1)])
    except ValueError as error:
        print(error, no_children_left())
    # a unit failing in the helper stops it quietly; this process carries on
    done = compile_on_two_cores([lambda: record(2), lambda: os.getpid() == here or fail()])
    print(done, here, no_children_left())
"""


def _units(folder, case):
    out = subprocess.run(
        [sys.executable, "-c", UNITS, str(folder), case], capture_output=True, text=True, timeout=120
    )
    assert out.returncode == 0, out.stderr[-2000:]
    return out.stdout.splitlines()


def _ran(folder):
    return [tuple(int(p) for p in name.split(".")) for name in os.listdir(folder)]


@pytest.mark.skipif(not TWO_CORES, reason="needs two usable cores")
def test_units_are_shared_between_the_two_processes_and_the_helper_is_reaped(tmp_path):
    forked, here, reaped = _units(tmp_path, "share")[0].split()
    assert forked == "True" and reaped == "True"
    ran = _ran(tmp_path)
    assert sorted({i for i, _ in ran}) == list(range(40))  # every unit ran
    assert len(ran) <= 41  # at most the unit where the two met ran twice
    assert (0, int(here)) in ran  # this process starts at the front
    assert len({pid for _, pid in ran} - {int(here)}) <= 1  # one helper


@pytest.mark.skipif(not TWO_CORES, reason="needs two usable cores")
def test_a_failing_unit_here_propagates_and_a_failing_helper_unit_is_left_to_the_caller(tmp_path):
    raised, carried_on = _units(tmp_path, "fail")
    assert raised == "unit failed True"  # raised here, after the helper was reaped
    done, here, reaped = carried_on.split()
    assert done == "True" and reaped == "True" and (2, int(here)) in _ran(tmp_path)


#: A host that reaps its children itself (a SIGCHLD handler): the helper is gone before
#: compile_on_two_cores waits for it.
REAPING_HOST = """
import os, signal, time
from jassy.forked_compile import compile_on_two_cores

def reap(signum, frame):
    try:
        while os.waitpid(-1, os.WNOHANG)[0]:
            pass
    except ChildProcessError:
        pass

signal.signal(signal.SIGCHLD, reap)
print(compile_on_two_cores([lambda: time.sleep(0.5), lambda: None]))
"""


@pytest.mark.skipif(not TWO_CORES, reason="needs two usable cores")
def test_a_host_reaping_its_children_does_not_break_the_wait_for_the_helper():
    out = subprocess.run([sys.executable, "-c", REAPING_HOST], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.split() == ["True"]


def test_no_helper_for_one_unit_or_with_other_threads_running():
    assert not may_fork_helper([print])
    stop = threading.Event()
    thread = threading.Thread(target=stop.wait)
    thread.start()
    try:
        assert not may_fork_helper([print, print])
    finally:
        stop.set()
        thread.join()


COLD_RENDER = """
import hashlib, sys
import numpy as np
from jassy import forked_compile
from jassy.patchfile import load_patch
from jassy.engines.offline import OfflineEngine
from numba.core import event
forked = []
compiled_after = []  # kernels the render compiled after the units (it should load them all)
class Compiles(event.Listener):
    def on_start(self, compile_event):
        function = compile_event.data["dispatcher"].py_func
        compiled_after.append(f"{function.__module__}.{function.__qualname__}")
    def on_end(self, compile_event):
        pass
original = forked_compile.compile_on_two_cores
def counted(units):
    forked.append(original(units))
    event.register("numba:compile", Compiles())  # with or without a helper: after the units
    return forked[-1]
import jassy.engines.offline
jassy.engines.offline.compile_on_two_cores = counted
patch = load_patch("bell")
engine = OfflineEngine(patch.graph, patch.score, 48000, program=sys.argv[1] == "program")
audio = engine.render(float(sys.argv[2])).audio
digest = hashlib.sha256(np.ascontiguousarray(audio).tobytes()).hexdigest()
print(forked[-1], digest, ",".join(compiled_after) or "-")
"""


def _render_bell(cache, path="program", helper=True, seconds=1.0):
    """(helper forked, SHA-256 of the bell's first ``seconds`` of audio, kernels compiled
    after the units) of a fresh process rendering on numba's cache ``cache`` as a program
    or node by node."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache))
    alone = (  # the units all run here, one after the other, and no helper is forked
        "def alone(units):\n    for unit in units:\n        unit()\n    return False\n"
        "forked_compile.compile_on_two_cores = alone\n"
    )
    code = COLD_RENDER if helper else COLD_RENDER.replace("forked = []\n", "forked = []\n" + alone)
    out = subprocess.run(
        [sys.executable, "-c", code, path, repr(seconds)],
        env=env,
        capture_output=True,
        text=True,
        timeout=550,
    )
    assert out.returncode == 0, out.stderr[-2000:]
    return out.stdout.split()


@pytest.mark.timeout(600)
@pytest.mark.skipif(not TWO_CORES, reason="needs two usable cores")
def test_a_render_with_kernels_from_the_helper_sounds_like_one_compiling_alone(tmp_path):
    """The bell on an empty cache (units shared with a helper), then on a second empty cache
    compiled here alone (no helper), then loading the first cache: one sound. With or
    without the helper, the render after the units compiles nothing (the units cover every
    kernel)."""
    shared, alone = tmp_path / "shared", tmp_path / "alone"
    shared.mkdir()
    alone.mkdir()
    first = _render_bell(shared)
    assert first[0] == "True"  # a helper was forked
    assert first[2] == "-", f"compiled after the units: {first[2]}"
    assert _render_bell(alone, helper=False) == ["False", first[1], "-"]
    assert _render_bell(shared)[1] == first[1]  # every kernel loaded from the cache


@pytest.mark.timeout(600)
@pytest.mark.skipif(not TWO_CORES, reason="needs two usable cores")
def test_a_cold_render_node_by_node_shares_its_kernels_and_sounds_like_the_program(tmp_path):
    """Node by node on an empty cache (as `jassy render` renders until the program's kernels
    are compiled): a helper takes its share, every kernel of the graph's nodes (the gain's
    fade too), the strikes and the output stage comes from the units, and the sound is the
    program's, bit for bit."""
    program, nodes = tmp_path / "program", tmp_path / "nodes"
    program.mkdir()
    nodes.mkdir()
    forked, digest, after = _render_bell(nodes, "nodes", seconds=8.0)  # with the gain's fade at 6 s
    assert forked == "True"
    # only numba's own helpers (e.g. np.zeros' implementation) may compile after the units
    assert all(name == "-" or name.startswith("numba.") for name in after.split(",")), after
    assert _render_bell(program, helper=False, seconds=8.0)[1] == digest


PER_PATCH = """
import sys
from jassy.apps import cli
from jassy.engines import offline
from jassy.engines.coldstart import program_cached
from jassy.patchfile import load_patch

offline.OfflineEngine(load_patch("bell").graph, load_patch("bell").score, 48000).render(0.05)


class Built(BaseException):
    pass


class Recorded(offline.OfflineEngine):  # what `jassy render` builds, before it renders
    def __init__(self, graph, score, rate, *args, program=True, **options):
        raise Built(program)


offline.OfflineEngine = Recorded
for name in ("wall_tap", "scrape"):
    try:
        cli.main(["render", name, "-o", sys.argv[1] + "/" + name + ".wav", "--duration", "0.05"])
    except Built as built:
        print(name, built.args[0], program_cached(load_patch(name).graph))
"""


@pytest.mark.timeout(600)
def test_a_cli_render_takes_the_program_path_only_when_its_graphs_program_is_cached(tmp_path):
    """After an API render of the bell as a program on an empty cache, `jassy render` renders
    a patch of the same node kinds (wall_tap) as a program and the scrape (biquads, a mixer
    and scrapes, never compiled as program functions) node by node."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"))
    out = subprocess.run(
        [sys.executable, "-c", PER_PATCH, str(tmp_path)], env=env, capture_output=True, text=True, timeout=550
    )
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.split("\n")[-3:] == ["wall_tap True True", "scrape False False", ""]


JIT_OFF = """
from jassy.engines.coldstart import graph_units, kernels_cached, program_cached
from jassy.forked_compile import cache_holds
from jassy.patchfile import load_patch
from jassy.safety import limit

graph = load_patch("bell").graph
options = {"sample_rate": 48000.0, "block": 64}
print(cache_holds(limit), kernels_cached(), program_cached(graph), len(graph_units(graph, options)))
"""


def test_with_the_jit_off_nothing_counts_as_cached_and_nothing_compiles_ahead(tmp_path):
    """NUMBA_DISABLE_JIT on an empty cache: no kernel is cached (a render takes the node path,
    whose Python code runs as is) and a cold render lists no compile units."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path), NUMBA_DISABLE_JIT="1")
    out = subprocess.run(
        [sys.executable, "-c", JIT_OFF], env=env, capture_output=True, text=True, timeout=120
    )
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.split() == ["False", "False", "False", "0"]
