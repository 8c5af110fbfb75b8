"""The device loop over UDP: probe poses in, haptic frames out, and a device side
(``jassy haptic-bridge``) that lets go within 10 ms whatever happens to the engine."""

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from processes import read_line, rest_of_output

from jassy.apps.bridge import FADE, GAP, ForceOutput
from jassy.engines.hapticframes import FLAG_FINAL
from jassy.engines.probeinput import BUTTON_MAIN, PoseDriver, decode_pose, encode_pose
from jassy.errors import JassyError
from jassy.events import Event

ROOT = Path(__file__).resolve().parents[1]


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_pose_datagrams_round_trip_and_reject_bad_input():
    data = encode_pose(12, 3.5, (0.1, -0.02, 0.003), (0.0, 1.0, 0.0, 0.0), BUTTON_MAIN)
    pose = decode_pose(data, received=4.0)
    assert len(data) == 52 and data[:4] == b"JPOS"
    assert (pose.sequence, pose.sent, pose.buttons, pose.received) == (12, 3.5, BUTTON_MAIN, 4.0)
    np.testing.assert_allclose(pose.position, (0.1, -0.02, 0.003), rtol=1e-6)
    assert pose.touching  # button held, though above the surface
    with pytest.raises(JassyError, match="expected 52"):
        decode_pose(data[:-1])
    with pytest.raises(JassyError, match="finite"):
        encode_pose(0, 0.0, (np.nan, 0.0, 0.0))


def test_poses_drive_the_probe_as_the_pointer_does():
    from patches.demo import Probe

    events: list[Event] = []
    probe = Probe(events.append, width=0.5, live=True)
    drive = PoseDriver(probe, length=0.5)
    for k, (x, z) in enumerate([(0.1, 0.01), (0.1, -0.001), (0.15, -0.001), (0.2, -0.001), (0.2, 0.01)]):
        drive(decode_pose(encode_pose(k, 0.0, (x, 0.0, z)), received=k * 0.01))
    actions = [(e.node, e.action) for e in events]
    assert actions[:3] == [("plate", "set"), ("tap", "impact"), ("contact", "set")]  # touch down: a tap
    speeds = [e.args["speed"] for e in events if e.node == "contact" and "speed" in e.args][1:3]
    np.testing.assert_allclose(speeds, [0.05 / 0.01, 0.05 / 0.01], rtol=1e-5)  # 5 cm per 10 ms
    assert events[-1].args == {"force": 0.0, "speed": 0.0}  # lift off: released
    assert probe.x == pytest.approx(0.4, rel=1e-5) and not probe.touching


def test_the_device_side_fades_to_zero_after_silence_or_the_final_frame():
    out = ForceOutput()
    out.take(np.array([2.0]), 0, now=1.0)
    assert out(1.0 + GAP - 1e-6) == (pytest.approx([2.0]), False)
    force, letting_go = out(1.0 + GAP + FADE / 2)
    assert letting_go and force[0] == pytest.approx(1.0)
    assert out(1.0 + GAP + FADE + 1e-9)[0][0] == 0.0
    out.take(np.array([3.0]), 0, now=2.0)  # frames again: force follows them
    assert out(2.0005)[0][0] == 3.0
    out.take(np.array([0.0]), FLAG_FINAL, now=2.001)
    assert out(2.001 + FADE + 1e-9)[0][0] == 0.0 and GAP + FADE < 0.010


def test_kill_9_of_the_engine_bridge_force_reaches_zero_within_10_ms(jack, tmp_path):
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    probe_port, frame_port = free_port(), free_port()
    log = tmp_path / "bridge.csv"
    engine = subprocess.Popen(
        [sys.executable, "-m", "jassy", "demo", "--headless", "--mode", "scrape",
         "--probe-udp", f"127.0.0.1:{probe_port}", "--haptic-udp", f"127.0.0.1:{frame_port}"],
        env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
    )  # fmt: skip
    bridge = None
    try:
        ready = read_line(engine)
        assert "running headless" in ready, ready + rest_of_output(engine)
        bridge = subprocess.Popen(
            [sys.executable, "-m", "jassy", "haptic-bridge", "--engine", f"127.0.0.1:{probe_port}",
             "--listen", f"127.0.0.1:{frame_port}", "--log", str(log)],
            env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
        )  # fmt: skip
        assert "haptic bridge" in read_line(bridge)
        time.sleep(1.0)  # the scripted stroke touches the plate from 0.2 s to 1.4 s
        killed_at = time.monotonic()
        engine.kill()
        engine.wait(timeout=10)
        time.sleep(0.2)
        bridge.send_signal(signal.SIGTERM)
        assert bridge.wait(timeout=20) == 143
    finally:
        for proc in (engine, bridge):
            if proc is not None and proc.poll() is None:
                proc.kill()
    ticks = np.genfromtxt(log, delimiter=",", names=True)
    t, force = ticks["time_s"], ticks["force_0_n"]
    before = (t > killed_at - 0.2) & (t < killed_at)
    pressing = force[before]  # the scraping contact's force: rough, but never still
    assert pressing.size > 100 and np.all(pressing != 0), "the probe was not touching when the engine died"
    after = t >= killed_at
    first_zero = t[after & (force == 0)][0]
    assert first_zero - killed_at <= 0.010
    assert np.all(force[after & (t > first_zero)] == 0)
