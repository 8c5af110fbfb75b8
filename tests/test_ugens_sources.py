"""Sources: Sine, WhiteNoise, FractalNoise and Envelope against closed forms."""

import math

import numpy as np
import pytest
from scipy import signal, stats

from jassy import Event, Graph, render
from ugens.envelope import EXP_SPAN, Envelope
from ugens.noise import FractalNoise, WhiteNoise
from ugens.oscillators import Sine

FS = 48000


def run(ugen, score=(), duration=0.5, block=64, sample_rate=FS):
    return render(
        Graph(ugen), score, duration=duration, sample_rate=sample_rate, block=block, limiter=False
    ).audio[0]


def apply_frame(time, fs=FS):
    return math.ceil(time * fs - 1e-6)


# ---------------------------------------------------------------------------- Sine
def test_sine_matches_closed_form():
    f, amp, phase = 1234.567, 0.7, 0.3
    x = run(Sine(freq=f, amp=amp, phase=phase, name="s"), duration=2.0)
    n = np.arange(x.size)
    assert np.max(np.abs(x - amp * np.sin(2 * np.pi * f * n / FS + phase))) < 1e-9


def test_sine_frequency_changes_are_phase_continuous():
    f0, f1, f2, t1, t2 = 440.0, 523.25, 300.0, 0.1013, 0.2017
    score = [Event(t1, "s", "set", {"freq": f1}), Event(t2, "s", "set", {"freq": f2}, jump=True)]
    x = run(Sine(freq=f0, name="s"), score, duration=0.3)
    # independent model: freq per sample (linear ramp of round(0.005 fs) samples, then a jump),
    # phase = 2 pi * cumulative sum of freq / fs over the previous samples
    freqs = np.full(x.size, f0)
    a, b, m = apply_frame(t1), apply_frame(t2), round(0.005 * FS)
    freqs[a:b] = f1
    freqs[a : a + m] = f0 + (f1 - f0) * np.arange(0, m) / m  # the line through (a, f0), (a + m, f1)
    freqs[b:] = f2
    phase = 2 * np.pi * np.concatenate([[0.0], np.cumsum(freqs[:-1])]) / FS
    assert np.max(np.abs(x - np.sin(phase))) < 1e-9
    # |sin(p + d) - sin(p)| <= |d|: no step larger than the largest phase increment
    assert np.max(np.abs(np.diff(x))) <= 2 * np.pi * max(f0, f1, f2) / FS


def test_sine_amp_ramp():
    x = run(Sine(freq=1000.0, amp=1.0, name="s"), [Event(0.05, "s", "set", {"amp": 0.25})], duration=0.1)
    n = np.arange(x.size)
    a, m = apply_frame(0.05), round(0.005 * FS)
    amps = np.ones(x.size)
    amps[a:] = 0.25
    amps[a : a + m] = 1.0 - 0.75 * np.arange(0, m) / m
    assert np.max(np.abs(x - amps * np.sin(2 * np.pi * 1000.0 * n / FS))) < 1e-9


# ---------------------------------------------------------------------- WhiteNoise
def splitmix64_uniform(seed, count):
    """Reference splitmix64 in Python integers, mapped to [-1, 1) as documented."""
    mask, s, out = 2**64 - 1, seed, []
    for _ in range(count):
        s = (s + 0x9E3779B97F4A7C15) & mask
        z = ((s ^ (s >> 30)) * 0xBF58476D1CE4E5B9) & mask
        z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & mask
        z ^= z >> 31
        out.append((z >> 11) * 2.0**-52 - 1.0)
    return np.array(out)


def test_white_noise_matches_reference_generator():
    x = run(WhiteNoise(amp=0.5, seed=12345, name="w"), duration=1000 / FS, block=7)
    assert np.array_equal(x, 0.5 * splitmix64_uniform(12345, 1000))


NOISE_N = 2**18


def test_white_noise_moments_and_distribution():
    amp = 0.5
    x = run(WhiteNoise(amp=amp, seed=1, name="w"), duration=NOISE_N / FS)
    var = amp**2 / 3  # uniform on [-amp, amp)
    assert abs(x.mean()) < 5 * math.sqrt(var / NOISE_N)
    # Var(sample variance) = (mu4 - sigma^4) / N with mu4 = amp^4 / 5 for the uniform law
    assert abs(x.var() - var) < 5 * math.sqrt((amp**4 / 5 - var**2) / NOISE_N)
    assert x.min() >= -amp and x.max() < amp
    assert stats.kstest(x, "uniform", args=(-amp, 2 * amp)).pvalue > 1e-3


