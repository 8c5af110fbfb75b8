"""Biquad, OnePole, Limiter and Delay against closed forms and independent references."""

import numpy as np
import pytest
import scipy.signal
from helpers import ArraySource, max_abs_diff
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from jassy import Event, Graph, PatchError, render
from ugens.delay import Delay
from ugens.dynamics import Limiter
from ugens.filters import Biquad, OnePole
from ugens.mix import Gain, Mixer

FS = 48000
BLOCKS = (1, 64, 1000)


def rbj(mode, f0, q, fs=FS):
    """(b, a) of the RBJ Audio-EQ-Cookbook filters, normalised so that a[0] = 1."""
    w0 = 2 * np.pi * f0 / fs
    c, alpha = np.cos(w0), np.sin(w0) / (2 * q)
    b = {
        "lowpass": [(1 - c) / 2, 1 - c, (1 - c) / 2],
        "highpass": [(1 + c) / 2, -(1 + c), (1 + c) / 2],
        "bandpass": [alpha, 0.0, -alpha],
    }[mode]
    a = np.array([1 + alpha, -2 * c, 1 - alpha])
    return np.array(b) / a[0], a / a[0]


def run(make, x, block=64, score=()):
    """Render node ``make(source)`` fed by the array x (source named "src")."""
    node = make(ArraySource(x, name="src"))
    return render(Graph(node), score, len(x) / FS, FS, block, limiter=False).audio[0]


def impulse(frames, at=0):
    x = np.zeros(frames)
    x[at] = 1.0
    return x


def noise(frames, seed=1, scale=1.0):
    return scale * np.random.default_rng(seed).standard_normal(frames)


def sine_amplitude(y, f0):
    """Amplitude of the f0 (Hz) sinusoid that best fits y (least squares)."""
    t = np.arange(y.size) / FS
    basis = np.column_stack([np.sin(2 * np.pi * f0 * t), np.cos(2 * np.pi * f0 * t)])
    coef = np.linalg.lstsq(basis, y, rcond=None)[0]
    return float(np.hypot(*coef))


# --------------------------------------------------------------------------- Biquad
@pytest.mark.parametrize(
    "mode, f0, q",
    [
        ("lowpass", 1000.0, 1 / np.sqrt(2)),
        ("lowpass", 40.0, 0.5),
        ("highpass", 250.0, 2.0),
        ("bandpass", 2000.0, 5.0),
    ],
)
def test_biquad_frequency_response_matches_rbj_cookbook(mode, f0, q):
    h = run(lambda s: Biquad(s, mode=mode, freq=f0, q=q), impulse(16384))
    freqs = np.array([20.0, 100.0, 500.0, 1000.0, 2000.0, 5000.0, 12000.0, 20000.0])
    dtft = np.exp(-2j * np.pi * np.outer(freqs / FS, np.arange(h.size))) @ h
    ref = scipy.signal.freqz(*rbj(mode, f0, q), worN=freqs, fs=FS)[1]
    assert np.max(np.abs(np.abs(dtft) / np.abs(ref) - 1)) < 1e-6
    assert np.max(np.abs(dtft - ref) / np.abs(ref)) < 1e-6  # phase too


@pytest.mark.parametrize(
    "mode, f0, q, gain",
    [
        ("lowpass", 1000.0, 1 / np.sqrt(2), 1 / np.sqrt(2)),  # -3.01 dB at the cutoff
        ("highpass", 3000.0, 1 / np.sqrt(2), 1 / np.sqrt(2)),
        ("bandpass", 1000.0, 10.0, 1.0),  # 0 dB peak at the centre, whatever q
        ("bandpass", 5000.0, 0.3, 1.0),
    ],
)
def test_biquad_steady_sine_gain_at_freq(mode, f0, q, gain):
    x = np.sin(2 * np.pi * f0 * np.arange(12000) / FS)
    y = run(lambda s: Biquad(s, mode=mode, freq=f0, q=q), x)
    assert abs(sine_amplitude(y[6000:], f0) / gain - 1) < 1e-6


@pytest.mark.parametrize("mode", ["lowpass", "highpass", "bandpass"])
def test_biquad_matches_lfilter(mode):
    x = noise(20000)
    y = run(lambda s: Biquad(s, mode=mode, freq=700.0, q=1.3), x)
    assert max_abs_diff(y, scipy.signal.lfilter(*rbj(mode, 700.0, 1.3), x)) < 1e-9


