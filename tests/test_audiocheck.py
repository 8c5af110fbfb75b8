"""The radiation output stage against the pulsating sphere, the check-audio measures against
closed forms, and every shipped patch within the check-audio targets."""

from __future__ import annotations

import numpy as np
import pytest

from jassy.apps import audiocheck as ac
from jassy.engines.offline import render
from jassy.graph import Graph
from jassy.patchfile import builtin_patches
from ugens.oscillators import Sine
from ugens.radiation import Radiation, radiate, radiation_coefficients, radiation_response

RATE = 48000


def test_radiation_follows_the_pulsating_sphere():
    """|H(f)| of the stage equals ka / sqrt(1 + (ka)^2) (a = 5 cm: corner 1.09 kHz) within
    0.2 dB from 100 Hz to 8 kHz, and removes DC."""
    n = 1 << 16
    x = np.zeros(n)
    x[0] = 1.0
    y = np.zeros(n)
    radiate(x, y, n, radiation_coefficients(0.05, 343.0, 10.0, RATE), np.zeros(3))
    freqs = np.fft.rfftfreq(n, 1.0 / RATE)
    h = np.abs(np.fft.rfft(y))
    band = (freqs >= 100) & (freqs <= 8000)
    err = 20 * np.log10(h[band] / radiation_response(freqs[band], 0.05))
    assert np.max(np.abs(err)) < 0.2
    assert abs(h[0]) < 1e-9


def test_radiation_removes_the_mean_of_a_pushed_body():
    """A slow force curve (2 Hz) plus a 1 kHz ring: the ring passes, the push does not."""
    push = Sine(freq=2.0, amp=1.0, phase=0.3)
    ring = Sine(freq=1000.0, amp=0.1)
    out = Radiation(push + ring, radius=0.1)
    audio = render(Graph(out), duration=2.0, sample_rate=RATE, limiter=False).audio[0]
    assert ac.subsonic_share(audio[RATE // 2 :], RATE) < 0.01
    assert abs(np.mean(audio[RATE // 2 :])) < 1e-4
    ring_gain = radiation_response(1000.0, 0.1)
    assert np.std(audio[RATE:]) == pytest.approx(0.1 / np.sqrt(2) * ring_gain, rel=0.02)


def test_subsonic_share_and_dc_of_known_signals():
    t = np.arange(4 * RATE) / RATE
    x = 0.3 * np.sin(2 * np.pi * 10 * t) + 0.4 * np.sin(2 * np.pi * 1000 * t) + 0.01
    expected = (0.3**2 / 2 + 0.01**2) / (0.3**2 / 2 + 0.4**2 / 2 + 0.01**2)
    assert ac.subsonic_share(x, RATE) == pytest.approx(expected, rel=1e-3)
    report = ac.measure("x", ac.Render(x, RATE, np.zeros(0)), None, 0)
    assert report.dc == pytest.approx(0.01, rel=1e-3)


def test_clicks_are_steps_and_spikes_not_ringing_onsets():
    t = np.arange(RATE) / RATE
    x = 0.2 * np.sin(2 * np.pi * 300 * t)
    x[30000:] += 0.05  # a step: a click at 0.625 s
    onset = 12000  # a struck mode starting at a scheduled event
    x[onset:] += np.sin(2 * np.pi * 3000 * t[: RATE - onset] + 1.0) * np.exp(-20 * t[: RATE - onset])
    clicks = ac.click_times(x, RATE, event_times=[onset / RATE])
    assert clicks.size == 1 and abs(clicks[0] - 30000 / RATE) < 1e-4
    # an onset followed by ringing is not a click even without its event
    assert ac.click_times(x, RATE).size == 1
    # a lone spike is
    x[40000] += 0.05
    assert ac.click_times(x, RATE, event_times=[onset / RATE]).size == 2


def test_alias_figure_of_a_naive_and_of_a_band_limited_sawtooth():
    """A naive sawtooth at 48 kHz folds its harmonics into 16-24 kHz; one built from its
    harmonics below Nyquist matches the 192 kHz render of the same tone."""
    f0, seconds = 1234.5, 0.25

    def saw(rate, naive):
        t = np.arange(int(seconds * rate)) / rate
        if naive:
            return 2 * ((f0 * t) % 1.0) - 1
        k = np.arange(1, int(0.5 * rate / f0) + 1)
        return -2 / np.pi * (np.sin(2 * np.pi * f0 * np.outer(t, k)) / k).sum(axis=1)

    over = saw(4 * RATE, False)
    assert abs(ac.alias_db(saw(RATE, False), RATE, over, 4 * RATE)) < 0.5
    assert ac.alias_db(saw(RATE, True), RATE, over, 4 * RATE) > 1.5  # 2.3 dB folded back


@pytest.mark.parametrize("name", sorted(builtin_patches()))
def test_shipped_patch_within_targets(name):
    """Every shipped patch, rendered in full: subsonic share < 5 %, |DC| < 1e-4, no clipping."""
    report = ac.check(name, aliasing=False)
    assert ac.failures(report) == []


def test_check_audio_cli_rejects_unknown_names_and_bad_durations(capsys):
    from jassy.apps.cli import main

    assert main(["check-audio", "nosuch"]) == 2
    assert "unknown patch 'nosuch'" in capsys.readouterr().err
    assert main(["check-audio", "bell", "--duration", "0"]) == 2
    assert "--duration" in capsys.readouterr().err
