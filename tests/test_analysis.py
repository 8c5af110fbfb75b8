"""Analysis ugens against closed forms: DC steps, sines, white noise, clicks."""

import math

import numpy as np
import pytest
from helpers import ArraySource

from jassy import Graph, render
from ugens.analysis import EnvelopeFollower, Onset, Pitch, SpectralFeatures, ZeroCrossings
from ugens.noise import WhiteNoise
from ugens.oscillators import Sine

FS = 48000


def run(node, taps=(), duration=1.0, block=64):
    r = render(Graph(node, [node.tap(t) for t in taps] or None), (), duration=duration, sample_rate=FS,
               block=block, limiter=False)  # fmt: skip
    return r.audio[0], r.haptic


def test_envelope_follows_a_dc_step_exponentially():
    level, attack, release = 0.8, 0.01, 0.05
    x = np.zeros(FS)
    x[: FS // 2] = level
    y, _ = run(EnvelopeFollower(ArraySource(x), name="e", mode="peak", attack=attack, release=release))
    n = np.arange(FS // 2)
    a, r = 1 - math.exp(-1 / (attack * FS)), 1 - math.exp(-1 / (release * FS))
    np.testing.assert_allclose(y[: FS // 2], level * (1 - (1 - a) ** (n + 1)), rtol=1e-9, atol=1e-12)
    top = y[FS // 2 - 1]
    np.testing.assert_allclose(y[FS // 2 :], top * (1 - r) ** (n + 1), rtol=1e-9, atol=1e-12)


def test_rms_envelope_of_a_sine():
    y, _ = run(EnvelopeFollower(Sine(freq=440.0, amp=0.6, name="s"), name="e", attack=0.05, release=0.05))
    assert abs(np.mean(y[FS // 2 :]) / (0.6 / math.sqrt(2)) - 1) < 0.01


@pytest.mark.parametrize("freq", [100.0, 1234.0])
def test_zero_crossing_rate_of_a_sine_is_twice_its_frequency(freq):
    window = 0.05
    y, _ = run(ZeroCrossings(Sine(freq=freq, phase=0.1, name="s"), name="z", window=window))
    assert np.max(np.abs(y[FS // 4 :] - 2 * freq)) <= 1 / window + 1e-9


def test_zero_crossing_rate_of_white_noise_is_half_the_sample_rate():
    y, _ = run(ZeroCrossings(WhiteNoise(name="w", seed=3), name="z", window=0.5), duration=2.0)
    # each sample pair changes sign with probability 1/2: count ~ Binomial(N, 1/2)
    n = 0.5 * FS
    assert abs(y[-1] - FS / 2) < 5 * math.sqrt(n / 4) / 0.5


def test_spectral_features_of_a_sine():
    f = 1500.0
    y, (spread, flatness, rolloff, flux) = run(
        SpectralFeatures(Sine(freq=f, name="s"), name="f", size=2048, hop=512),
        ("spread", "flatness", "rolloff", "flux"),
    )
    late = slice(FS // 2, None)
    assert np.all(np.abs(y[late] - f) < 0.01 * f)
    assert np.all(spread[late] < 0.05 * f) and np.all(flatness[late] < 1e-3)
    assert np.all(np.abs(rolloff[late] - f) <= FS / 2048)
    assert np.all(flux[late] < 1e-3)


def test_spectral_features_of_white_noise():
    """Periodogram bins of white noise are exponential: flatness e^-gamma; magnitudes flat
    in expectation: centroid fs / 4, rolloff at the fraction of fs / 2."""
    y, (spread, flatness, rolloff, _) = run(
        SpectralFeatures(WhiteNoise(name="w", seed=5), name="f", size=4096, hop=1024),
        ("spread", "flatness", "rolloff", "flux"),
        duration=4.0,
    )
    frames = slice(FS // 2, None, 1024)
    assert abs(np.mean(flatness[frames]) / math.exp(-np.euler_gamma) - 1) < 0.03
    assert abs(np.mean(y[frames]) / (FS / 4) - 1) < 0.01
    assert abs(np.mean(spread[frames]) / (FS / 2 / math.sqrt(12)) - 1) < 0.02  # uniform on [0, fs/2]
    assert abs(np.mean(rolloff[frames]) / (0.85 * FS / 2) - 1) < 0.01


@pytest.mark.parametrize("freq", [82.4, 220.0, 440.0, 1046.5])
def test_yin_pitch_of_a_harmonic_tone(freq):
    t = np.arange(FS) / FS
    tone = sum(np.sin(2 * np.pi * k * freq * t) / k for k in range(1, 8))  # a band-limited sawtooth
    y, (clarity,) = run(Pitch(ArraySource(tone), name="p"), ("clarity",))
    late = y[FS // 4 :]
    assert np.all(np.abs(late / freq - 1) < 0.001)
    assert np.all(clarity[FS // 4 :] > 0.9)


def test_yin_reports_noise_as_unvoiced():
    y, _ = run(Pitch(WhiteNoise(name="w", seed=1), name="p", threshold=0.1))
    assert np.mean(y[FS // 4 :] == 0.0) > 0.9


def test_onsets_of_clicks_in_noise():
    rng = np.random.default_rng(2)
    x = 0.01 * rng.standard_normal(2 * FS)
    clicks = [0.31, 0.62, 0.9, 1.37, 1.71]
    for c in clicks:
        k = int(c * FS)
        x[k : k + 200] += np.exp(-np.arange(200) / 40.0) * rng.standard_normal(200)
    y, _ = run(Onset(ArraySource(x), name="o", size=1024, hop=256), duration=2.0)
    found = np.flatnonzero(y) / FS
    # the noise floor starting from silence at 0 s is an onset too, then each click
    onsets = [0.0, *clicks]
    assert found.size == len(onsets)
    # reported at the end of the first frame holding the onset: within size + hop samples
    assert np.all((found >= onsets) & (found - onsets <= (1024 + 256) / FS))


@pytest.mark.parametrize("make", [
    lambda: SpectralFeatures(WhiteNoise(name="w", seed=5), name="u", size=512, hop=100),
    lambda: Pitch(Sine(freq=300.0, name="s"), name="u", size=1024, hop=300),
    lambda: Onset(WhiteNoise(name="w", seed=5), name="u", size=256, hop=64, threshold=0.0, ratio=1.0),
    lambda: EnvelopeFollower(WhiteNoise(name="w", seed=5), name="u"),
    lambda: ZeroCrossings(WhiteNoise(name="w", seed=5), name="u"),
])  # fmt: skip
def test_block_size_invariance(make):
    outs = [run(make(), duration=0.2, block=block)[0] for block in (1, 64, 1000)]
    assert np.any(outs[0] != 0)
    for out in outs[1:]:
        assert np.array_equal(out, outs[0])
