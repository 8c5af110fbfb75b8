"""Frequency-domain variable projection (physics/modal/varpro.py): the closed-form DFT of a
damped sinusoid against numpy's FFT, and the refined poles of two close modes in noise
against their true values within a few Cramer-Rao bounds."""

import numpy as np
import pytest

from physics.modal import varpro
from physics.modal.fit_bench import crb_bounds

pytestmark = pytest.mark.timeout(120)


def test_model_columns_are_the_dft_of_the_time_signal():
    rate, n = 8000.0, 3000
    f, d, c = 611.3, 37.0, 0.8 * np.exp(0.7j)
    z = np.exp((-d + 2j * np.pi * f) / rate)
    x = np.real(c * z ** np.arange(n))
    bins = np.arange(1, n // 2)
    phi, dd, dw = varpro.model_columns(np.array([z]), bins, n)
    model = phi[:, 0] * c.real + phi[:, 1] * c.imag
    assert np.max(np.abs(model - np.fft.rfft(x)[bins])) < 1e-9 * np.max(np.abs(model))
    # derivatives (per unit of d and omega, times fs) against finite differences
    h = 1e-5
    for deriv, dd_, dw_ in ((dd, h, 0.0), (dw, 0.0, h)):
        z2 = np.exp((-(d + dd_) + 1j * (2 * np.pi * f + dw_)) / rate)
        fd = (np.fft.rfft(np.real(c * z2 ** np.arange(n)))[bins] - np.fft.rfft(x)[bins]) / h
        an = (deriv[:, 0] * c.real + deriv[:, 1] * c.imag) / rate
        assert np.max(np.abs(fd - an)) < 1e-4 * np.max(np.abs(an))


def test_two_close_modes_refined_to_within_the_cramer_rao_bound():
    rate, n = 48000.0, 96000
    t = np.arange(n) / rate
    true = [(1000.0, 6.0, 0.5, 0.2), (1003.0, 9.0, 0.3, 1.1)]
    sigma = 0.003
    errs_f, errs_d = [], []
    for seed in range(4):
        rng = np.random.default_rng(seed)
        x = sum(a * np.exp(-d * t) * np.sin(2 * np.pi * f * t + p) for f, d, a, p in true)
        x = x + sigma * rng.standard_normal(n)
        spec = np.fft.rfft(x)
        bins = np.arange(int(950 * n / rate), int(1050 * n / rate))
        r = varpro.refine([varpro.Spectrum(bins, spec[bins], n)], rate, [999.5, 1003.6], [8.0, 8.0])
        assert r.cost < r.cost0
        for k, (f, d, a, _) in enumerate(true):
            b = crb_bounds(a, f, d, sigma, rate, n)
            errs_f.append(abs(r.frequencies[k] - f) / b.frequency)
            errs_d.append(abs(r.decays[k] - d) / b.decay)
            assert abs(abs(r.amplitudes[0][k]) / a - 1) < 0.05
    # the neighbour raises the bound a little; 4 bounds is far outside a biased estimate
    assert max(errs_f) < 4 and max(errs_d) < 4


def test_fast_length_is_five_smooth_and_close():
    for n in (17, 1000, 95999, 480001):
        m = varpro.fast_length(n)
        assert m <= n and m > 0.9 * n
        for p in (2, 3, 5):
            while m % p == 0:
                m //= p
        assert m == 1


class _NoProgress:
    def step(self, label):
        pass


def test_steady_tone_keeps_its_pre_sweep_pole():
    """An undamped tone refines to the decay clamp (varpro.MIN_DECAY): that is a pole that
    stopped decaying, so it keeps its value from before the sweep; the decaying mode beside
    it is still refined towards its true decay."""
    from physics.modal.fit import Pole, Segment, _spectral_refine
    from physics.modal.strikes import Hit

    rate, n = 8000.0, 8000
    t = np.arange(n) / rate
    rng = np.random.default_rng(3)
    x = np.sin(2 * np.pi * 500.0 * t) + np.exp(-20.0 * t) * np.sin(2 * np.pi * 530.0 * t + 0.3)
    x += 1e-3 * rng.standard_normal(n)
    seg = Segment(0, 0, Hit(0, 0, n), x, np.zeros(0, np.int64), np.ones(n + 1), 2 * n)
    start = [Pole(500.0, 0.5), Pole(530.5, 24.0)]
    out = _spectral_refine(start, [seg], rate, 20.0, 3000.0, _NoProgress(), sweeps=1)
    assert out[0] == start[0]
    assert abs(out[1].decay - 20.0) < abs(start[1].decay - 20.0)


def test_degenerate_input_keeps_the_start_without_amplitudes():
    """A non-finite sample, a pole at z = 0 (infinite decay: a non-finite design) or a
    non-finite spectrum keep the start with zero amplitudes instead of raising or returning
    NaN amplitudes; a clean signal still moves its pole (the guard does not fire)."""
    from physics.modal import esprit

    rate, n = 8000.0, np.arange(400)
    z_true = np.exp((-20.0 + 2j * np.pi * 440.0) / rate)
    y = np.real(z_true**n)
    z_start = np.exp((-25.0 + 2j * np.pi * 441.0) / rate)
    moved, amps = esprit.refine([y], rate, np.array([z_start]), real=True)
    assert abs(moved[0] - z_true) < abs(z_start - z_true) / 10 and abs(amps[0][0]) > 0.5
    for signal, z0 in (
        (np.where(n == 5, np.nan, y), z_start),
        (np.where(n == 5, np.inf, y), z_start),
        (y, 0j),
    ):
        z, amps = esprit.refine([signal], rate, np.array([z0]), real=True)
        assert z[0] == z0 and np.all(amps[0] == 0)
    bad = varpro.Spectrum(np.arange(50, 60), np.full(10, np.nan + 0j), 400)
    ref = varpro.refine([bad], rate, [440.0], [20.0])
    assert ref.frequencies[0] == 440.0 and ref.decays[0] == 20.0 and np.all(ref.amplitudes[0] == 0)
