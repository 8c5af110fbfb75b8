"""SDT's crumpling model: each micro-impact's fragment size retunes the resonator.

Against closed forms: a ModalBank driven with a fragment size s rings at f / sqrt(s) with
decay rate d / sqrt(s) and amplitude a J / sqrt(s) (SDT's resonator: modal mass times s at
unchanged stiffness); a retune keeps a ringing mode's amplitude and phase; over a Crumple
render each event's spectral centroid is the size-1 centroid / sqrt(s) and its energy
J^2 / sqrt(s) times the size-1 energy per unit impulse (time scaling h_s(t) = h_1(t /
sqrt(s)) / sqrt(s)); the fragmentation spread follows SDT's size distribution.
"""

import math

import numpy as np
from helpers import ArraySource
from scipy import stats

from jassy import Event, Graph, ModalModel, render
from ugens.modal import ModalBank
from ugens.stochastic import Crumple

FS = 48000


def model(freqs, decays, gains):
    return ModalModel(frequencies=freqs, decays=decays, gains=[gains])


def bank_output(m, force, size, block=64):
    bank = ModalBank(m, name="bank")(ArraySource(force, name="f"), size=ArraySource(size, name="s"))
    return render(Graph(bank), [], force.size / FS, FS, block, limiter=False).audio[0]


def test_size_scales_frequency_decay_and_amplitude():
    f, d, a, s, J = 1000.0, 30.0, 2.0, 0.36, 1e-3
    n = 9600
    force = np.zeros(n)
    force[0] = J * FS
    y = bank_output(model([f], [d], [a]), force, np.full(n, s))
    t = np.arange(1, n) / FS
    u = math.sqrt(s)
    exact = J * a / u * np.exp(-d * t / u) * np.sin(2 * math.pi * f * t / u)
    assert np.max(np.abs(y[1:] - exact)) < 1e-6 * np.max(np.abs(exact))


def test_retune_keeps_amplitude_and_phase():
    """From the frame where the size changes on, the mode rings at the new tuning with the
    amplitude and phase it had at that frame; that frame carries the kink's end correction,
    the Euler-Maclaurin term (slope jump per sample) / 12 (the direct gain's counterpart
    for a kink, as h'(0) / (12 fs^2) is for an impulse)."""
    f, d, a, J = 800.0, 5.0, 1.0, 1e-3
    n, at = 9600, 4000
    force = np.zeros(n)
    force[0] = J * FS
    size = np.ones(n)
    size[at:] = 0.5
    u = math.sqrt(0.5)
    t0 = at / FS  # the retune's instant: frame ``at`` still has the old tuning
    phase0 = 2 * math.pi * f * t0
    amp0 = J * a * math.exp(-d * t0)
    before = J * a * np.exp(-d * np.arange(at + 1) / FS) * np.sin(2 * math.pi * f * np.arange(at + 1) / FS)
    t = np.arange(at, n) / FS - t0
    after = amp0 * np.exp(-d * t / u) * np.sin(phase0 + 2 * math.pi * f * t / u)
    slope_old = amp0 * (2 * math.pi * f * math.cos(phase0) - d * math.sin(phase0))
    slope_new = amp0 * (2 * math.pi * f * math.cos(phase0) - d * math.sin(phase0)) / u
    kink = (slope_new - slope_old) / FS / 12
    for block in (64, 1000):
        y = bank_output(model([f], [d], [a]), force, size, block)
        assert np.max(np.abs(y[1:at] - before[1:at])) < 1e-6 * amp0
        assert np.max(np.abs(y[at + 1 :] - after[1:])) < 1e-6 * amp0
        assert abs(y[at] - (after[0] + kink)) < 1e-6 * amp0
        assert abs(kink) > 1e-3 * amp0  # the correction is there


NFFT = 1 << 17


def event_spectra(seconds=4.0):
    """A sparse Crumple on a three-mode bank. Per isolated event: measured (centroid Hz,
    energy) and predicted from its sampled force pulse P and the size-1 bank's spectrum
    H_1: |P(f)|^2 |H_1(sqrt(s) f)|^2 (H_s(f) = H_1(sqrt(s) f))."""
    m = model([700.0, 1900.0, 3700.0], [120.0, 160.0, 220.0], [1.0, 0.8, 0.6])
    crumple = Crumple(name="c", density=12.0, fragmentation=0.8, duration=1e-6, seed=4)
    crumple.log_capacity = 1000
    bank = ModalBank(m, name="bank")(crumple, size=crumple.tap("size"))
    events = [Event(0.0, "c", "start", {})]
    r = render(Graph(bank, haptic=[crumple]), events, seconds, FS, 64, limiter=False)
    y, force = r.audio[0], r.haptic[0]
    ref = np.zeros(int(0.2 * FS))
    ref[0] = FS  # 1 N s
    h1 = np.abs(np.fft.rfft(bank_output(m, ref, np.ones(ref.size)), NFFT)) ** 2
    f = np.fft.rfftfreq(NFFT, 1 / FS)
    log = crumple.event_log()
    starts = np.floor(log[:, 0] * FS).astype(int) + 1
    ends = np.append(starts[1:], y.size)
    measured, predicted = [], []
    for k in range(1, len(starts)):
        # isolated: the previous event has decayed 80 dB, this one lasts 80 dB long
        lead = 9.2 * math.sqrt(log[k - 1, 2]) / 120.0
        tail = 9.2 * math.sqrt(log[k, 2]) / 120.0
        if starts[k] - starts[k - 1] < lead * FS or ends[k] - starts[k] < tail * FS:
            continue
        seg = y[starts[k] : ends[k]]
        spec = np.abs(np.fft.rfft(seg, NFFT)) ** 2
        measured.append(((spec * f).sum() / spec.sum(), (seg * seg).sum()))
        pulse = np.abs(np.fft.rfft(force[starts[k] : starts[k] + 4] / FS, NFFT)) ** 2
        model_spec = pulse * np.interp(math.sqrt(log[k, 2]) * f, f, h1)
        energy = (2 * model_spec.sum() - model_spec[0] - model_spec[-1]) / NFFT  # Parseval, one-sided
        predicted.append(((model_spec * f).sum() / model_spec.sum(), energy))
    return np.array(measured), np.array(predicted), log


def test_event_centroid_and_energy_follow_size():
    measured, predicted, log = event_spectra()
    assert len(measured) >= 10
    assert np.ptp(log[:, 2]) > 0.4  # the spread covers a wide range of sizes
    np.testing.assert_allclose(measured[:, 0], predicted[:, 0], rtol=0.01)
    np.testing.assert_allclose(measured[:, 1], predicted[:, 1], rtol=0.02)


def test_fragmentation_spread_follows_sdt():
    frag, spread = 0.8, 0.6
    c = Crumple(name="c", density=3000.0, fragment=frag, fragmentation=spread, seed=9)
    c.log_capacity = 20000
    render(Graph(c), [Event(0.0, "c", "start", {})], 4.0, FS, 256, limiter=False)
    sizes = c.event_log()[:, 2]
    rng = np.random.default_rng(1)
    u, w = rng.random((2, 200000))
    expected = frag * (1 - spread + spread * u) * (0.5 + 0.5 * w)
    assert sizes.size > 10000
    assert stats.ks_2samp(sizes, expected).pvalue > 1e-3
    assert sizes.min() >= frag * (1 - spread) * 0.5 and sizes.max() <= frag