def test_white_noise_seeds():
    a = run(WhiteNoise(seed=7, name="w"), duration=1.0)
    b = run(WhiteNoise(seed=7, name="w"), duration=1.0, block=1000)
    c = run(WhiteNoise(seed=8, name="w"), duration=1.0)
    assert np.array_equal(a, b)
    assert abs(np.corrcoef(a, c)[0, 1]) < 5 / math.sqrt(a.size)


def test_white_noise_spectrum_is_flat():
    amp = 1.0
    x = run(WhiteNoise(amp=amp, seed=3, name="w"), duration=NOISE_N / FS)
    f, p = signal.welch(x, FS, nperseg=1024)
    bands = np.array([b.mean() for b in np.array_split(p[1:-1], 16)])
    # one-sided PSD of white noise of variance amp^2 / 3: 2 var / fs
    assert np.max(np.abs(bands / (2 * amp**2 / 3 / FS) - 1)) < 0.05
    r = [np.dot(x[:-k], x[k:]) / np.dot(x, x) for k in range(1, 21)]
    assert np.max(np.abs(r)) < 5 / math.sqrt(x.size)


# -------------------------------------------------------------------- FractalNoise
@pytest.mark.parametrize("beta", [0.0, 0.5, 1.0, 1.5, 2.0])
def test_fractal_noise_slope(beta):
    x = run(FractalNoise(beta=beta, seed=11, name="f"), duration=4.5)[FS // 2 :]
    f, p = signal.welch(x, FS, nperseg=8192)
    band = (f >= 50) & (f <= 5000)
    slope = np.polyfit(np.log10(f[band]), np.log10(p[band]), 1)[0]
    assert abs(slope + beta) < 0.15


def test_fractal_noise_beta_zero_is_scaled_white_noise():
    # zeros cancel poles, and unit-variance scaling of the uniform draw is sqrt(3)
    x = run(FractalNoise(beta=0.0, amp=0.2, seed=5, name="f"), duration=0.2)
    w = run(WhiteNoise(amp=0.2 * math.sqrt(3), seed=5, name="w"), duration=0.2)
    assert np.max(np.abs(x - w)) < 1e-9


@pytest.mark.parametrize("beta", [0.5, 1.0, 2.0])
def test_fractal_noise_rms_is_amp(beta):
    # low-frequency power makes the RMS of one render fluctuate; average 4 seeds x 20 s
    fs, amp = 16000, 0.3
    ms = [
        np.mean(
            run(
                FractalNoise(beta=beta, amp=amp, seed=s, name="f"), duration=20.0, block=1000, sample_rate=fs
            )[fs:]
            ** 2
        )
        for s in range(4)
    ]
    assert abs(math.sqrt(np.mean(ms)) / amp - 1) < 0.06


# ------------------------------------------------------------------------ Envelope
def stage(k, m, start, end, curve):
    """Closed form of one stage at positions k (0..m)."""
    x = k / m
    if curve == "exponential":
        x = (1 - np.exp(-EXP_SPAN * x)) / (1 - np.exp(-EXP_SPAN))
    return start + (end - start) * x


@pytest.mark.parametrize("curve", ["linear", "exponential"])
def test_envelope_adsr_closed_form(curve):
    a, d, s, r, peak = 0.01, 0.02, 0.5, 0.05, 0.8
    t0, tr = 0.01, 0.1
    env = Envelope(attack=a, decay=d, sustain=s, release=r, curve=curve, name="e")
    x = run(env, [Event(t0, "e", "trigger", {"velocity": peak}), Event(tr, "e", "release")], duration=0.2)
    f0, fr, na, nd, nr = apply_frame(t0), apply_frame(tr), round(a * FS), round(d * FS), round(r * FS)
    assert np.all(x[:f0] == 0)
    assert x[f0] == 0 and x[f0 + na] == peak and np.all(x[f0 : f0 + na] < peak)
    assert x[f0 + na + nd] == s * peak and np.all(x[f0 + na + nd : fr] == s * peak)
    assert x[fr + nr] == 0 and np.all(x[fr + nr :] == 0) and np.all(x[fr : fr + nr] > 0)
    expected = np.zeros(x.size)
    expected[f0 : f0 + na + 1] = stage(np.arange(na + 1), na, 0.0, peak, curve)
    expected[f0 + na : f0 + na + nd + 1] = stage(np.arange(nd + 1), nd, peak, s * peak, curve)
    expected[f0 + na + nd : fr] = s * peak
    expected[fr : fr + nr + 1] = stage(np.arange(nr + 1), nr, s * peak, 0.0, curve)
    assert np.max(np.abs(x - expected)) < 1e-12


def test_envelope_attack_decay_when_sustain_is_zero():
    a, d = 0.005, 0.03
    x = run(Envelope(attack=a, decay=d, sustain=0.0, name="e"), [Event(0.02, "e", "trigger")], duration=0.2)
    f0, na, nd = apply_frame(0.02), round(a * FS), round(d * FS)
    assert x[f0 + na] == 1.0 and np.argmax(x) == f0 + na
    assert np.all(np.diff(x[f0 + na : f0 + na + nd + 1]) < 0)
    assert x[f0 + na + nd] == 0 and np.all(x[f0 + na + nd :] == 0)


def test_envelope_starts_at_fractional_event_frame():
    t = 1000.3 / FS  # applied before frame 1001
    x = run(Envelope(attack=0.001, name="e"), [Event(t, "e", "trigger")], duration=0.05)
    na = round(0.001 * FS)
    assert np.all(x[:1002] == 0) and x[1002] == 1 / na and x[1001 + na] == 1.0


def test_envelope_release_and_retrigger_start_from_current_level():
    a, r = 0.02, 0.01
    na, nr = round(a * FS), round(r * FS)
    score = [Event(0.0, "e", "trigger"), Event(0.01, "e", "release"), Event(0.015, "e", "trigger")]
    x = run(Envelope(attack=a, release=r, name="e"), score, duration=0.05)
    fr, ft = apply_frame(0.01), apply_frame(0.015)
    level = (fr - 1) / na  # the release starts from the last attack sample
    assert x[fr] == pytest.approx(level)
    assert np.allclose(x[fr:ft], level * (1 - np.arange(ft - fr) / nr))
    assert np.allclose(x[ft : ft + na + 1], x[ft] + (1 - x[ft]) * np.arange(na + 1) / na)
    assert np.max(np.abs(np.diff(x))) <= max(1 / na, level / nr) + 1e-12


# ------------------------------------------------------------- block invariance
def sine_case():
    return Sine(freq=300.0, amp=0.5, phase=1.0, name="u"), [
        Event(0.05, "u", "set", {"freq": 2000.0}),
        Event(0.051, "u", "set", {"amp": 0.9}),
        Event(0.2, "u", "set", {"freq": 150.0, "amp": 0.1}, jump=True),
        Event(0.3, "u", "set", {"freq": 700.0}),
    ]


def white_case():
    return WhiteNoise(seed=4, name="u"), [
        Event(0.1, "u", "set", {"amp": 0.3}),
        Event(0.2, "u", "set", {"amp": 0.6}, jump=True),
    ]


def fractal_case():
    return FractalNoise(beta=1.3, seed=9, name="u"), [
        Event(0.1, "u", "set", {"amp": 0.3}),
        Event(0.2, "u", "set", {"amp": 0.6}, jump=True),
    ]


def envelope_case():
    return Envelope(attack=0.01, decay=0.03, sustain=0.6, release=0.05, curve="exponential", name="u"), [
        Event(0.0101, "u", "trigger", {"velocity": 0.9}),
        Event(0.03, "u", "set", {"attack": 0.002, "sustain": 0.3}),
        Event(0.1, "u", "release"),
        Event(0.12, "u", "trigger"),
        Event(0.13, "u", "set", {"decay": 0.0}),
        Event(0.25, "u", "release"),
        Event(0.26, "u", "trigger", {"velocity": 0.4}),
    ]


@pytest.mark.parametrize("case", [sine_case, white_case, fractal_case, envelope_case])
def test_block_size_invariance(case):
    outs = [run(*case(), duration=0.4, block=block) for block in (1, 64, 1000)]
    assert np.any(outs[0] != 0)
    for out in outs[1:]:
        assert np.max(np.abs(out - outs[0])) < 1e-6