def test_biquad_ramp_redesigns_coefficients_every_sample():
    """A freq and q ramp equals a DF2T reference with RBJ coefficients of every sample's values."""
    frames, at, ramp = 1200, 300, 240  # smooth = 0.005 s = 240 samples
    x = noise(frames, seed=2)
    score = [Event(at / FS, "f", "set", {"freq": 4000.0, "q": 3.0})]
    y = run(lambda s: Biquad(s, mode="bandpass", freq=500.0, q=0.7, name="f"), x, score=score)
    k = np.clip(np.arange(frames) - at, 0, ramp) / ramp  # ramp_fill: old value at "at", target at at + ramp
    freqs, qs = 500.0 + k * 3500.0, 0.7 + k * 2.3
    ref, s1, s2 = np.zeros(frames), 0.0, 0.0
    for i in range(frames):
        b, a = rbj("bandpass", freqs[i], qs[i])
        ref[i] = b[0] * x[i] + s1
        s1, s2 = b[1] * x[i] - a[1] * ref[i] + s2, b[2] * x[i] - a[2] * ref[i]
    assert max_abs_diff(y, ref) < 1e-9


def test_biquad_freq_at_or_above_nyquist_is_a_patch_error():
    x = noise(100)
    with pytest.raises(PatchError, match=r"nodes\.f\.freq.*Nyquist"):
        run(lambda s: Biquad(s, freq=24000.0, name="f"), x)
    with pytest.raises(PatchError, match=r"score\[0\]\.set\.freq.*Nyquist"):
        run(
            lambda s: Biquad(s, freq=1000.0, name="f"), x, score=[Event(0.001, "f", "set", {"freq": 30000.0})]
        )
    assert np.any(run(lambda s: Biquad(s, freq=23000.0, name="f"), x) != 0)


# -------------------------------------------------------------------------- OnePole
@pytest.mark.parametrize("cutoff", [5.0, 1000.0, 15000.0])
def test_onepole_matches_lfilter(cutoff):
    x = noise(20000)
    y = run(lambda s: OnePole(s, cutoff=cutoff), x)
    a = 1 - np.exp(-2 * np.pi * cutoff / FS)
    assert max_abs_diff(y, scipy.signal.lfilter([a], [1, a - 1], x)) < 1e-9


# -------------------------------------------------------------------------- Limiter
@settings(max_examples=40, deadline=None)
@given(
    x=hnp.arrays(np.float64, st.integers(1, 300), elements=st.floats(-1e3, 1e3) | st.floats()),
    ceiling=st.floats(1e-3, 1.0),
    release=st.floats(0.0, 0.5),
    block=st.sampled_from(BLOCKS),
)
def test_limiter_output_never_exceeds_ceiling(x, ceiling, release, block):
    y = run(lambda s: Limiter(s, ceiling=ceiling, release=release), x, block)
    assert np.all(np.isfinite(y))
    assert np.all(np.abs(y) <= ceiling)


def test_limiter_passes_quiet_signal_unchanged():
    x = 0.5 * np.sin(2 * np.pi * 440.0 * np.arange(4800) / FS) + noise(4800, scale=0.1).clip(-0.3, 0.3)
    assert np.array_equal(run(lambda s: Limiter(s, ceiling=0.9), x), x)


def test_limiter_gain_drops_at_once_and_recovers_with_release():
    """A spike of 4 under ceiling 1 sets the gain to 1/4; then g[k] = 1 - 3/4 c^k, c = e^(-1/(release fs))."""
    x = np.full(2000, 0.1)
    x[0] = 4.0
    y = run(lambda s: Limiter(s, ceiling=1.0, release=0.01), x)
    c = np.exp(-1 / (0.01 * FS))
    expected = 0.1 * (1 - 0.75 * c ** np.arange(1, 2000))
    assert y[0] == 1.0
    assert max_abs_diff(y[1:], expected) < 1e-12


def test_limiter_turns_nan_and_inf_into_zero():
    x = noise(1000, scale=0.1)
    bad = [10, 11, 500, 999]
    x[bad] = [np.nan, np.inf, -np.inf, np.nan]
    node = Limiter(ArraySource(x), ceiling=0.9)
    r = render(Graph(node), [], len(x) / FS, FS, 64, limiter=False)
    y = r.audio[0]
    assert np.all(y[bad] == 0.0)
    good = np.setdiff1d(np.arange(x.size), bad)
    assert np.array_equal(y[good], x[good])
    assert r.warnings == []


