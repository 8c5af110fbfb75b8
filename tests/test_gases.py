"""Explosion, Wind, KarmanWhistle and CavityTone against their closed forms."""

import math

import numpy as np
import pytest
from scipy import signal

from jassy import Event, Graph, render
from ugens.explosion import Explosion, friedlander, positive_impulse
from ugens.wind import END_CORRECTION, CavityTone, KarmanWhistle, Wind

FS = 48000


def run(ugen, score=(), duration=1.0, block=64):
    return render(Graph(ugen), score, duration=duration, sample_rate=FS, block=block, limiter=False).audio[0]


def spectral_peak(x, nperseg=16384):
    """Frequency of the Welch spectrum's peak, refined by a parabola through 3 bins (log)."""
    f, p = signal.welch(x, FS, nperseg=nperseg)
    k = int(np.argmax(p[1:-1])) + 1
    a, b, c = np.log(p[k - 1 : k + 2])
    return f[k] + 0.5 * (a - c) / (a - 2 * b + c) * (f[1] - f[0])


# ---------------------------------------------------------------------- Explosion
@pytest.mark.parametrize("blast_time, decay, distance", [(0.01, 1.0, 1.0), (0.03, 2.0, 40.0)])
def test_explosion_positive_phase_and_impulse(blast_time, decay, distance):
    peak, t0, c = 2000.0, 0.1003, 343.0
    e = Explosion(name="e", blast_time=blast_time, decay=decay, distance=distance, dispersion=0.0)
    x = run(e, [Event(t0, "e", "blast", {"overpressure": peak})], duration=t0 + distance / c + 0.3)
    arrival = (t0 + distance / c) * FS  # fractional sample
    first = int(np.argmax(np.abs(x) > 1e-9 * peak))
    assert first == math.ceil(arrival)
    # zero crossing of the positive phase (linear interpolation between samples)
    k = first + int(np.argmax(x[first + 3 :] < 0)) + 3
    crossing = k - 1 + x[k - 1] / (x[k - 1] - x[k])
    assert abs((crossing - arrival) / FS - blast_time) < 0.02 * blast_time
    impulse = x[first:k].sum() / FS
    assert abs(impulse / positive_impulse(peak / distance, blast_time, decay) - 1) < 0.02
    # the low-pass keeps the waveform's shape: compare with the closed form, one sample late
    t = (np.arange(x.size) - arrival) / FS
    ideal = friedlander(t, peak / distance, blast_time, decay)
    late = slice(first + int(0.2 * blast_time * FS), first + int(3 * blast_time * FS))
    assert np.max(np.abs(x[late] - ideal[late])) < 0.03 * peak / distance


def test_explosion_tail_carries_the_blast_energy():
    """With full dispersion the output is the scattered tail: energy = the blast's energy
    (up to the tail that is still ringing), decaying 60 dB in scatter_time."""
    peak, blast_time, t60 = 1000.0, 0.01, 0.5
    e = Explosion(
        name="e", blast_time=blast_time, scatter_time=t60, dispersion=1.0, distance=1.0, rumble=2000.0
    )
    x = run(e, [Event(0.0, "e", "blast", {"overpressure": peak})], duration=2.0)
    t = np.arange(x.size) / FS - 1.0 / 343.0
    blast_energy = np.sum(friedlander(t, peak, blast_time) ** 2)
    assert abs(np.sum(x**2) / blast_energy - 1) < 0.15
    # level drop between two windows 0.25 s apart: 60 dB per t60 -> 30 dB
    w = int(0.05 * FS)
    a = np.mean(x[int(0.3 * FS) : int(0.3 * FS) + w] ** 2)
    b = np.mean(x[int(0.55 * FS) : int(0.55 * FS) + w] ** 2)
    assert abs(10 * np.log10(a / b) - 60 * 0.25 / t60) < 3.0


# ------------------------------------------------------------ whistle, wind, cavity
@pytest.mark.parametrize("speed, diameter", [(6.0, 0.004), (12.0, 0.004), (12.0, 0.0015), (25.0, 0.002)])
def test_karman_whistle_peak_at_strouhal_frequency(speed, diameter):
    x = run(KarmanWhistle(name="k", speed=speed, diameter=diameter, seed=2), duration=2.0)
    assert abs(spectral_peak(x) / (0.2 * speed / diameter) - 1) < 0.02


