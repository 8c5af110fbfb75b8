"""jassy analyze: feature curves of a file as CSV and a plot; bad arguments exit 2."""

import csv

import numpy as np
import soundfile as sf

from jassy.apps.cli import main

FS = 44100


def test_analyze_writes_pitch_centroid_and_onsets(tmp_path, capsys):
    t = np.arange(FS) / FS
    x = np.zeros(2 * FS)
    fade = np.minimum(1.0, (1.0 - t) / 0.2)  # a tone from 0.5 to 1.5 s, faded out (no click)
    x[FS // 2 : FS // 2 + FS] = 0.5 * np.sin(2 * np.pi * 330.0 * t) * fade
    path = tmp_path / "tone.wav"
    sf.write(path, x, FS)
    out, png = tmp_path / "f.csv", tmp_path / "f.png"
    assert (
        main(["analyze", str(path), "-o", str(out), "--plot", str(png), "--features", "pitch,centroid,onset"])
        == 0
    )
    with open(out) as fh:
        rows = list(csv.DictReader(fh))
    times = np.array([float(r["time_s"]) for r in rows])
    pitch = np.array([float(r["pitch"]) for r in rows])
    centroid = np.array([float(r["centroid"]) for r in rows])
    onset = np.array([float(r["onset"]) for r in rows])
    inside = (times > 0.6) & (times < 1.3)
    assert np.all(np.abs(pitch[inside] / 330.0 - 1) < 1e-3)
    assert np.all(np.abs(centroid[inside] / 330.0 - 1) < 0.02)
    assert np.all(pitch[times < 0.45] == 0.0) and np.all(pitch[times > 1.6] == 0.0)
    hits = times[onset > 0]
    assert hits.size == 1 and 0.5 <= hits[0] <= 0.5 + 3 * 2048 / FS
    assert png.stat().st_size > 1000 and "pitch" in capsys.readouterr().out


def test_analyze_bad_arguments_exit_2(tmp_path, capsys):
    path = tmp_path / "x.wav"
    sf.write(path, np.zeros(1000), FS)
    assert main(["analyze", str(path), "--features", "pich"]) == 2
    assert "did you mean 'pitch'" in capsys.readouterr().err
    assert main(["analyze", str(tmp_path / "none.wav")]) == 2
    assert "no such file" in capsys.readouterr().err
    assert main(["analyze", str(path), "-o", str(tmp_path / "f.txt")]) == 2


def test_a_recordings_envelope_drives_a_parameter(tmp_path):
    """The RMS envelope of an amplitude-modulated tone, as events, makes a Gain's gain
    follow the modulation (read on a constant input)."""
    from helpers import ArraySource

    from jassy import Graph, render
    from jassy.apps.analyze import analyze, feature_events
    from ugens import Gain

    t = np.arange(2 * FS) / FS
    envelope = 0.5 + 0.4 * np.sin(2 * np.pi * 1.5 * t)
    path = tmp_path / "am.wav"
    sf.write(path, envelope * np.sin(2 * np.pi * 1000.0 * t), FS)
    features = analyze(str(path), ["rms"], size=1024, hop=256)
    events = feature_events(features, "rms", "g", "gain", scale=np.sqrt(2))  # RMS of a sine: amp / sqrt 2
    gain = render(Graph(Gain(ArraySource(np.ones(2 * FS)), name="g", gain=0.0)), events, 2.0, FS, 64,
                  limiter=False).audio[0]  # fmt: skip
    inside = slice(int(0.2 * FS), int(1.9 * FS))
    # the one-pole RMS follower (time constant one hop) and the ramps lag by about two hops
    lagged = np.interp(t - 2 * 256 / FS, t, envelope)
    assert np.max(np.abs(gain[inside] - lagged[inside])) < 0.03
