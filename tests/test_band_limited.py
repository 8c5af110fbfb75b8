"""Band-limited firing corners of the Engine (BLAMP) against the naive sampled corner and
against a render at four times the rate."""

from __future__ import annotations

import numpy as np
import pytest

from jassy.apps import audiocheck as ac
from ugens.engine import BLAMP_HALF, BLAMP_PHASES, blamp_table


def _corner_spectrum(d: float, corrected: bool) -> np.ndarray:
    """|DTFT| of the second difference of a unit-slope corner at sub-sample position d
    (the corner between samples, d samples before the next one)."""
    n = 4 * BLAMP_HALF
    t = np.arange(n) - 2 * BLAMP_HALF  # corner at t = -d
    x = np.maximum(t + d, 0.0)
    if corrected:
        row = blamp_table()[int(round(d * BLAMP_PHASES))]
        x[BLAMP_HALF : 3 * BLAMP_HALF] += row
    h = np.diff(x, 2)
    return np.abs(np.fft.rfft(h, 4096))


def test_corner_spectrum_does_not_depend_on_its_sub_sample_position():
    """A sampled band-limited corner has the same magnitude spectrum wherever it falls
    between two samples (a time shift); the naive one does not (its images fold back)."""
    freqs = np.fft.rfftfreq(4096)  # cycles per sample
    band = freqs <= 0.4
    ref = _corner_spectrum(0.0, True)
    naive_ref = _corner_spectrum(0.0, False)
    for d in (0.25, 0.5, 0.75):
        err = 20 * np.log10(_corner_spectrum(d, True)[band] / ref[band])
        assert np.max(np.abs(err)) < 0.1
        naive = 20 * np.log10(_corner_spectrum(d, False)[band] / naive_ref[band])
        assert np.max(np.abs(naive)) > 3.0
    # the slope change is kept: the second difference of a sampled ideal corner has the
    # response (sin(pi f) / (pi f))^2 of the difference operator; within 0.1 dB of it to
    # 0.4 of the rate (19.2 kHz at 48 kHz), 1 dB to 0.45, and 30 dB below it at Nyquist
    ideal = np.sinc(freqs) ** 2
    err = 20 * np.log10(ref / ideal)
    assert np.max(np.abs(err[freqs <= 0.4])) < 0.1
    assert np.max(np.abs(err[freqs <= 0.45])) < 1.0
    assert err[-1] < -30.0


@pytest.mark.parametrize("name", ["engine", "marble"])
def test_patch_top_octave_matches_the_oversampled_render(name):
    """16-24 kHz band of the 48 kHz render within 1 dB of the 192 kHz render (the first 3 s:
    engine firings with exhaust, intake and block noise; marble bounces and the mallet)."""
    report = ac.check(name, duration=3.0)
    assert report.alias_db is not None and abs(report.alias_db) <= ac.MAX_ALIAS_DB
