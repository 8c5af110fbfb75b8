"""DCMotor: speed against the first-order motor equation's closed form, and the gear-mesh
and rotor tones at teeth x f_r and f_r from the integrated closed-form rotor angle."""

import math

import numpy as np
import pytest

from jassy import Event, Graph, render
from ugens.dcmotor import REFERENCE_SPEED, SECOND_HARMONIC, DCMotor

FS = 48000
R, K, J, B = 2.0, 0.02, 2e-5, 1e-5
QUIET = {"rotor_level": 0.0, "ripple_level": 0.0, "brush_level": 0.0, "gear_level": 0.0}


def motor(**params):
    return DCMotor(name="m", resistance=R, motor_constant=K, inertia=J, friction=B, **params)


def run(node, score=(), duration=1.0, block=64):
    r = render(Graph(node, haptic=node.tap("rpm")), score, duration=duration, sample_rate=FS, block=block,
               limiter=False)  # fmt: skip
    return r.audio[0], r.haptic[0]


def lag(w0, w_ss, tau, t):
    """Speed and angle (rad) of the first-order lag from w0 towards w_ss after t s."""
    e = np.exp(-t / tau)
    return w_ss + (w0 - w_ss) * e, w_ss * t + (w0 - w_ss) * tau * (1 - e)


def test_startup_load_step_and_coast_down_follow_the_closed_form():
    volts, load, t_load, t_off = 12.0, 0.05, 0.6, 1.2
    g_on, g_off = K * K / R + B, B
    score = [
        Event(t_load, "m", "set", {"load": load}, jump=True),
        Event(t_off, "m", "set", {"switched_on": False}),
    ]
    _, rpm = run(motor(voltage=volts, **QUIET), score, duration=3.0)
    t = np.arange(rpm.size) / FS
    w1, _ = lag(0.0, K * volts / R / g_on, J / g_on, t)
    w2, _ = lag(w1[round(t_load * FS)], (K * volts / R - load) / g_on, J / g_on, t - t_load)
    w3, _ = lag(w2[round(t_off * FS)], -load / g_off, J / g_off, t - t_off)
    expected = np.maximum(np.where(t < t_load, w1, np.where(t < t_off, w2, w3)), 0.0) * 60 / (2 * math.pi)
    assert np.max(np.abs(rpm - expected)) < 1e-6 * np.max(expected)
    assert expected[-1] == 0.0 and np.any(expected[t > t_off] > 1000)  # stopped by the load, after a coast


@pytest.mark.parametrize("teeth", [9, 14])
def test_gear_mesh_tone_follows_the_integrated_speed_during_startup(teeth):
    volts, level = 9.0, 0.2
    g = K * K / R + B
    out, _ = run(motor(voltage=volts, teeth=teeth, **{**QUIET, "gear_level": level}), duration=0.5)
    t = np.arange(out.size) / FS
    w, angle = lag(0.0, K * volts / R / g, J / g, t)
    x = teeth * angle
    expected = level * w / REFERENCE_SPEED * (np.sin(x) + np.sin(2 * x) / 2 + np.sin(3 * x) / 3)
    assert np.max(np.abs(out - expected)) < 1e-6 * level


def test_rotor_tone_is_at_the_rotation_rate_and_grows_as_speed_squared():
    volts, level = 12.0, 0.3
    g = K * K / R + B
    out, _ = run(motor(voltage=volts, **{**QUIET, "rotor_level": level}), duration=0.4)
    t = np.arange(out.size) / FS
    w, angle = lag(0.0, K * volts / R / g, J / g, t)
    expected = level * (w / REFERENCE_SPEED) ** 2 * (np.sin(angle) + SECOND_HARMONIC * np.sin(2 * angle))
    assert np.max(np.abs(out - expected)) < 1e-6 * level


def test_commutation_bursts_at_segments_times_rotation_rate():
    volts, segments = 12.0, 12
    out, rpm = run(motor(voltage=volts, segments=segments, **{**QUIET, "ripple_level": 0.1}), duration=1.0)
    steady = out[FS // 2 :]
    f_r = rpm[-1] / 60
    spectrum = np.abs(np.fft.rfft(steady * np.hanning(steady.size)))
    f = np.fft.rfftfreq(steady.size, 1 / FS)
    assert abs(f[np.argmax(spectrum)] - segments * f_r) <= 2 * (f[1] - f[0])


def test_block_size_invariance():
    def case():
        return motor(voltage=6.0, seed=3), [
            Event(0.05, "m", "set", {"voltage": 12.0}),
            Event(0.1, "m", "set", {"load": 0.03}, ramp=0.05),
            Event(0.2, "m", "set", {"switched_on": False}),
        ]

    outs = [run(*case(), duration=0.3, block=block)[0] for block in (1, 64, 1000)]
    assert np.any(outs[0] != 0)
    for out in outs[1:]:
        assert np.max(np.abs(out - outs[0])) < 1e-9
