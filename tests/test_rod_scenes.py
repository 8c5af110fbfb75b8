"""Rod contact scenes: archery (physics and rendered sound), snap-fit, stack of shells, bicycle on a rope."""

import warnings

import numpy as np
import pytest
import scipy.io.wavfile as wavfile

from physics.rod.contact_experiments import bicycle_on_rope, run_archery, shell_stack, snap_fit


@pytest.fixture(scope="module")
def shot():
    return run_archery()


def test_archery_energy_and_ballistic_flight(shot):
    s = shot.summary
    assert s["max_residual"] < 1e-8
    assert 0.3 < s["efficiency"] < 1.0  # arrow kinetic energy below the stored draw energy
    assert s["draw_force_n"] > 0 and s["brace_tension_n"] > 0
    # free flight after the power stroke and before the hit: x linear, y'' = -g (no drag)
    t0 = shot.release_time + s["power_stroke_ms"] * 1e-3 + 5e-3
    free = shot.arrow[(shot.arrow[:, 0] > t0) & (shot.arrow[:, 0] < shot.hit_time - 5e-3)]
    tt = free[:, 0] - free[0, 0]
    assert np.polyfit(tt, free[:, 2], 2)[0] == pytest.approx(-9.81 / 2, rel=0.02)
    cx = np.polyfit(tt, free[:, 1], 2)
    assert abs(cx[0]) < 1e-3 * abs(cx[1])
    # the hit happens when the tip disk reaches the target plane
    x_hit = np.interp(shot.hit_time, shot.arrow[:, 0], shot.arrow[:, 1]) + 0.375 + 3e-3
    assert x_hit == pytest.approx(3.0, abs=2e-3 + 5e-4 * s["arrow_speed_m_s"])
    assert any(set(ev.bodies) == {3, 5} and np.isfinite(ev.impulse) and ev.impulse > 0 for ev in shot.impacts)


def test_archery_render(shot, tmp_path):
    from patches.archery import render_archery
    from patches.scene_io import PEAK

    wav, csv, hap = tmp_path / "a.wav", tmp_path / "a.csv", tmp_path / "h.csv"
    info = render_archery(wav, haptic_path=hap, csv_path=csv, result=shot)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sr, x = wavfile.read(wav)
    x = x.astype(np.float64).reshape(len(x), -1)[:, 0]
    assert np.all(np.isfinite(x))
    assert np.max(np.abs(x)) == pytest.approx(PEAK, rel=1e-3)
    spec = np.abs(np.fft.rfft(x * np.hanning(len(x))))
    f = np.fft.rfftfreq(len(x), 1 / sr)
    for f0 in (info["bow_f1_hz"], info["string_f1_hz"]):
        peak = spec[np.abs(f - f0) < 1.5].max()
        near = np.median(spec[((f > 0.6 * f0) & (f < 0.85 * f0)) | ((f > 1.2 * f0) & (f < 1.5 * f0))])
        assert peak > 5 * near
    # the string's fundamental from the brace tension: c / 2L
    c = np.sqrt(info["brace_tension_n"] / 2e-3)
    assert info["string_f1_hz"] == pytest.approx(c / (2 * info["string_length_m"]))
    rows = np.loadtxt(csv, delimiter=",", skiprows=1)
    assert rows.shape[1] == 4 and np.all(np.isfinite(rows))
    assert hap.stat().st_size > 0


def test_snap_fit_friction_widens_the_force_loop():
    loops = {}
    for mu in (0.0, 0.4):
        r = snap_fit("I", n=12, mu=mu, speed=0.2)
        assert r["max_residual"] < 1e-8
        x, fo = np.array(r["displacement_m"]), np.array(r["force_n"])
        half = int(np.argmax(x))
        assert r["peak_assembly_force_n"] > 0 and r["peak_removal_force_n"] > 0
        # free approach (before the tips reach the cylinder): only the ring's small start-up ringing
        assert np.max(np.abs(fo[: max(1, int(0.15 * half))])) < 0.1 * r["peak_assembly_force_n"]
        loops[mu] = np.trapezoid(fo[: half + 1], x[: half + 1]) + np.trapezoid(fo[half:], x[half:])
    assert loops[0.4] > loops[0.0] + 1e-4  # frictional work (J) added by the loop


def test_shell_stack_soft_shells_sag_more():
    stiff = shell_stack(gamma=0.1, shells=2, n=8, duration=0.2)
    soft = shell_stack(gamma=10.0, shells=2, n=8, duration=0.2)
    for r in (stiff, soft):
        assert r["max_residual"] < 1e-8
    assert np.allclose(stiff["apex_over_rest"], 1.0, atol=0.03)  # nearly rigid shells keep their height
    assert max(soft["apex_over_rest"]) < min(stiff["apex_over_rest"]) - 0.05


@pytest.mark.slow
def test_bicycle_crosses_the_rope():
    r = bicycle_on_rope(torque=15.0)
    assert r["crossed"] and r["max_residual"] < 1e-8
    assert r["min_frame_y_m"] > 0.3  # stayed on the rope
