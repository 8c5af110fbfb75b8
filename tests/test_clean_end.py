"""Live commands end cleanly on SIGINT, SIGTERM and SIGHUP: forces fade to zero, the
final haptic frame goes out, the stream stops, no process outlives the command, and the
exit status is 128 + the signal number."""

import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from jassy.engines.hapticframes import FLAG_FINAL, FLAG_WATCHDOG, FrameRecorder

ROOT = Path(__file__).resolve().parents[1]


def session_processes(sid: int) -> list[int]:
    """Pids of the live processes in session ``sid`` (zombies excluded)."""
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        state, session = fields[0], int(fields[3])
        if session == sid and state != "Z":
            found.append(int(entry.name))
    return found


def start_command(args: list[str]) -> tuple[subprocess.Popen, list[str]]:
    """Start ``python -m jassy ARGS`` in a session of its own; collect its output lines."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "jassy", *args],
        env={**os.environ, "PYTHONPATH": str(ROOT)},
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        start_new_session=True,
    )
    lines: list[str] = []
    threading.Thread(target=lambda: lines.extend(proc.stdout), daemon=True).start()
    return proc, lines


def wait_for(lines: list[str], text: str, proc: subprocess.Popen, seconds: float = 60.0) -> None:
    deadline = time.monotonic() + seconds
    while not any(text in line for line in lines):
        if proc.poll() is not None or time.monotonic() > deadline:
            proc.kill()
            pytest.fail(f"no {text!r} from the command: {''.join(lines)[-2000:]}")
        time.sleep(0.05)


@pytest.fixture
def short_patch(tmp_path):
    """The bar patch with a 0.5 s duration (the play must not stop there)."""
    text = (ROOT / "patches" / "bar.toml").read_text().replace("duration = 5.0", "duration = 0.5", 1)
    path = tmp_path / "short_bar.toml"
    path.write_text(text)
    (tmp_path / "bar_model.toml").write_text((ROOT / "patches" / "bar_model.toml").read_text())
    return path


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP])
def test_each_ending_signal_raises_stopped_once_and_maps_to_its_exit_status(sig):
    from jassy.engines.signals import Stopped, stop_on_signals

    before = signal.getsignal(sig)
    cleaned = []
    with pytest.raises(Stopped) as caught, stop_on_signals():
        try:
            os.kill(os.getpid(), sig)
            time.sleep(5)  # interrupted by the signal
        finally:
            os.kill(os.getpid(), sig)  # a second signal during the cleanup is ignored
            cleaned.append(True)
    assert cleaned == [True]
    assert caught.value.exit_code == {signal.SIGINT: 130, signal.SIGTERM: 143, signal.SIGHUP: 129}[sig]
    assert signal.getsignal(sig) == before  # the previous handler is back


def test_play_ends_cleanly_on_sigterm_with_no_process_left(jack, short_patch):
    sig = signal.SIGTERM
    recorder = FrameRecorder()
    proc, lines = start_command(
        # the ring mode has child processes (producer, UDP sender) whose end this checks
        [
            "play",
            str(short_patch),
            "--duration",
            "0",
            "-q",
            "--mode",
            "ring",
            "--haptic-udp",
            recorder.address,
        ]
    )
    try:
        wait_for(lines, "until stopped", proc)
        time.sleep(1.5)  # beyond the patch's 0.5 s: --duration 0 plays until stopped
        assert proc.poll() is None, "".join(lines)
        family = session_processes(proc.pid)
        assert len(family) >= 3  # the command, its producer and its UDP sender
        os.kill(proc.pid, sig)
        code = proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert code == 128 + sig, "".join(lines)
    assert session_processes(proc.pid) == []  # nothing outlives the command
    assert recorder.wait_final(2.0), "no final frame"
    frames = recorder.stop()
    assert frames[-1].flags & FLAG_FINAL and np.all(frames[-1].force == 0)
    assert frames[-1].sample_time >= 0.6 * 48000  # it played on past the patch's 0.5 s
    # before the final frame: the fade (flagged) down to zero force
    fade = [f for f in frames if f.flags & FLAG_WATCHDOG]
    assert fade and frames[-2].force[0] == 0.0
    assert "stopped by " + signal.Signals(sig).name in "".join(lines)
