"""Devices through sounddevice, and a sound server that stops answering: both fail fast
with a reason instead of hanging."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]


def jassy_env(**extra):
    return {**os.environ, "PYTHONPATH": str(ROOT), **extra}


@pytest.mark.skipif(Path("/proc/asound/cards").exists(), reason="this machine has ALSA sound cards")
def test_devices_says_when_there_is_no_output_device():
    env = jassy_env(JACK_NO_START_SERVER="1", JACK_DEFAULT_SERVER=f"jassy-none-{os.getpid()}")
    run = subprocess.run(
        [sys.executable, "-m", "jassy", "devices"], env=env, capture_output=True, text=True, timeout=60
    )
    assert run.returncode == 0, run.stderr
    assert run.stdout.strip() == "no output devices found"


def test_devices_lists_the_jack_server_with_sounddevice_indices(jack):
    import json

    from jassy.engines.devices import find_device, output_devices

    found = output_devices()
    listing = subprocess.run(  # sounddevice's own view, in a process of its own
        [sys.executable, "-c", "import json, sounddevice as sd; print(json.dumps(list(sd.query_devices())))"],
        env=jassy_env(),
        capture_output=True,
        text=True,
        timeout=30,
    )
    reference = {d["index"]: d["name"] for d in json.loads(listing.stdout)}
    assert found and all(reference[d.index] == d.name for d in found)
    jack_device = next(d for d in found if "JACK" in d.host_api)
    assert find_device(jack_device.name) == jack_device.index
    assert find_device(str(jack_device.index)) == jack_device.index
    with pytest.raises(Exception, match="--device 'no such device': expected one matching"):
        find_device("no such device")


def test_a_server_that_stops_answering_fails_within_seconds_saying_why():
    import shutil

    from jassy.engines.jackserver import ServerNotAnswering, check_answers, dummy_jack
    from jassy.engines.portaudio import LiveError

    if shutil.which("jackd") is None:
        pytest.skip("jackd is not installed (apt-get install jackd2)")
    try:
        server = dummy_jack(f"jassy-stopped-{os.getpid()}", 48000, 64)
        started = server.__enter__()
    except LiveError as exc:
        pytest.fail(f"JACK dummy server: {exc}")
    os.kill(started.pid, signal.SIGSTOP)  # the socket stays, nothing answers on it
    try:
        t0 = time.monotonic()
        with pytest.raises(ServerNotAnswering, match="does not answer"):
            check_answers(started.name, timeout=2.0)
        assert time.monotonic() - t0 < 5.0
    finally:
        os.kill(started.pid, signal.SIGCONT)
        server.__exit__(None, None, None)


def test_jackd_late_cycles_are_counted_by_cause(tmp_path):
    from jassy.engines.jackserver import server_xruns

    log = tmp_path / "jackd.log"
    log.write_text(  # jackd 1.9's own lines: the dummy driver late twice, a client late once
        "JACK server starting in realtime mode with priority 10\n"
        "JackTimedDriver::Process XRun = 9 usec\n"
        "JackEngine::XRun: client = PortAudio was not finished, state = Triggered\n"
        "JackTimedDriver::Process XRun = 1068 usec\n"
    )
    assert server_xruns(str(log)) == (2, 1)


def test_callback_memory_is_kept_resident_without_changing_it():
    from jassy.engines.memlock import resident

    data = np.arange(300_000, dtype=np.float64)  # 2.4 MB: pages not yet all written
    fresh = np.zeros(100_000)
    locked, touched = resident([data, fresh, data[::2]])  # a strided view is skipped
    assert locked + touched == data.nbytes + fresh.nbytes
    assert np.array_equal(data, np.arange(300_000)) and not fresh.any()
