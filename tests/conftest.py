import itertools
import os
import sys
from pathlib import Path

import pytest
from hypothesis import settings

sys.path.insert(0, str(Path(__file__).parent))

# In CI (CI=true) property tests draw the same examples every run: a landing is judged on
# the code, not on which random inputs a run happened to draw. Locally they stay random.
settings.register_profile("ci", derandomize=True)
if os.environ.get("CI"):
    settings.load_profile("ci")

FS = 48000
_servers = itertools.count()


@pytest.fixture(scope="module")
def jack():
    """A private JACK server with the dummy driver (48 kHz, 64 frames, 4 channels) for the
    module; yields its name. Skipped, saying why, where jackd or libportaudio2 is missing;
    a server that does not answer a client within seconds fails the test, saying so."""
    import ctypes.util
    import shutil

    from jassy.engines.jackserver import dummy_jack

    if ctypes.util.find_library("portaudio") is None:
        pytest.skip("libportaudio2 is not installed (apt-get install libportaudio2)")
    if shutil.which("jackd") is None:
        pytest.skip("jackd is not installed (apt-get install jackd2)")
    from jassy.engines.portaudio import LiveError

    try:
        server = dummy_jack(f"jassy-test-{os.getpid()}-{next(_servers)}", FS, 64, channels=4)
        started = server.__enter__()
    except LiveError as exc:
        pytest.fail(f"JACK dummy server: {exc}", pytrace=False)
    try:
        yield started.name
    finally:
        server.__exit__(None, None, None)


ALONE = "JASSY_TEST_ALONE"


@pytest.fixture
def forking_alone(request):
    """For a test that forks a compile helper: jassy forks only from a process running one
    thread (`jassy.forked_compile.may_fork_helper`), and earlier tests of a suite may leave
    threads behind, so the test runs again by itself in a fresh pytest process, and passes
    only if it passed there. Yields True in that fresh process (run the body), False here
    (the body already ran there). Skipped where no helper can be forked at all."""
    from jassy.forked_compile import may_fork_helper

    if os.environ.get(ALONE) == request.node.nodeid:
        if not may_fork_helper([None, None]):
            pytest.fail("a fresh single-threaded process may not fork a helper", pytrace=False)
        yield True
        return
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
    if cores < 2 or not hasattr(os, "fork"):
        pytest.skip("no helper may be forked here (one core or no fork)")
    import subprocess

    command = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", request.node.nodeid]
    run = subprocess.run(
        command,
        cwd=request.config.rootpath,
        env={**os.environ, ALONE: request.node.nodeid},
        capture_output=True,
        text=True,
        timeout=50,
    )
    assert run.returncode == 0 and "1 passed" in run.stdout, run.stdout[-3000:] + run.stderr[-2000:]
    yield False
