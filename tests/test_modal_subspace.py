"""Building blocks of the subspace modal fit (physics.modal.esprit, physics.modal.strikes):
pooled ESPRIT exact on noise-free damped exponentials, the pooled refinement recovering
close poles, closed-form least-squares amplitudes
against a dense solve, strike onsets and clipped samples on signals made here."""

from __future__ import annotations

import numpy as np

from physics.modal import esprit
from physics.modal.strikes import clipped_samples, detect_onsets

RATE = 48000


def test_esprit_is_exact_without_noise():
    """Two damped complex exponentials, two signals with different amplitudes (pooled)."""
    s_true = np.array([-3.0 + 2j * np.pi * 40.0, -10.0 - 2j * np.pi * 120.0])
    z_true = np.exp(s_true / 1000.0)
    n = np.arange(300)
    ys = [
        (np.asarray(a)[None, :] * z_true[None, :] ** n[:, None]).sum(axis=1)
        for a in ([1.0, 0.3j], [0.2, -1.0])
    ]
    gram, rows = esprit.pooled_gram(ys, 40)
    z = esprit.esprit_poles(gram, rows, noise=1e-8, margin=4.0, max_order=10)
    assert z.size == 2
    np.testing.assert_allclose(np.sort_complex(np.log(z) * 1000), np.sort_complex(s_true), rtol=1e-8)


def test_refine_recovers_close_poles_shared_by_several_signals():
    """Variable-projection refinement from a start 0.3 Hz and 30 % off: three poles (two
    0.8 Hz apart) shared by three signals of their own amplitudes, complex and real."""
    rate = 375.0
    f_true, d_true = np.array([10.0, 10.8, 40.0]), np.array([0.6, 0.9, 3.0])
    s_true = -d_true + 2j * np.pi * f_true
    t = np.arange(1200) / rate
    amps = [np.array([1.0, 0.5j, 0.3]), np.array([0.4, -1.0, 0.2j]), np.array([0.7j, 0.6, -0.5])]
    start = np.exp((-d_true * 1.3 + 2j * np.pi * (f_true + 0.3)) / rate)
    for real in (False, True):
        ys = [np.exp(np.outer(t, s_true)) @ a for a in amps]
        ys = [y.real for y in ys] if real else ys
        z, c = esprit.refine(ys, rate, start, real=real, max_nfev=30)
        s = np.log(z) * rate
        np.testing.assert_allclose(s.imag / (2 * np.pi), f_true, atol=1e-6)
        np.testing.assert_allclose(-s.real, d_true, rtol=1e-6)
        for got, a in zip(c, amps, strict=True):
            np.testing.assert_allclose(got, a, atol=1e-6)


def test_amplitudes_closed_form_gram_matches_dense_least_squares():
    rng = np.random.default_rng(0)
    z = np.exp((-np.array([2.0, 50.0, 400.0]) + 2j * np.pi * np.array([300.0, 310.0, 5000.0])) / RATE)
    n = np.arange(4000)
    x = rng.standard_normal(n.size)
    excluded = np.array([3, 4, 5, 100])
    keep = np.setdiff1d(n, excluded)
    basis = np.hstack([(z[None, :] ** n[:, None]).real, -(z[None, :] ** n[:, None]).imag])[keep]
    coef = np.linalg.lstsq(basis, x[keep], rcond=None)[0]
    np.testing.assert_allclose(esprit.amplitudes(x, z, excluded), coef[:3] + 1j * coef[3:], rtol=1e-6)


def test_onsets_of_strikes_over_a_ringing_tail_and_clipping():
    t = np.arange(3 * RATE) / RATE
    x = np.zeros(t.size)
    onsets = [0.05, 1.1, 2.3]
    for t0, a in zip(onsets, [1.0, 0.5, 0.7], strict=True):
        tt = np.clip(t - t0, 0, None)
        x += (
            (t >= t0)
            * a
            * (
                np.exp(-0.5 * tt) * np.sin(2 * np.pi * 200 * tt)
                + 0.3 * np.exp(-300 * tt) * np.sin(2 * np.pi * 7000 * tt)
            )
        )
    x += 1e-4 * np.random.default_rng(1).standard_normal(t.size)
    found = np.array(detect_onsets(x, RATE)) / RATE
    np.testing.assert_allclose(found, onsets, atol=0.001)
    assert clipped_samples(x).size == 0
    assert clipped_samples(np.clip(x, -0.8, 0.8)).size > 10


def test_noise_floor_below_a_dense_low_cluster():
    """White noise (sigma known) under 30 strong slow modes at 40-400 Hz, 70-90 dB above it,
    ringing through the whole 2 s: the floor at 50-400 Hz and above is within 1.5 dB of
    sigma^2 (a median over +-1 kHz of a Hann periodogram read the modes' skirts as noise
    there, 17-32 dB too high)."""
    from physics.modal.fit import noise_floor

    rng = np.random.default_rng(3)
    t = np.arange(2 * RATE) / RATE
    sigma = 1e-4
    x = sigma * rng.standard_normal(t.size)
    for f in np.sort(rng.uniform(40.0, 400.0, 30)):
        x += rng.uniform(0.1, 1.0) * np.exp(-rng.uniform(0.5, 2.0) * t) * np.sin(2 * np.pi * f * t)
    n_fft = 1 << int(np.ceil(np.log2(2 * x.size)))
    floor = noise_floor(x, RATE, n_fft) / x.size
    freqs = np.arange(floor.size) * RATE / n_fft
    for f in (50.0, 150.0, 300.0, 1000.0, 5000.0, 20000.0):
        level_db = 10 * np.log10(floor[np.searchsorted(freqs, f)] / sigma**2)
        assert abs(level_db) < 1.5, (f, level_db)


def test_onsets_of_quiet_strikes_over_ringing_modes_in_noise():
    """Recordings of the fit bench's generator (closed form, made without the fitter) whose
    later strikes raise the level by less than 12 dB over noise 20-30 dB below the first
    strike and the modes still ringing: every strike found, within 1 ms."""
    from physics.modal.fit_bench import random_recording

    for seed in (1001, 1032, 2001):
        x, truth = random_recording(seed)
        found = np.array(detect_onsets(x, RATE)) / RATE
        assert found.size == truth.onsets.size, (seed, found, truth.onsets)
        np.testing.assert_allclose(found, truth.onsets, atol=1e-3)


def test_no_onset_in_noise_and_steady_ringing():
    """A mode ringing from before the recording plus noise: no strike but the recording's
    start (the fallback for recordings that begin with the strike)."""
    t = np.arange(RATE) / RATE
    x = np.exp(-0.5 * t) * np.sin(2 * np.pi * 300 * t) + 1e-3 * np.random.default_rng(2).standard_normal(
        t.size
    )
    found = detect_onsets(x, RATE)
    assert len(found) == 1 and found[0] < 0.001 * RATE, found
