"""A cold render's compile units run on two cores (jassy.coldstart): every unit runs, the two
processes share them, the helper is always reaped, and a render whose kernels came from the
helper sounds the same as one that compiled them itself."""

from __future__ import annotations

import os
import subprocess
import sys
import threading

import pytest

from jassy.coldstart import compile_on_two_cores, may_fork_helper

TWO_CORES = len(os.sched_getaffinity(0)) >= 2 and threading.active_count() == 1


def _record(folder, i):
    with open(os.path.join(folder, f"{i}.{os.getpid()}"), "w"):
        pass


def _ran(folder):
    return [tuple(int(p) for p in name.split(".")) for name in os.listdir(folder)]


def _no_children_left():
    try:
        return os.waitpid(-1, os.WNOHANG) is None
    except ChildProcessError:
        return True


@pytest.mark.skipif(not TWO_CORES, reason="needs two usable cores and a single thread")
def test_units_are_shared_between_the_two_processes_and_the_helper_is_reaped(tmp_path):
    units = [lambda i=i: _record(tmp_path, i) for i in range(40)]
    assert compile_on_two_cores(units)
    ran = _ran(tmp_path)
    assert sorted({i for i, _ in ran}) == list(range(40))  # every unit ran
    assert len(ran) <= 41  # at most the unit where the two met ran twice
    assert (0, os.getpid()) in ran  # this process starts at the front
    assert len({pid for _, pid in ran} - {os.getpid()}) <= 1  # one helper
    assert _no_children_left()


@pytest.mark.skipif(not TWO_CORES, reason="needs two usable cores and a single thread")
def test_a_failing_unit_here_propagates_and_a_failing_helper_unit_is_left_to_the_caller(tmp_path):
    def fail():
        raise ValueError("unit failed")

    with pytest.raises(ValueError, match="unit failed"):
        compile_on_two_cores([fail, lambda: _record(tmp_path, 1)])
    assert _no_children_left()
    # a unit failing in the helper stops it quietly; this process carries on
    here = os.getpid()
    assert compile_on_two_cores([lambda: _record(tmp_path, 2), lambda: os.getpid() == here or fail()])
    assert (2, here) in _ran(tmp_path) and _no_children_left()


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
from jassy import coldstart
from jassy.patchfile import load_patch
from jassy.engines.offline import OfflineEngine
forked = []
original = coldstart.compile_on_two_cores
def counted(units):
    forked.append(original(units))
    return forked[-1]
import jassy.engines.offline
jassy.engines.offline.compile_on_two_cores = counted
patch = load_patch("bell")
audio = OfflineEngine(patch.graph, patch.score, 48000).render(1.0).audio
print(forked[0], hashlib.sha256(np.ascontiguousarray(audio).tobytes()).hexdigest())
"""


@pytest.mark.timeout(600)
@pytest.mark.skipif(not TWO_CORES, reason="needs two usable cores and a single thread")
def test_a_render_with_kernels_from_the_helper_sounds_like_one_compiling_alone(tmp_path):
    """The bell on an empty cache (units shared with a helper), then on a second empty cache
    compiled here alone (no helper), then loading the first cache: one sound."""

    def render(cache, helper=True):
        env = dict(os.environ, NUMBA_CACHE_DIR=str(cache))
        alone = "coldstart.may_fork_helper = lambda units: False\n"  # the caller compiles it all
        code = COLD_RENDER if helper else COLD_RENDER.replace("forked = []\n", "forked = []\n" + alone)
        out = subprocess.run(
            [sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=550
        )
        assert out.returncode == 0, out.stderr[-2000:]
        return out.stdout.split()

    shared, alone = tmp_path / "shared", tmp_path / "alone"
    shared.mkdir()
    alone.mkdir()
    first = render(shared)
    assert first[0] == "True"  # a helper was forked
    assert render(alone, helper=False) == ["False", first[1]]
    assert render(shared)[1] == first[1]  # every kernel loaded from the cache
