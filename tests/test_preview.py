"""Previews: the level meter against closed forms, and PNGs from `jassy plot` / `render --plot`."""

import numpy as np
import pytest
import soundfile as sf

from jassy.apps.cli import main
from jassy.apps.preview import levels_db

pytest.importorskip("matplotlib")


def test_levels_of_a_sine_and_silence():
    fs, amplitude = 48000, 0.25
    t = np.arange(fs) / fs
    x = amplitude * np.sin(2 * np.pi * 1000 * t)  # 50 whole periods per 50 ms window
    times, peak, rms = levels_db(np.concatenate([x, np.zeros(fs)]), fs)
    assert times.size == 40 and times[0] == pytest.approx(0.025)
    np.testing.assert_allclose(peak[:20], 20 * np.log10(amplitude), atol=1e-3)
    np.testing.assert_allclose(rms[:20], 20 * np.log10(amplitude / np.sqrt(2)), atol=1e-6)
    assert np.all(peak[20:] == -120.0) and np.all(rms[20:] == -120.0)


def _png_pixels(path):
    import matplotlib.image

    return matplotlib.image.imread(path)


def test_plot_file_writes_a_picture_of_the_sound(tmp_path):
    fs = 16000
    t = np.arange(fs) / fs
    stereo = np.stack([0.5 * np.sin(2 * np.pi * 440 * t), 0.1 * np.sin(2 * np.pi * 3000 * t)], axis=1)
    sf.write(tmp_path / "tone.wav", stereo, fs)
    assert main(["plot", str(tmp_path / "tone.wav"), "-q"]) == 0
    pixels = _png_pixels(tmp_path / "tone.png")
    assert pixels.shape[0] == 800 and pixels.shape[1] == 1000
    assert pixels[..., :3].std() > 0.1  # not a blank canvas


def test_render_plot_checks_its_name_before_rendering(tmp_path, capsys):
    out = tmp_path / "bar.wav"
    assert main(["render", "bar", "-o", str(out), "--plot", str(tmp_path / "bar.jpg"), "-q"]) == 2
    assert "--plot" in capsys.readouterr().err and not out.exists()
    assert (
        main(["render", "bar", "-o", str(out), "--duration", "0.5", "--plot", str(tmp_path / "b.png"), "-q"])
        == 0
    )
    assert out.exists() and _png_pixels(tmp_path / "b.png")[..., :3].std() > 0.1


def test_plot_refuses_a_file_that_is_not_audio(tmp_path, capsys):
    (tmp_path / "x.wav").write_bytes(b"not audio at all")
    assert main(["plot", str(tmp_path / "x.wav")]) == 2
    assert "x.wav" in capsys.readouterr().err
