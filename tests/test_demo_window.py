"""The demo window under Xvfb: driven by the UDP probe input along a scripted path, its
screenshots show the plate (not a blank canvas) and change where the probe moved."""

import contextlib
import math
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from processes import read_line, rest_of_output

from jassy.engines.probeinput import encode_pose

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def xvfb():
    """A virtual X display for the module; skipped, saying why, where Xvfb or Pillow's X
    screenshots are missing."""
    if shutil.which("Xvfb") is None:
        pytest.skip("Xvfb is not installed (apt-get install xvfb)")
    pytest.importorskip("PIL.ImageGrab", reason="screenshots need Pillow (pip install pillow)")
    number = 90 + os.getpid() % 500
    proc = subprocess.Popen(
        ["Xvfb", f":{number}", "-screen", "0", "800x600x24", "-nolisten", "tcp"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    deadline = time.monotonic() + 10
    while not Path(f"/tmp/.X11-unix/X{number}").exists():
        if proc.poll() is not None or time.monotonic() > deadline:
            proc.kill()
            pytest.fail(f"Xvfb :{number} did not start within 10 s")
        time.sleep(0.05)
    yield f":{number}"
    proc.terminate()
    proc.wait(timeout=5)


def screenshot(display: str) -> np.ndarray:
    from PIL import ImageGrab

    return np.asarray(ImageGrab.grab(xdisplay=display).convert("RGB")).astype(int)


def send_path(sock, port, points, seconds_each=0.3, rate=200.0):
    """Hold each (x m, z m) pose of ``points`` for ``seconds_each`` at ``rate`` Hz."""
    k = 0
    for x, z in points:
        end = time.monotonic() + seconds_each
        while time.monotonic() < end:
            sock.sendto(encode_pose(k, time.monotonic(), (x, 0.0, z)), ("127.0.0.1", port))
            k += 1
            time.sleep(1.0 / rate)


@contextlib.contextmanager
def demo_window(mode: str, display: str):
    """``jassy demo --mode MODE`` on ``display`` with its probe on a free UDP port, its
    window open on entry; yields ``move(points, seconds_each)`` (see :func:`send_path`).
    Leaving the block normally, the demo must end on SIGTERM with exit code 143."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    proc = subprocess.Popen(
        [sys.executable, "-m", "jassy", "demo", "--mode", mode, "--probe-udp", f"127.0.0.1:{port}"],
        env={**os.environ, "PYTHONPATH": str(ROOT), "DISPLAY": display},
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        line = read_line(proc)
        assert "window open" in line, line + rest_of_output(proc)
        yield lambda points, seconds_each=0.3: send_path(sock, port, points, seconds_each)
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=30) == 143
    finally:
        sock.close()
        if proc.poll() is None:
            proc.kill()


def test_the_window_draws_the_plate_and_the_probe_where_it_moves(jack, xvfb, tmp_path):
    from patches.demo_view import HEIGHT, WIDTH, DemoView

    with demo_window("scrape", xvfb) as move:
        move([(0.1, 0.01)], seconds_each=0.5)  # hovering at 20 % of the track
        hover = screenshot(xvfb)
        # touch down there, slide to 80 % and stay pressed
        move([(0.1, -0.001)] + [(0.1 + 0.02 * k, -0.001) for k in range(1, 16)], 0.02)
        move([(0.4, -0.001)], seconds_each=0.3)
        pressed = screenshot(xvfb)
        arrows = []  # scraping to and fro on the spot (+-3 mm at 5 Hz): the force vector shows
        wiggle = [(0.4 + 0.003 * np.sin(2 * np.pi * k / 40), -0.001) for k in range(40)]
        for _ in range(4):
            move(wiggle, seconds_each=0.005)
            arrows.append(screenshot(xvfb))
    from PIL import Image

    Image.fromarray(hover.astype(np.uint8)).save(tmp_path / "hover.png")
    Image.fromarray(pressed.astype(np.uint8)).save(tmp_path / "pressed.png")
    for k, shot in enumerate(arrows):
        Image.fromarray(shot.astype(np.uint8)).save(tmp_path / f"scraping{k}.png")
    canvas = hover[:HEIGHT, :WIDTH]
    # not a blank canvas: the plate's modal texture has many shades and real contrast
    assert len(np.unique(canvas.reshape(-1, 3), axis=0)) > 200 and canvas.std() > 20
    changed = np.any(pressed[:HEIGHT, :WIDTH] != canvas, axis=2)
    changed[HEIGHT - 30 :] = False  # the meters' text changes all the time
    ys, xs = np.nonzero(changed)
    view = DemoView.__new__(DemoView)
    start, end = view.track_point(0.2), view.track_point(0.8)
    near_start = np.hypot(xs - start[0], ys - start[1]) < 30
    near_end = (np.abs(xs - end[0]) < 30) & (ys > end[1] - 40) & (ys < end[1] + 140)  # probe, force arrow
    assert near_start.sum() > 50 and near_end.sum() > 50  # the probe left one place, appeared at the other
    assert np.all(near_start | near_end), "pixels changed where the probe never was"
    green = [np.all(shot[:HEIGHT, :WIDTH] == (64, 255, 128), axis=2) for shot in arrows]
    below = [np.nonzero(g) for g in green]
    # the arrow hangs down from the contact point, which the +-3 mm wiggle moves by a few px
    assert any(
        ys.size > 20
        and np.all(np.abs(xs - end[0]) < 10)
        and np.all(ys >= end[1] - 10)
        and ys.max() - ys.min() >= 5
        for ys, xs in below
    )


def lens_area(R: float, r: float, d: float) -> float:
    """Area shared by two circles of radii R and r whose centres are d apart."""
    a = r * r * math.acos((d * d + r * r - R * R) / (2 * d * r))
    b = R * R * math.acos((d * d + R * R - r * r) / (2 * d * R))
    return a + b - 0.5 * math.sqrt((-d + r + R) * (d + r - R) * (d - r + R) * (d + r + R))


@pytest.mark.timeout(240)  # the ball's Green's functions and contact kernels load for ~30 s
def test_poke_window_dents_the_ball_where_the_probe_presses(jack, xvfb, tmp_path):
    from patches.demo_view import BALL_CENTRE, BALL_SCALE, HEIGHT, WIDTH

    top = 0.25  # m: the middle of the 0.5 m the probe input maps to -45..45 degrees: the top
    with demo_window("poke", xvfb) as move:
        move([(top, 0.01)], seconds_each=0.5)  # hovering over the top
        hover = screenshot(xvfb)[:HEIGHT, :WIDTH]
        move([(top, -0.001)], seconds_each=0.8)  # pressed: sinks 8 mm at 5 cm/s
        pressed = screenshot(xvfb)[:HEIGHT, :WIDTH]
        move([(top, 0.01)], seconds_each=0.8)  # lifted: the ball is round again
        lifted = screenshot(xvfb)[:HEIGHT, :WIDTH]

    from PIL import Image

    for name, shot in (("hover", hover), ("pressed", pressed), ("lifted", lifted)):
        Image.fromarray(shot.astype(np.uint8)).save(tmp_path / f"poke_{name}.png")

    def ball(shot):
        return np.all(shot == (0xC0, 0x50, 0x4D), axis=2)  # the ball's fill

    R, r = 0.05 * BALL_SCALE, 0.015 * BALL_SCALE  # ball and probe sphere radii (px)
    # hovering: a round ball (its 2 px outline inside the radius)
    assert ball(hover).sum() == pytest.approx(math.pi * (R - 1) ** 2, rel=0.03)
    assert ball(lifted).sum() == pytest.approx(ball(hover).sum(), rel=0.01)
    # pressed 8 mm deep: the probe sphere's overlap with the ball is cut out of it, at the top
    dent = ball(hover) & ~ball(pressed)
    depth = 0.008 * BALL_SCALE
    assert dent.sum() == pytest.approx(lens_area(R, r, R + r - depth), rel=0.3)
    ys, xs = np.nonzero(dent)
    cx, cy = BALL_CENTRE
    assert np.all(np.abs(xs - cx) < r + 3) and np.all(ys < cy - R + depth + 4)
    # the force on the probe points up, out of the ball: a green arrow from the dent's floor
    gy, gx = np.nonzero(np.all(pressed == (0x40, 0xFF, 0x80), axis=2))
    floor = cy - R + depth
    assert gy.size > 20 and np.all(np.abs(gx - cx) < 8) and gy.max() <= floor + 6 and gy.min() < floor - 10
    assert not np.all(lifted == (0x40, 0xFF, 0x80), axis=2).any()  # no force once lifted


@pytest.mark.timeout(180)
def test_drill_window_removes_bone_under_the_burr(jack, xvfb, tmp_path):
    from patches.demo_view import HEIGHT, WIDTH

    middle = 0.25  # m: the middle of the 0.5 m the probe input maps across the bone slice
    with demo_window("drill", xvfb) as move:
        move([(middle, 0.01)], seconds_each=0.5)  # hovering
        hover = screenshot(xvfb)[:HEIGHT, :WIDTH]
        move([(middle, -0.001)], seconds_each=1.5)  # drilling
        early = screenshot(xvfb)[:HEIGHT, :WIDTH]
        move([(middle, -0.001)], seconds_each=1.5)
        late = screenshot(xvfb)[:HEIGHT, :WIDTH]
    from PIL import Image

    for name, shot in (("hover", hover), ("early", early), ("late", late)):
        Image.fromarray(shot.astype(np.uint8)).save(tmp_path / f"drill_{name}.png")
    r, g, b = (hover[..., k] for k in range(3))
    bone = (r > 0) & (np.abs(g - 0.92 * r) <= 1) & (np.abs(b - 0.8 * r) <= 1)  # grey, 0.92, 0.8

    def hole(shot):  # bone before, a voxel with no bone left now
        return bone & np.all(shot == (32, 38, 46), axis=2)

    assert len(np.unique(hover[bone], axis=0)) > 20  # the slice's grey levels, not a blank canvas
    ys, xs = np.nonzero(hole(late))
    burr = np.nonzero(np.all(late == (0xFF, 0xD0, 0x40), axis=2))[1]  # the burr's outline
    assert xs.size > 100  # bone removed ...
    assert burr.min() - 2 <= xs.min() and xs.max() <= burr.max() + 2  # ... only under the burr
    # and it stays removed, where the slice shows (the burr, the contact point and the force
    # arrow are drawn over it, and the deeper burr's arrow crosses the earlier hole)
    lr, lg, lb = (late[..., k] for k in range(3))
    slice_shows = np.all(late == (32, 38, 46), axis=2) | (
        (lr > 0) & (np.abs(lg - 0.92 * lr) <= 1) & (np.abs(lb - 0.8 * lr) <= 1)
    )
    assert np.all(hole(early)[slice_shows] <= hole(late)[slice_shows]) and hole(early).sum() < xs.size
