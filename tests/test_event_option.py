"""`jassy render --event`: score events from the command line."""

import numpy as np
import pytest
import soundfile as sf

from jassy.apps.cli import main
from jassy.errors import PatchError
from jassy.patchfile import parse_event_option


def test_event_text_becomes_a_score_entry():
    entry = parse_event_option(
        "time=1.5, node=hit, action=impact, impulse=0.02, location={vertices=[0,1], weights=[0.5,0.5]}"
    )
    assert entry == {
        "time": 1.5,
        "node": "hit",
        "impact": {"impulse": 0.02, "location": {"vertices": [0, 1], "weights": [0.5, 0.5]}},
    }
    assert parse_event_option("time=2,node=out,gain=0.1,ramp=0.5") == {
        "time": 2,
        "node": "out",
        "ramp": 0.5,
        "set": {"gain": 0.1},
    }
    with pytest.raises(PatchError, match="time: missing"):
        parse_event_option("node=out,gain=1")
    with pytest.raises(PatchError, match="expected key=value"):
        parse_event_option("time=1,node=out,gain")


def test_an_added_strike_changes_the_render_only_from_its_time_on(tmp_path):
    base, more = tmp_path / "base.wav", tmp_path / "more.wav"
    assert main(["render", "bar", "-o", str(base), "--duration", "2", "-q"]) == 0
    event = "time=1.25,node=mallet,action=impact,impulse=0.05,location=x1"
    assert main(["render", "bar", "-o", str(more), "--duration", "2", "--event", event, "-q"]) == 0
    a, fs = sf.read(base)
    b, _ = sf.read(more)
    first = np.flatnonzero(np.abs(b - a) > 1e-9)[0]
    assert first == pytest.approx(1.25 * fs, abs=2)


def test_a_bad_event_names_the_option(tmp_path, capsys):
    out = tmp_path / "x.wav"
    assert (
        main(["render", "bar", "-o", str(out), "--event", "time=1,node=malet,action=impact,impulse=1"]) == 2
    )
    err = capsys.readouterr().err
    assert "--event 'time=1,node=malet" in err and "unknown node 'malet'" in err and not out.exists()
