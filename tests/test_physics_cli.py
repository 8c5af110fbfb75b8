"""The physics entry points of the CLI: ``jassy rod`` and the rigid scenes of ``jassy render``."""

import json

import numpy as np
import soundfile as sf

from jassy.apps.cli import main


def test_rod_list_and_unknown_name(capsys):
    assert main(["rod", "list"]) == 0
    names = capsys.readouterr().out.split()
    assert {"cantilever", "vibration", "snap_fit", "shell_stack", "archery", "bicycle"} <= set(names)
    assert main(["rod", "no_such"]) == 2
    assert "unknown experiment 'no_such'" in capsys.readouterr().err


def test_rod_vibration_prints_json_with_euler_bernoulli_ratio(capsys, tmp_path):
    png = tmp_path / "vib.png"
    assert main(["rod", "vibration", "--quick", "--plot", str(png)]) == 0
    result = json.loads(capsys.readouterr().out)
    # first cantilever frequency, chained model, within 1 % of beta L = 1.8751 (independent of the code)
    assert abs(result["chained_L1_rel_error"][0]) < 0.01
    assert png.stat().st_size > 1000
    assert main(["rod", "vibration", "--plot", str(tmp_path / "x.jpg")]) == 2


def test_render_drop_scene_from_the_cli(tmp_path):
    wav, csv = tmp_path / "drop.wav", tmp_path / "drop.csv"
    assert main(["render", "drop", "-o", str(wav), "--csv", str(csv), "--duration", "1.0", "-q"]) == 0
    audio, rate = sf.read(wav)
    assert len(audio) == rate and np.all(np.isfinite(audio))
    impacts = np.loadtxt(csv, delimiter=",", skiprows=1, ndmin=2)
    assert len(impacts) > 0 and np.all(np.diff(impacts[:, 0]) >= 0)
    assert main(["render", "drop", "-o", str(wav), "--duration", "-1"]) == 2
