"""jassy.forked_compile: the helper's progress as this process sees it (which unit the helper
has finished, whether the helper has ended) and numba's cache as a waiting process sees it.
Each test forks a helper that sleeps or exits instead of compiling."""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import time

import numba as nb
import pytest
from numba.core import caching

from jassy import forked_compile
from jassy.forked_compile import cache_holds, compile_on_two_cores, helper_busy_with


def _waiting_for_last_unit(waited: list[float], seconds: float = 20.0):
    """A unit (run here, first) that waits while the helper is busy with the last unit."""

    def unit():
        start = time.monotonic()
        while helper_busy_with(-1) and time.monotonic() - start < seconds:
            time.sleep(0.01)
        waited.append(time.monotonic() - start)

    return unit


@pytest.mark.timeout(60)
def test_the_wait_ends_when_the_helper_has_finished_the_unit(forking_alone):
    """The helper gives up its first unit at once and works 3 s on another: the wait for the
    first ends with it, not with the helper."""
    if not forking_alone:
        return
    waited: list[float] = []
    assert compile_on_two_cores([_waiting_for_last_unit(waited), lambda: time.sleep(3.0), lambda: None])
    assert waited[0] < 1.5


@pytest.mark.timeout(60)
def test_an_other_finished_child_does_not_end_the_wait(forking_alone):
    """A child this process started earlier, ended and not reaped, is not the helper: the wait
    lasts while the helper works on the unit (1.5 s)."""
    if not forking_alone:
        return
    earlier = subprocess.Popen(["true"])
    time.sleep(0.3)  # ended, not reaped
    waited: list[float] = []
    try:
        assert compile_on_two_cores([_waiting_for_last_unit(waited), lambda: time.sleep(1.5)])
    finally:
        earlier.wait()
    assert 1.0 < waited[0] < 10.0


@pytest.mark.timeout(60)
def test_the_wait_ends_with_the_helper_reaped_while_an_other_child_runs(forking_alone):
    """The helper ends without finishing the unit (as if it crashed) and the host's SIGCHLD
    handler reaps it; another child of this process still runs: the wait ends at once."""
    if not forking_alone:
        return

    def reap_helper(*_):
        helper = forked_compile._helper
        if helper is not None:
            with contextlib.suppress(ChildProcessError):
                os.waitpid(helper.pid, os.WNOHANG)

    player = subprocess.Popen(["sleep", "30"])
    previous = signal.signal(signal.SIGCHLD, reap_helper)
    waited: list[float] = []
    try:
        assert compile_on_two_cores([_waiting_for_last_unit(waited), lambda: os._exit(0)])
    finally:
        signal.signal(signal.SIGCHLD, previous)
        player.kill()
        player.wait()
    assert waited[0] < 5.0


def test_no_helper_is_never_busy():
    assert not helper_busy_with(0)
    assert not helper_busy_with(-1)


@nb.njit(cache=True)
def _cached_twice(x):
    return x * 2


def test_the_cache_holds_a_kernel_once_its_data_file_is_written(monkeypatch):
    """numba writes a kernel's cache index before its data file: between the two the kernel
    cannot be loaded, and cache_holds says so."""
    seen = []
    save_data = caching.IndexDataCacheFile._save_data

    def save_data_seen(self, name, data):
        seen.append((os.path.exists(self._index_path), cache_holds(_cached_twice)))
        save_data(self, name, data)

    for name in _cached_twice._cache._cache_file._load_index().values():
        os.remove(os.path.join(_cached_twice._cache._cache_path, name))
    monkeypatch.setattr(caching.IndexDataCacheFile, "_save_data", save_data_seen)
    assert _cached_twice(2.0) == 4.0
    assert seen == [(True, False)]
    assert cache_holds(_cached_twice)


@pytest.mark.timeout(60)
def test_the_helper_passes_over_a_unit_this_process_claimed(forking_alone, tmp_path):
    """This process claims unit 2 (forked_compile.claim) while the helper works on unit 3:
    the helper passes over unit 2 and runs unit 1, which this process then leaves to it."""
    if not forking_alone:
        return
    ran: list[int] = []

    def first():
        assert forked_compile.claim(2)
        ran.append(0)
        time.sleep(1.5)  # the helper reaches unit 1 meanwhile

    def mark(unit: int):
        return lambda: (tmp_path / f"unit{unit}-{os.getpid()}").touch()

    here = os.getpid()
    assert compile_on_two_cores([first, mark(1), lambda: ran.append(2), lambda: time.sleep(0.3)])
    assert ran == [0]  # unit 2 was claimed, not run, here
    marks = sorted(p.name for p in tmp_path.iterdir())
    assert len(marks) == 1 and marks[0].startswith("unit1-") and marks[0] != f"unit1-{here}"
