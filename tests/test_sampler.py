"""Sampler: exact playback, loop period, varispeed pitch and duration, bad files."""

import numpy as np
import pytest
import soundfile as sf

from jassy import Event, Graph, PatchError, render
from ugens.sampler import Sampler

FS = 48000


def run(node, score=(), duration=1.0, block=64):
    return render(Graph(node), score, duration=duration, sample_rate=FS, block=block, limiter=False).audio[0]


@pytest.fixture
def tone(tmp_path):
    """0.5 s of a 440 Hz sine (float WAV at 48 kHz) and its samples."""
    data = 0.5 * np.sin(2 * np.pi * 440.0 * np.arange(FS // 2) / FS)
    path = tmp_path / "tone.wav"
    sf.write(path, data, FS, subtype="DOUBLE")
    return str(path), data


def test_plays_the_file_exactly_then_stops(tone):
    path, data = tone
    y = run(Sampler(name="s", file=path))
    assert np.array_equal(y[: data.size], data)
    assert np.all(y[data.size :] == 0.0)


def test_loop_repeats_the_span(tone):
    path, data = tone
    a, b = 0.1, 0.25
    y = run(Sampler(name="s", file=path, loop=True, loop_start=a, loop_end=b), duration=1.0)
    span = int(round((b - a) * FS))
    first = int(b * FS)  # the first pass reaches loop_end, then jumps to loop_start
    np.testing.assert_allclose(y[first : first + span], data[int(a * FS) : int(b * FS)], atol=1e-12)
    np.testing.assert_allclose(y[first + span : first + 2 * span], y[first : first + span], atol=1e-12)


@pytest.mark.parametrize("rate", [2.0, 0.75])
def test_varispeed_scales_pitch_and_duration(tone, rate):
    path, data = tone
    y = run(Sampler(name="s", file=path, rate=rate), duration=1.0)
    sounding = np.flatnonzero(y)
    assert abs(sounding[-1] + 1 - (data.size - 1) / rate) <= 1.0
    seg = y[1000 : int(0.4 / rate * FS)]
    spectrum = np.abs(np.fft.rfft(seg * np.hanning(seg.size), 16 * seg.size))
    peak = np.argmax(spectrum) * FS / (16 * seg.size)
    assert abs(peak / (440.0 * rate) - 1) < 1e-3


def test_play_and_stop_events(tone):
    path, data = tone
    score = [Event(0.1, "s", "play", {"at": 0.2}), Event(0.2, "s", "stop", {})]
    y = run(Sampler(name="s", file=path, playing=False), score, duration=0.3)
    assert np.all(y[: int(0.1 * FS)] == 0.0) and np.all(y[int(0.2 * FS) :] == 0.0)
    start = int(0.1 * FS)
    np.testing.assert_allclose(y[start : start + 100], data[int(0.2 * FS) : int(0.2 * FS) + 100], atol=1e-12)


def test_missing_file_is_a_patch_error(tmp_path):
    with pytest.raises(PatchError, match=r"nodes\.s\.file: .*nope\.wav: no such file"):
        run(Sampler(name="s", file=str(tmp_path / "nope.wav")))


def test_block_size_invariance(tone):
    path, _ = tone

    def case():
        return Sampler(name="u", file=path, loop=True, loop_start=0.05, loop_end=0.2), [
            Event(0.1, "u", "set", {"rate": 1.7}, ramp=0.05),
            Event(0.25, "u", "play", {"at": 0.3}),
        ]

    outs = [run(*case(), duration=0.4, block=block) for block in (1, 64, 1000)]
    for out in outs[1:]:
        assert np.max(np.abs(out - outs[0])) < 1e-12
