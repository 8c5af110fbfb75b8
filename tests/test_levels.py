"""The limiter reports what it cut; --normalise reaches its peak or loudness target."""

import math

import numpy as np
import pytest
import soundfile as sf

from jassy.apps.cli import main
from jassy.engines.offline import render
from jassy.patchfile import load_patch
from jassy.safety import CEILING, pinned_samples

SINE_PATCH = """
[patch]
duration = 3.0
[nodes.tone]
type = "Sine"
freq = 1000.0
amp = {amp}
[outputs]
audio = "tone"
"""


def test_pinned_runs_are_counted_across_chunks():
    c = CEILING
    a = np.array([[0.0, c, c, 0.5, -c, -c, -c]])
    count, longest, run = pinned_samples(a, a.shape[1], c, 0)
    assert (count, longest, run) == (5, 3, 3)
    b = np.array([[-c, 0.0]])
    assert pinned_samples(b, 2, c, run) == (1, 4, 0)  # the open run goes on into the next chunk


def test_the_limiter_reports_the_reduction_it_applied():
    patch = load_patch("bell", ["out.gain=4.0"])
    raw = render(patch.graph, patch.score, 2.0, limiter=False)
    peak = float(np.max(np.abs(raw.audio)))
    assert peak > 1.0
    patch = load_patch("bell", ["out.gain=4.0"])
    limited = render(patch.graph, patch.score, 2.0)
    (warning,) = [w for w in limited.warnings if w.startswith("limiter:")]
    assert f"reduced by {20 * math.log10(peak / CEILING):.1f} dB" in warning
    quiet = load_patch("bell")
    assert not any(w.startswith("limiter:") for w in render(quiet.graph, quiet.score, 2.0).warnings)


@pytest.mark.parametrize(("mode", "target"), [("peak", -3.0), ("lufs", -20.0)])
def test_normalise_reaches_the_target_on_a_sine(tmp_path, mode, target):
    src = tmp_path / "tone.toml"
    src.write_text(SINE_PATCH.format(amp=0.01))
    out = tmp_path / "tone.wav"
    assert main(["render", str(src), "-o", str(out), "--normalise", mode, "--target", str(target), "-q"]) == 0
    x, fs = sf.read(out)
    amplitude = np.max(np.abs(x))
    if mode == "peak":
        assert 20 * np.log10(amplitude) == pytest.approx(target, abs=0.01)
    else:  # BS.1770: a full-scale 1 kHz sine in one channel reads -3.01 LUFS
        assert 20 * np.log10(amplitude) - 3.01 == pytest.approx(target, abs=0.1)


def test_target_without_normalise_is_refused(tmp_path, capsys):
    assert main(["render", "bar", "-o", str(tmp_path / "x.wav"), "--target", "-3"]) == 2
    assert "--target" in capsys.readouterr().err


def test_render_writes_the_file_it_returns(tmp_path):
    patch = load_patch("bar")
    out = render(patch.graph, patch.score, 0.5, path=tmp_path / "bar.wav", haptic_path=tmp_path / "f.npz")
    data, fs = sf.read(tmp_path / "bar.wav", always_2d=True)
    assert fs == 48000 and data.shape == out.audio.T.shape
    np.testing.assert_array_equal(data.T, out.audio.astype(np.float32))
    assert np.load(tmp_path / "f.npz")["data"].shape == out.haptic.shape
