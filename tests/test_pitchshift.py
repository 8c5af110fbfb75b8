"""PitchShift: the shift ratio on a sine within 1 cent, the duration kept."""

import math

import numpy as np
import pytest
from helpers import ArraySource
from scipy import signal

from jassy import Event, Graph, render
from ugens.oscillators import Sine
from ugens.pitchshift import MIN_DELAY, PitchShift

FS = 48000


def dominant_head_frequency(y, ratio, window):
    """Mean instantaneous frequency (Hz, from the analytic signal's phase) over the samples
    where one read head sounds alone (the other's cross-fade weight < 1e-4): there the
    output is that head's resampled input. (The overlap-add of the two heads has no
    spectral line at r f: each head restarts with a phase jump, so the long-term phase
    drifts; the pitch heard is the heads' own frequency, which this measures.)"""
    n = np.arange(y.size - 1)
    phi = (n * (1 - ratio) / (window * FS)) % 1.0  # head A's phase; head B is half a turn on
    alone = np.minimum(np.sin(np.pi * phi) ** 2, np.cos(np.pi * phi) ** 2) < 1e-4
    alone[: FS // 10] = alone[-FS // 10 :] = False  # the Hilbert transform's edges
    phase = np.unwrap(np.angle(signal.hilbert(y)))
    return np.mean(np.diff(phase)[alone]) * FS / (2 * np.pi)


@pytest.mark.parametrize("freq, ratio", [(440.0, 1.5), (440.0, 2 ** (-5 / 12)), (1000.0, 2.0), (300.0, 0.5)])
def test_shift_ratio_within_one_cent(freq, ratio):
    node = PitchShift(Sine(freq=freq, amp=0.5, name="s"), name="p", ratio=ratio, window=0.04)
    y = render(Graph(node), (), duration=1.5, sample_rate=FS, block=64, limiter=False).audio[0]
    measured = dominant_head_frequency(y, ratio, 0.04)
    assert abs(1200 * math.log2(measured / (freq * ratio))) < 1.0


@pytest.mark.parametrize("ratio", [0.7, 1.8])
def test_duration_unchanged(ratio):
    window = 0.03
    x = np.zeros(FS)
    x[int(0.1 * FS) : int(0.6 * FS)] = np.sin(2 * np.pi * 500 * np.arange(int(0.5 * FS)) / FS)
    node = PitchShift(ArraySource(x), name="p", ratio=ratio, window=window)
    y = render(Graph(node), (), duration=1.0, sample_rate=FS, block=64, limiter=False).audio[0]
    loud = np.flatnonzero(np.abs(y) > 1e-3)
    # the heads lag the input by MIN_DELAY .. MIN_DELAY + window fs samples
    assert 0.1 * FS <= loud[0] <= 0.1 * FS + MIN_DELAY + window * FS
    assert 0.6 * FS <= loud[-1] <= 0.6 * FS + MIN_DELAY + window * FS
    # and the sound is there all along: no gap longer than a window's fade
    assert np.max(np.diff(loud)) < 0.1 * window * FS


def test_ratio_one_is_a_pure_delay():
    x = np.random.default_rng(1).standard_normal(FS // 4)
    y = render(Graph(PitchShift(ArraySource(x), name="p", ratio=1.0)), (), duration=0.25, sample_rate=FS,
               block=64, limiter=False).audio[0]  # fmt: skip
    # phi stays 0: head A at MIN_DELAY with weight 0, head B at MIN_DELAY + W/2 with weight 1
    d = int(MIN_DELAY + 0.04 * FS / 2)
    assert np.max(np.abs(y[d:] - x[:-d])) < 1e-12


def test_block_size_invariance():
    def case():
        return PitchShift(Sine(freq=300.0, name="s"), name="u", ratio=1.3), [
            Event(0.05, "u", "set", {"ratio": 0.8}, ramp=0.05),
            Event(0.2, "u", "set", {"wet": 0.5}),
        ]

    outs = []
    for block in (1, 64, 1000):
        node, score = case()
        outs.append(
            render(Graph(node), score, duration=0.3, sample_rate=FS, block=block, limiter=False).audio[0]
        )
    assert np.any(outs[0] != 0)
    for out in outs[1:]:
        assert np.max(np.abs(out - outs[0])) < 1e-9