# ---------------------------------------------------------------------------- Delay
@pytest.mark.parametrize("block", BLOCKS)
@pytest.mark.parametrize("d", [1, 37, 480])
def test_delay_shifts_an_impulse_by_exactly_d_samples(d, block):
    y = run(lambda s: Delay(s, time=d / FS), impulse(3000, at=5), block)
    assert np.array_equal(y, impulse(3000, at=5 + d))


def feedback_comb(x, d, g, block):
    """y = x + g * Delay(y); returns (y, graph)."""
    y = Mixer(ArraySource(x), name="y")
    y(Gain(Delay(y, time=d / FS, name="d"), gain=g))
    graph = Graph(y)
    return render(graph, [], len(x) / FS, FS, block, limiter=False).audio[0], graph


def test_feedback_comb_matches_closed_form_at_every_block_size():
    d, g, frames = 37, 0.97, 4800
    expected = np.zeros(frames)
    k = np.arange(0, frames, d)
    expected[k] = g ** (k // d)
    outs = []
    for block in BLOCKS:
        y, graph = feedback_comb(impulse(frames), d, g, block)
        assert graph.max_sub_block == min(block, d)
        assert max_abs_diff(y, expected) < 1e-12
        outs.append(y)
    assert max_abs_diff(outs[0], outs[1]) == 0.0 and max_abs_diff(outs[0], outs[2]) == 0.0


def test_cycle_without_delay_is_a_patch_error():
    y = Mixer(ArraySource(impulse(10)), name="y")
    y(Gain(y, gain=0.5))
    with pytest.raises(PatchError, match="cycle without delay"):
        Graph(y)


def test_delay_rounding_to_zero_samples_is_a_patch_error():
    with pytest.raises(PatchError, match=r"nodes\.d\.time"):
        run(lambda s: Delay(s, time=0.4 / FS, name="d"), impulse(10))


# ------------------------------------------------------------ block-size invariance
def comb_with_lowpass(s):
    """y = s + 0.8 * OnePole(Delay(y)): a loop with a smoothed parameter inside."""
    y = Mixer(s, name="y")
    y(Gain(OnePole(Delay(y, time=100 / FS), cutoff=3000.0, name="lp"), gain=0.8))
    return y


INVARIANCE = {
    "biquad-lowpass": (
        lambda s: Biquad(s, mode="lowpass", freq=800.0, name="n"),
        [
            Event(0.01, "n", "set", {"freq": 5000.0}),
            Event(0.0123, "n", "set", {"q": 4.0}),
            Event(0.05, "n", "set", {"freq": 300.0}, jump=True),
        ],
    ),
    "biquad-highpass": (
        lambda s: Biquad(s, mode="highpass", freq=2000.0, q=0.5, name="n"),
        [Event(0.02, "n", "set", {"freq": 100.0, "q": 2.0}), Event(0.0221, "n", "set", {"freq": 9000.0})],
    ),
    "biquad-bandpass": (
        lambda s: Biquad(s, mode="bandpass", freq=1500.0, q=8.0, smooth=0.02, name="n"),
        [Event(0.0301, "n", "set", {"q": 0.6})],
    ),
    "onepole": (
        lambda s: OnePole(s, cutoff=200.0, name="n"),
        [Event(0.01, "n", "set", {"cutoff": 8000.0}), Event(0.06, "n", "set", {"cutoff": 50.0}, jump=True)],
    ),
    "limiter": (
        lambda s: Limiter(Gain(s, gain=5.0), ceiling=0.5, release=0.01, name="n"),
        [Event(0.03, "n", "set", {"ceiling": 0.2}), Event(0.06, "n", "set", {"release": 0.001})],
    ),
    "delay": (lambda s: Delay(s, time=0.0021), []),
    "delay-loop": (comb_with_lowpass, [Event(0.04, "lp", "set", {"cutoff": 500.0})]),
}


@pytest.mark.parametrize("case", list(INVARIANCE))
def test_output_does_not_depend_on_block_size(case):
    make, score = INVARIANCE[case]
    x = noise(4800, seed=7)
    outs = [run(make, x, block, score) for block in BLOCKS]
    assert np.max(np.abs(outs[1])) > 0.01
    assert max_abs_diff(outs[0], outs[1]) < 1e-6
    assert max_abs_diff(outs[2], outs[1]) < 1e-6
