"""First render in a fresh process: the kernels it compiles are bounded and a second process
loads every one of them from numba's cache (jassy.apps.startup; timings: `jassy bench startup`)."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from jassy.apps.startup import cached_kernels, render_argv, run_fresh

#: Bounds well above this code's first bell render (node by node: 20 functions, 20
#: specialisations, about 6 s of CPU in two processes on the shared 2-core VM at load 7; as a
#: program it compiled 24 / 24, 8.7-9.1 s at load 19): a regression by half as much again fails.
MAX_KERNELS, MAX_SPECIALISATIONS, MAX_COLD_CPU_S = 30, 30, 45.0


def _index_stamps(folder) -> dict:
    return {
        os.path.join(root, name): os.stat(os.path.join(root, name)).st_mtime_ns
        for root, _, files in os.walk(folder)
        for name in files
    }


@pytest.mark.timeout(600)
def test_a_cold_bell_render_compiles_few_kernels_and_a_warm_one_compiles_none(tmp_path):
    cache = tmp_path / "cache"
    cache.mkdir()
    cold = run_fresh(render_argv("bell", str(tmp_path)), cache_dir=str(cache))
    kernels, specialisations = cached_kernels(str(cache))
    assert 0 < kernels <= MAX_KERNELS and 0 < specialisations <= MAX_SPECIALISATIONS, (
        kernels,
        specialisations,
    )
    assert cold.cpu_s < MAX_COLD_CPU_S
    # rendered node by node: the program's render loop was not compiled
    assert not any("render_planar" in name for name in _index_stamps(cache)), sorted(_index_stamps(cache))
    if len(os.sched_getaffinity(0)) >= 2:  # the compile helper took its share (about half)
        assert cold.main_cpu_s < 0.8 * cold.cpu_s, cold
    before = _index_stamps(cache)
    warm = run_fresh(render_argv("bell", str(tmp_path)), cache_dir=str(cache))
    # every kernel came from the cache: numba rewrote no index and added no file
    assert _index_stamps(cache) == before
    assert warm.cpu_s < cold.cpu_s / 2


def test_warm_refuses_an_unknown_scene_in_one_line():
    proc = subprocess.run(
        [sys.executable, "-m", "jassy", "warm", "nosuch"], capture_output=True, text=True, timeout=120
    )
    assert proc.returncode == 2
    assert proc.stderr.count("\n") == 1 and "nosuch" in proc.stderr
