"""Calibrated levels of the closed-loop modal sources (Friction, HuntCrossleyImpact) and the
physical chain force (N) -> displacement (m) -> sound pressure (Pa) at a distance."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from jassy import Event, Graph, ModalModel, render
from jassy.levels import reference_gain
from ugens import Friction, HuntCrossleyImpact, Sine, SoundPressure
from ugens.pressure import sphere_pressure

FS = 48000
PASCAL = 20 * math.log10(1 / 20e-6)  # full_scale_spl of an output in Pa
PATCHES = Path(__file__).resolve().parents[1] / "patches"
F0, DECAY, GAIN = 300.0, 20.0, 2e-3  # one mode: Hz, 1/s, m per N s
FORCE = 0.5  # N, amplitude of the sinusoidal strike force


def one_mode() -> ModalModel:
    return ModalModel([F0], [DECAY], [[GAIN]], ("p",), "one")


def steady(y: np.ndarray, freq: float) -> float:
    """Amplitude of the last 0.2 s of ``y`` at ``freq`` (least squares sine + cosine)."""
    n = int(0.2 * FS)
    t = np.arange(len(y))[-n:] / FS
    basis = np.stack([np.sin(2 * np.pi * freq * t), np.cos(2 * np.pi * freq * t)], axis=1)
    coef, *_ = np.linalg.lstsq(basis, y[-n:], rcond=None)
    return float(np.hypot(*coef))


def mode_amplitude(freq: float) -> float:
    """|q| of q'' + 2 d q' + (w0^2 + d^2) q = a w0 F sin(w t) in steady state (m): the
    resonator convention of ModalBank and Friction."""
    w0, w = 2 * math.pi * F0, 2 * math.pi * freq
    return GAIN * w0 * FORCE / abs(complex(w0 * w0 + DECAY * DECAY - w * w, 2 * DECAY * w))


def strike_through_friction(freq: float, **friction) -> np.ndarray:
    """A rub with no normal force (no contact) and a sinusoidal strike force on the mode."""
    strike = Sine(name="strike", freq=freq, amp=FORCE)
    rub = Friction(one_mode(), name="rub", **friction)(strike=strike)
    out = SoundPressure(
        rub, name="p", radius=0.05, distance=1.0, input_kind="displacement", full_scale_spl=PASCAL
    )
    rendering = render(Graph([rub, out]), [], duration=0.6, sample_rate=FS, limiter=False)
    return rendering.audio


@pytest.mark.parametrize("freq", [F0, 250.0, 400.0])
def test_a_known_force_through_one_mode_gives_the_analytic_amplitude_and_pressure(freq):
    displacement, pressure = strike_through_friction(freq)
    x = mode_amplitude(freq)
    assert steady(displacement, freq) == pytest.approx(x, rel=1e-3)
    w = 2 * math.pi * freq
    first_difference = 2 * math.sin(w / FS / 2) * FS / w
    expected = sphere_pressure(freq, w * x * first_difference, 0.05, 1.0)
    assert steady(pressure, freq) == pytest.approx(float(expected), rel=3e-3)


def test_calibrated_friction_is_the_reference_gain_times_the_analytic_amplitude():
    calibrated = strike_through_friction(F0, level="calibrated")[0]
    g = reference_gain(one_mode(), FS)
    assert steady(calibrated, F0) == pytest.approx(g * mode_amplitude(F0), rel=1e-3)


def rubbed(model: ModalModel, location: str, level: str) -> tuple[np.ndarray, np.ndarray]:
    """(heard output, contact displacement) of a rub."""
    rub = Friction(model, name="rub", location=location, level=level, sigma0=1e7)
    events = [Event(0.01, "rub", "set", {"force": 2.0, "speed": 0.05})]
    r = render(Graph(rub, haptic=[rub.tap("contact")]), events, duration=0.3, sample_rate=FS, limiter=False)
    return r.audio[0], r.haptic[0]


@pytest.mark.parametrize(
    ("filename", "location"), [("wine_glass_model.toml", "rim"), ("steel_plate_model.toml", "t3")]
)
def test_calibration_scales_what_is_heard_and_leaves_the_friction_loop_alone(filename, location):
    """Pickup at the contact (glass) and signed pickup gains (plate): the same motion, heard
    times the model's reference gain."""
    model = ModalModel.load(PATCHES / filename)
    raw, raw_contact = rubbed(model, location, "raw")
    calibrated, contact = rubbed(model, location, "calibrated")
    assert np.abs(raw).max() > 0
    np.testing.assert_array_equal(contact, raw_contact)  # the loop itself: bit for bit
    # heard: scaled coefficients round differently over 0.3 s of up to 675 modes (3e-12 of the peak)
    np.testing.assert_allclose(
        calibrated, raw * reference_gain(model, FS), rtol=1e-9, atol=1e-11 * np.abs(calibrated).max()
    )


