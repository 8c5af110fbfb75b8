"""The noise of the gas models has a spectral density independent of the sample rate: the
level of a band well below both Nyquist frequencies agrees at 48 and 96 kHz.

Each model sets the variance of its noise *after* a filter whose bandwidth is fixed in Hz
(the flow band-pass, the cavity resonator, the rumble low-pass), so it needs no
sqrt(fs / 48 kHz) factor; plain white noise of a fixed variance per sample, which does, is
the control: its band level falls by 3 dB from 48 to 96 kHz."""

import numpy as np
import pytest
from scipy import signal

from jassy import Event, Graph, render
from ugens.explosion import Explosion
from ugens.noise import WhiteNoise
from ugens.wind import CavityTone, KarmanWhistle, Wind

CASES = {  # ugen, score, band (Hz); bands of at least 50 Hz x 4 s for a steady level
    "wind": (
        lambda: Wind(name="u", speed=15.0, gustiness=0.0, eddy_size=0.005, q=1.0, seed=1),
        (),
        (300, 1500),
    ),
    "gusty-wind": (lambda: Wind(name="u", speed=10.0, gustiness=0.5, gust_time=0.01, seed=2), (), (200, 800)),
    "whistle": (lambda: KarmanWhistle(name="u", speed=10.0, diameter=0.002, q=8.0, seed=3), (), (700, 1400)),
    "cavity": (lambda: CavityTone(name="u", speed=8.0, gustiness=0.0, resonance_q=2.0, seed=4), (), None),
    "white-control": (lambda: WhiteNoise(name="u", seed=6), (), (1000, 4000)),
    "explosion-tail": (
        lambda: Explosion(name="u", distance=1.0, dispersion=1.0, scatter_time=2.0, rumble=400.0, seed=5),
        [Event(0.01, "u", "blast", {"overpressure": 100.0})],
        (100, 400),
    ),
}


def band_level_db(x, fs, band):
    """Power (dB) in ``band`` from a Welch spectrum with 10 Hz bins (density x width)."""
    f, p = signal.welch(x, fs, nperseg=int(fs / 10))
    keep = (f >= band[0]) & (f <= band[1])
    return 10 * np.log10(np.sum(p[keep]) * (f[1] - f[0]))


@pytest.mark.parametrize("case", CASES)
def test_band_level_is_the_same_at_48_and_96_khz(case):
    make, score, band = CASES[case]
    levels = []
    for fs in (48000, 96000):
        node = make()
        if band is None:  # the cavity: an octave around its resonance
            band = (node.resonance() / np.sqrt(2), node.resonance() * np.sqrt(2))
        x = render(
            Graph(node),
            score,
            duration={"cavity": 30.0, "gusty-wind": 16.0}.get(case, 4.0),
            sample_rate=fs,
            block=64,
            limiter=False,
        ).audio[0]
        levels.append(band_level_db(x, fs, band))
    expected = -10 * np.log10(2) if case == "white-control" else 0.0
    assert abs(levels[1] - levels[0] - expected) < 0.5, levels
