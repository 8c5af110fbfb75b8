"""Every name error suggests the closest valid name ("did you mean ...?"): patches, nodes,
actions, arguments, parameters, points, patch-file keys, models, audit targets."""

from __future__ import annotations

from pathlib import Path

import pytest

from jassy.apps.cli import main

PATCH = """
[patch]
name = "typo"
{patch_extra}
[models.glass]
file = "{model}"
{top_extra}
[nodes.hit]
type = "ImpactForce"

[nodes.body]
type = "ModalBank"
model = "{model_ref}"
input = "hit"
location = "{point}"

[outputs]
audio = "body"
"""
MODEL = Path(__file__).resolve().parents[1] / "patches" / "wine_glass_model.toml"
GOOD = {"patch_extra": "", "top_extra": "", "model_ref": "glass", "point": "rim"}


def patch_file(tmp_path, **changes):
    """A one-strike wine-glass patch with ``changes`` made to it."""
    path = tmp_path / "typo.toml"
    path.write_text(PATCH.format(model=MODEL.as_posix(), **{**GOOD, **changes}))
    return str(path)


CLI_CASES = {
    "patch": (["render", "bel"], "bell"),
    "event node": (["render", "bell", "--event", "time=0.1,node=clappr,action=impact"], "clapper"),
    "event action": (["render", "bell", "--event", "time=0.1,node=clapper,action=impct"], "impact"),
    "event argument": (
        ["render", "bell", "--event", "time=0.1,node=clapper,action=impact,impuls=0.1"],
        "impulse",
    ),
    "set node": (["render", "bell", "--set", "clappr.duration=0.001"], "clapper"),
    "audit patch": (["check-audio", "bel"], "bell"),
}


@pytest.mark.parametrize("case", CLI_CASES)
def test_cli_name_errors_suggest_the_closest_name(case, tmp_path, capsys):
    args, expected = CLI_CASES[case]
    out = ["-o", str(tmp_path / "x.wav")] if args[0] == "render" else []
    assert main([*args, *out]) == 2
    err = capsys.readouterr().err
    assert f"did you mean {expected!r}?" in err, err


FILE_CASES = {
    "patch key": ({"patch_extra": "duraton = 1.0"}, "duration"),
    "top-level key": ({"top_extra": "[scor]\n"}, "score"),
    "model reference": ({"model_ref": "glas"}, "glass"),
    "point": ({"point": "rimm"}, "rim"),
}


@pytest.mark.parametrize("case", FILE_CASES)
def test_patch_file_name_errors_suggest_the_closest_name(case, tmp_path, capsys):
    changes, expected = FILE_CASES[case]
    assert main(["render", patch_file(tmp_path, **changes), "-o", str(tmp_path / "x.wav")]) == 2
    err = capsys.readouterr().err
    assert f"did you mean {expected!r}?" in err, err