@pytest.mark.parametrize(
    ("filename", "location"), [("wine_glass_model.toml", "rim"), ("steel_plate_model.toml", "t2")]
)
def test_calibrated_hunt_crossley_is_the_raw_sound_times_the_reference_gain(filename, location):
    model = ModalModel.load(PATCHES / filename)
    outputs = []
    for level in ("raw", "calibrated"):
        hammer = HuntCrossleyImpact(model, name="hammer", location=location, level=level)
        events = [Event(0.01, "hammer", "strike", {"speed": 1.0})]
        outputs.append(render(Graph(hammer), events, duration=0.2, sample_rate=FS, limiter=False).audio[0])
    raw, calibrated = outputs
    assert np.abs(raw).max() > 0
    np.testing.assert_allclose(
        calibrated, raw * reference_gain(model, FS), rtol=1e-9, atol=1e-12 * np.abs(calibrated).max()
    )


def test_a_dropped_object_rings_a_calibrated_mode_at_the_level_its_momentum_predicts():
    """Bounce (force in N) dropped from h: the first impact exchanges J = m sqrt(2 g h)
    (1 + e) N s as a 1 - cos pulse of tau; an undamped mode a sin(w t) then rings at
    a J |sinc(f tau) / (1 - (f tau)^2)|, times the reference gain when calibrated, until the
    next impact 2 e sqrt(2 g h) / g later."""
    from ugens import Bounce, ModalBank

    f, a, m, e, h, tau = 300.0, 1e-3, 0.01, 0.7, 0.2, 5e-4
    model = ModalModel([f], [0.0], [[a]])
    ball = Bounce(name="ball", mass=m, restitution=e, duration=tau)
    bank = ModalBank(model, name="plate", level="calibrated")(ball)
    y = render(
        Graph(bank), [Event(0.0, "ball", "drop", {"height": h})], duration=0.5, sample_rate=FS, limiter=False
    )
    v = math.sqrt(2 * 9.81 * h)
    first = math.sqrt(2 * h / 9.81)  # the fall
    second = first + 2 * e * v / 9.81  # the first flight
    ringing = y.audio[0][int((first + 0.01) * FS) : int((second - 0.001) * FS)]
    x = f * tau
    expected = (
        reference_gain(model, FS)
        * a
        * m
        * v
        * (1 + e)
        * abs(math.sin(math.pi * x) / (math.pi * x) / (1 - x * x))
    )
    assert np.abs(ringing).max() == pytest.approx(expected, rel=2e-3)


@pytest.mark.parametrize(
    "patch", ["examples/wine_glass.toml", "examples/door_knock.toml", "examples/pot.toml", "rain"]
)
def test_the_examples_need_no_gains_and_sound_between_minus_30_and_minus_6_dbfs(patch):
    """Forces in N to sound pressure at a listening distance: no Gain nodes, mixers at unity,
    the peak within -30..-6 dBFS (re 105 dB SPL) and the limiter idle."""
    from jassy.patchfile import load_patch

    root = Path(__file__).resolve().parents[1]
    loaded = load_patch(root / patch if patch.endswith(".toml") else patch)
    nodes = loaded.graph.nodes.values()
    assert not [n.name for n in nodes if n.type_name == "Gain"]
    mixers = [n.values["gains"] for n in nodes if n.type_name == "Mixer"]
    assert all(gains is None or np.all(np.asarray(gains) == 1.0) for gains in mixers)  # None: all 1
    assert [n.type_name for n in loaded.graph.audio] == ["SoundPressure"]
    result = render(loaded.graph, loaded.score, loaded.duration, sample_rate=FS)
    peak = 20 * math.log10(float(np.abs(result.audio).max()))
    assert -30.0 <= peak <= -6.0, f"{patch}: {peak:.1f} dBFS"
    assert not result.warnings
