"""Reverb: measured T60 per octave band against the set values, pre-delay, dry path."""

import numpy as np
import pytest
from helpers import ArraySource
from scipy import signal

from jassy import Event, Graph, render
from ugens.noise import WhiteNoise
from ugens.reverb import BANDS, Reverb, line_lengths

FS = 48000


def impulse_response(duration, **params):
    x = np.zeros(int(duration * FS))
    x[0] = 1.0
    node = Reverb(ArraySource(x), name="r", **params)
    r = render(
        Graph([node, node.tap("right")]), (), duration=duration, sample_rate=FS, block=64, limiter=False
    )
    return r.audio


def schroeder_t60(channels, low, high):
    """T60 (s) from the -5 to -25 dB slope of the backward-integrated energy in a band,
    the energy summed over the channels (ISO 3382 averages over receiver positions)."""
    sos = signal.butter(4, [low, min(high, 0.49 * FS)], btype="band", fs=FS, output="sos")
    energy = sum(np.cumsum(signal.sosfilt(sos, y)[::-1] ** 2)[::-1] for y in channels)
    level = 10 * np.log10(energy / energy[0])
    a, b = int(np.argmax(level < -5)), int(np.argmax(level < -25))
    slope = np.polyfit(np.arange(a, b) / FS, level[a:b], 1)[0]
    return -60.0 / slope


@pytest.mark.parametrize(
    "t60", [[1.5, 1.4, 1.2, 1.0, 0.85, 0.7, 0.5], [0.6, 0.7, 0.8, 0.9, 0.9, 0.8, 0.6]], ids=["hall", "rising"]
)
def test_measured_t60_per_octave_band_within_10_percent(t60):
    channels = impulse_response(1.7 * max(t60), t60=t60, pre_delay=0.0, dry=0.0, wet=1.0)
    for centre, target in zip(BANDS, t60, strict=True):
        measured = schroeder_t60(channels, centre / np.sqrt(2), centre * np.sqrt(2))
        assert abs(measured / target - 1) < 0.10, (centre, target, measured)


def test_pre_delay_and_first_reflection():
    pre = 0.031
    left, _ = impulse_response(0.2, pre_delay=pre, dry=0.0, wet=1.0, room_size=6.0)
    first = int(np.argmax(np.abs(left) > 0))
    assert first == round(pre * FS) + int(line_lengths(6.0, 343.0, FS).min())


def test_dry_path_is_the_input_and_channels_are_decorrelated():
    x = WhiteNoise(name="n", seed=1)
    node = Reverb(x, name="r", dry=1.0, wet=0.0)
    r = render(Graph([node, node.tap("right")], x), (), duration=0.2, sample_rate=FS, block=64, limiter=False)
    assert np.array_equal(r.audio[0], r.haptic[0]) and np.array_equal(r.audio[1], r.haptic[0])
    left, right = impulse_response(1.0, dry=0.0, wet=1.0)
    assert abs(np.corrcoef(left, right)[0, 1]) < 0.1


def test_rejects_wrong_number_of_bands():
    with pytest.raises(Exception, match=r"r\.t60: expected 7 reverberation times"):
        Reverb(name="r", where="r", t60=[1.0, 2.0])


def test_block_size_invariance():
    def case():
        return Reverb(WhiteNoise(name="n", seed=2), name="u", pre_delay=0.005, room_size=3.0), [
            Event(0.1, "u", "set", {"wet": 0.8})
        ]

    outs = [
        render(Graph(*case()[:1]), case()[1], duration=0.3, sample_rate=FS, block=b, limiter=False).audio[0]
        for b in (1, 64, 1000)
    ]
    assert np.any(outs[0] != 0)
    for out in outs[1:]:
        assert np.max(np.abs(out - outs[0])) < 1e-9