def test_karman_whistle_level_grows_as_speed_cubed():
    levels = [run(KarmanWhistle(name="k", speed=v, level=0.1), duration=1.0).std() for v in (5.0, 10.0, 20.0)]
    assert np.allclose(levels, [0.1 * (v / 10.0) ** 3 for v in (5.0, 10.0, 20.0)], rtol=0.1)


def test_karman_whistle_glides_with_a_speed_ramp():
    score = [Event(0.0, "k", "set", {"speed": 15.0}, ramp=2.0)]
    x = run(KarmanWhistle(name="k", speed=5.0, diameter=0.003, q=60.0), score, duration=2.0)
    # the peak of short windows follows 0.2 v(t) / d
    for t in (0.5, 1.0, 1.5):
        seg = x[int((t - 0.1) * FS) : int((t + 0.1) * FS)]
        v = 5.0 + 10.0 * t / 2.0
        assert abs(spectral_peak(seg, nperseg=seg.size) / (0.2 * v / 0.003) - 1) < 0.03


def test_wind_colour_and_level_follow_speed():
    slow = run(Wind(name="w", speed=5.0, gustiness=0.0, eddy_size=0.01, q=2.0), duration=2.0)
    fast = run(Wind(name="w", speed=20.0, gustiness=0.0, eddy_size=0.01, q=2.0), duration=2.0)
    assert abs(spectral_peak(slow, 4096) / 100.0 - 1) < 0.1
    assert abs(spectral_peak(fast, 4096) / 400.0 - 1) < 0.1
    assert abs(fast.std() / slow.std() - 64.0) < 0.1 * 64.0


def test_wind_gusts_modulate_the_level():
    calm = run(Wind(name="w", speed=10.0, gustiness=0.0), duration=3.0)
    gusty = run(Wind(name="w", speed=10.0, gustiness=0.5, gust_time=0.3), duration=3.0)
    frames = lambda x: np.sqrt(np.mean(x.reshape(-1, 4800) ** 2, axis=1))  # noqa: E731
    assert np.std(frames(gusty)) > 4 * np.std(frames(calm))


@pytest.mark.parametrize(
    "volume, neck_length, neck_radius", [(7.5e-4, 0.08, 0.0095), (3.3e-4, 0.05, 0.009), (2e-3, 0.02, 0.015)]
)
def test_cavity_tone_at_helmholtz_frequency(volume, neck_length, neck_radius):
    c = 343.0
    area = math.pi * neck_radius**2
    f_h = c / (2 * math.pi) * math.sqrt(area / (volume * (neck_length + END_CORRECTION * neck_radius)))
    mouth = 2 * neck_radius
    node = CavityTone(
        name="c", volume=volume, neck_length=neck_length, neck_radius=neck_radius, mouth=mouth,
        speed=f_h * mouth / 0.2,  # the jet's edge tone on the resonance
    )  # fmt: skip
    x = run(node, duration=3.0)
    assert abs(spectral_peak(x, 32768) / f_h - 1) < 0.02
    assert abs(node.resonance() / f_h - 1) < 1e-12


# --------------------------------------------------------------- block invariance
CASES = {
    "explosion": lambda: (
        Explosion(name="u", distance=20.0, seed=3),
        [Event(0.01, "u", "blast", {"overpressure": 500.0}), Event(0.05, "u", "set", {"dispersion": 0.9})],
    ),
    "wind": lambda: (Wind(name="u", seed=4), [Event(0.1, "u", "set", {"speed": 20.0})]),
    "whistle": lambda: (
        KarmanWhistle(name="u", gustiness=0.3, seed=5),
        [Event(0.05, "u", "set", {"speed": 25.0, "diameter": 0.002}, ramp=0.1)],
    ),
    "cavity": lambda: (CavityTone(name="u", seed=6), [Event(0.1, "u", "set", {"volume": 5e-4})]),
}


@pytest.mark.parametrize("case", CASES)
def test_block_size_invariance(case):
    outs = [run(*CASES[case](), duration=0.3, block=block) for block in (1, 64, 1000)]
    assert np.any(outs[0] != 0)
    for out in outs[1:]:
        assert np.max(np.abs(out - outs[0])) <= 1e-9 * np.max(np.abs(outs[0]))
