"""The level convention of sources (jassy.levels): every source is classified, and the
level rules of the sources that sound by themselves hold on rendered output (closed forms:
Campbell's theorem for a bubble stream, the v^3 law of flow noise, the jet band at a
cavity's resonance)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import signal

import ugens
from jassy import Event, Graph, render
from jassy.levels import (
    CALIBRATED_LOOPS,
    FORCE_SOURCES,
    MODEL_CALIBRATED_SOURCES,
    SIGNALS,
    SOUND_SOURCES,
    WATER_DENSITY,
    bubble_gain,
    bubble_stream_rms,
    cavity_tone_rms,
)
from jassy.registry import ugen_types
from ugens.wind import END_CORRECTION

FS = 48000


def rendered(ugen, duration):
    return render(Graph(ugen), [], duration=duration, sample_rate=FS, limiter=False).audio[0]


def test_every_source_has_a_level_convention():
    """Each ugen that needs no input is in exactly one class of jassy.levels."""
    classes = [set(FORCE_SOURCES), set(MODEL_CALIBRATED_SOURCES), set(CALIBRATED_LOOPS), set(SIGNALS)]
    classes.append(set(SOUND_SOURCES))
    sources = {
        name
        for name, cls in ugen_types().items()
        if not set(cls.inputs) - set(getattr(cls, "optional_inputs", ()))
    }
    counts = {name: sum(name in c for c in classes) for name in sources}
    assert {n: k for n, k in counts.items() if k != 1} == {}
    assert set().union(*classes) <= sources


def power_law_radii(rng, n, lo, hi, exponent):
    """Radii with density ~ r^-exponent on [lo, hi] by rejection from a uniform draw."""
    out = np.empty(0)
    while out.size < n:
        r = rng.uniform(lo, hi, 4 * n)
        keep = rng.uniform(0.0, 1.0, r.size) < (r / lo) ** -exponent
        out = np.concatenate([out, r[keep]])
    return out[:n]


@pytest.mark.timeout(300)  # a cold numba compile on a loaded machine, not a hang
@pytest.mark.parametrize(
    "params, overlap",
    [
        ({}, 0.0),  # the defaults: 100 /s, 1-5 mm, r^-1.5, depth 0.5-1: bubbles rarely overlap
        ({"rate": 2000.0, "min_radius": 2e-3, "max_radius": 3e-3, "exponent": 0.0, "max_voices": 256}, 1.0),
    ],
)
def test_bubble_stream_rms_is_campbells_theorem(params, overlap):
    node = ugens.BubbleStream(name="b", seed=3, **params)
    v = node.values
    args = [v[k] for k in ("rate", "min_radius", "max_radius", "exponent", "min_depth", "max_depth", "gain")]
    predicted = bubble_stream_rms(*args)
    duration = 40.0
    x = rendered(node, duration)
    # the estimate's spread: mean square over T of a shot noise ~ sqrt(E[e^2] / (rate T)) / E[e],
    # e a bubble's energy, from Monte Carlo radii and depths (independent of the quadrature)
    rng = np.random.default_rng(0)
    r = power_law_radii(rng, 200_000, v["min_radius"], v["max_radius"], v["exponent"])
    depth = rng.uniform(v["min_depth"], v["max_depth"], r.size)
    d = 0.13 / r + 0.0072 * r**-1.5
    a = v["gain"] * depth * (r / 1e-3) ** 1.5
    e = a**2 / (4 * d)  # energy of a e^{-dt} sin(w0 t), w0 >> d
    dc = v["rate"] * np.mean(a * r / (2 * math.pi * 3.0))  # rate E[int p dt] = rate E[a / w0]
    assert math.sqrt(v["rate"] * e.mean() + dc**2) == pytest.approx(predicted, rel=0.01)
    # plus, where bubbles overlap, a Gaussian noise's 1 / sqrt(d T) (its power estimated over
    # T with correlation time 1 / d; the slowest decay taken: conservative)
    spread = math.hypot(
        math.sqrt(np.mean(e**2) / (v["rate"] * duration)) / e.mean(), overlap / math.sqrt(d.min() * duration)
    )
    measured = float(np.mean(x**2))
    assert abs(measured / predicted**2 - 1) < 4 * spread, (measured, predicted**2, spread)


@pytest.mark.timeout(300)  # a cold numba compile on a loaded machine, not a hang
def test_wind_rms_is_its_level_at_10_m_s_and_grows_as_speed_cubed():
    for speed in (10.0, 20.0):
        x = rendered(ugens.Wind(name="w", speed=speed, gustiness=0.0, level=0.05), 4.0)
        assert np.sqrt(np.mean(x**2)) == pytest.approx(0.05 * (speed / 10.0) ** 3, rel=0.03)


def helmholtz(volume, neck_length, neck_radius, c=343.0):
    area = math.pi * neck_radius**2
    return c / (2 * math.pi) * math.sqrt(area / (volume * (neck_length + END_CORRECTION * neck_radius)))


@pytest.mark.timeout(300)  # a cold numba compile on a loaded machine, not a hang
@pytest.mark.parametrize("on_resonance", [True, False])
def test_cavity_tone_rms_is_the_jet_band_at_the_resonance(on_resonance):
    """Default bottle (f_H 110 Hz); the jet either centred on it or at the default 6 m/s
    (60 Hz: |H| 0.62). A broader cavity (Q 20) than the default so 30 s pin the RMS."""
    f_h = helmholtz(7.5e-4, 0.08, 0.0095)
    speed = f_h * 0.02 / 0.2 if on_resonance else 6.0
    node = ugens.CavityTone(name="c", speed=speed, resonance_q=20.0, level=0.1)
    x = rendered(node, 30.0)[FS:]
    predicted = cavity_tone_rms(0.1, speed, 0.02, f_h)
    assert np.sqrt(np.mean(x**2)) == pytest.approx(predicted, rel=0.08)


def test_jassy_doc_states_each_sources_level_convention():
    from jassy.ugendoc import describe_ugen

    for name, cls in ugen_types().items():
        if not set(cls.inputs) - set(getattr(cls, "optional_inputs", ())):
            line = next((ln for ln in describe_ugen(cls).splitlines() if ln.startswith("level: ")), "")
            assert len(line) > 20, name
    assert "1.0 = 105 dB SPL" in describe_ugen(ugen_types()["Wind"])
    assert "(Pa)" in describe_ugen(ugen_types()["Explosion"])


@pytest.mark.parametrize("radius", [1e-3, 3e-3])
def test_a_bubble_at_its_physical_gain_is_a_pulsating_sphere_in_water(radius):
    """gain = bubble_gain(epsilon, r) in Pa (93.98 dB full scale): the rendered bubble's
    envelope at its birth is rho w^2 R^3 epsilon(R) / r with w its measured frequency and
    epsilon(R) = epsilon sqrt(R / 1 mm)."""
    epsilon, distance, t0 = 2e-3, 0.5, 0.01
    node = ugens.Bubble(name="b", gain=bubble_gain(epsilon, distance, full_scale_spl=93.98))
    score = [Event(t0, "b", "bubble", {"radius": radius, "depth": 1.0})]
    x = render(Graph(node), score, duration=0.06, sample_rate=FS, limiter=False).audio[0]
    first = math.ceil(t0 * FS)
    z = signal.hilbert(x[first:])
    t = (first + np.arange(z.size)) / FS - t0
    fit = slice(int(0.002 * FS), int(0.012 * FS))  # away from the analytic signal's ends
    slope, intercept = np.polyfit(t[fit], np.log(np.abs(z[fit])), 1)
    omega = np.polyfit(t[fit], np.unwrap(np.angle(z[fit])), 1)[0]
    omega_birth = omega / (1 + 0.1 * -slope * 0.007)  # the rise: w (1 + sigma d t), fit centre 7 ms
    predicted = WATER_DENSITY * omega_birth**2 * radius**3 * epsilon * math.sqrt(radius / 1e-3) / distance
    assert math.exp(intercept) == pytest.approx(predicted, rel=0.02)
