"""User-study scripts: exact offsets, simulated observers, resume, fits, CLI, live.

Independent checks: onsets against the impact's first frame computed from its time,
offsets against round(ms * fs / 1000), fits against scipy minimisation and profile
likelihoods computed by scipy, coverage of the intervals over simulated participants,
the JND against a root of the fitted function, QUEST+ choices against the questplus
package, staircases against hand-computed sequences, Latin squares against their defining
property.
"""

from __future__ import annotations

import argparse
import csv
import io
import math
import os
import re
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import brentq, minimize
from scipy.special import ndtri

from jassy.errors import JassyError
from jassy.study import (
    CallableResponder,
    SimulatedObserver,
    make_model,
    measure_offset,
    parse_design,
    read_rows,
    render_trial,
    run_study,
)
from jassy.study.analysis import analyze
from jassy.study.design import DesignError, ObserverSpec, balanced_latin_square, load_design
from jassy.study.fitting import CHI2_95, fit
from jassy.study.methods import QuestPlusTrack, QuestTrack, Staircase
from jassy.study.observer import TrialInfo
from jassy.study.runner import ResultsError, read_header

FS = 48000
ROOT = Path(__file__).resolve().parents[1]
TAP_FRAME = 4800  # wall_tap's first impact at 0.1 s: the pulse is non-zero from frame 4801


def design(tmp_path=None, **over):
    study = {
        "name": "t",
        "stimulus": "wall_tap",
        "trial_duration": 0.15,
        "sample_rate": FS,
        "block": 64,
        "seed": 7,
        "task": "toj",
    }
    method = {"kind": "constant", "offsets_ms": [-2.0, 2.0], "repetitions": 5}
    observer = {"pss_ms": 0.0, "sigma_ms": 20.0, "lapse": 0.02}
    for key, value in over.items():
        target = (
            method
            if key
            in (
                "kind",
                "offsets_ms",
                "repetitions",
                "rule",
                "tracks",
                "start_ms",
                "steps_ms",
                "min_ms",
                "max_ms",
                "reversals",
                "max_trials",
            )
            else study
        )
        if key in observer:
            observer[key] = value
        else:
            target[key] = value
    if method["kind"] == "staircase":
        del method["offsets_ms"], method["repetitions"]
    return parse_design({"study": study, "method": method, "observer": observer}, "test-design")


# --------------------------------------------------------------------------- exact offsets
@pytest.mark.parametrize("block", [1, 64, 1000])
def test_measured_offset_equals_requested_to_the_sample_at_every_block_size(block):
    d = design(block=block)
    offsets = [-2.0, 2.0, 0.0, -10.0, 7.5, 1000.0 / FS] if block != 1 else [-2.0, 2.0, 0.0]
    for ms in offsets:
        r = render_trial(d, ms)
        a_on, h_on, measured = measure_offset(r.audio, r.haptic)
        expected = int(round(ms * FS / 1000.0))
        assert measured == expected, (block, ms)
        # the earlier kind starts where the impact starts, the later one exactly |offset| after
        assert min(a_on, h_on) == TAP_FRAME + 1
        assert max(a_on, h_on) == TAP_FRAME + 1 + abs(expected)
    assert int(round(2.0 * FS / 1000.0)) == 96


def test_onset_detection_ignores_waveform_shape_and_level():
    rng = np.random.default_rng(3)
    for shift_a, shift_h in [(100, 196), (500, 404), (7, 7)]:
        audio = np.zeros((2, 2000))
        haptic = np.zeros((1, 2000))
        audio[1, shift_a : shift_a + 300] = 1e-3 * rng.standard_normal(300) * np.exp(-np.arange(300) / 50)
        audio[1, shift_a] = 1e-7  # a faint first sample (5e-5 of the peak) still counts
        haptic[0, shift_h : shift_h + 50] = 40.0 * np.sin(np.pi * (np.arange(50) + 0.5) / 50) ** 2
        a, h, m = measure_offset(audio, haptic, threshold=1e-6)
        assert (a, h, m) == (shift_a, shift_h, shift_a - shift_h)
    with pytest.raises(JassyError, match="silent"):
        measure_offset(np.zeros((1, 10)), np.ones((1, 10)))


def test_every_logged_trial_records_the_exact_offset(tmp_path):
    d = design(offsets_ms=[-20.0, -2.0, -0.5, 0.0, 0.5, 2.0, 20.0], repetitions=2)
    result = run_study(d, tmp_path / "r.csv", "P1")
    rows = read_rows(tmp_path / "r.csv")
    assert result.completed and len(rows) == 14
    for row in rows:
        requested = float(row["requested_ms"])
        assert int(row["requested_samples"]) == int(round(requested * FS / 1000))
        assert int(row["measured_samples"]) == int(row["requested_samples"])
        assert float(row["measured_ms"]) == pytest.approx(int(row["measured_samples"]) * 1000 / FS)
        assert int(row["audio_onset"]) - int(row["haptic_onset"]) == int(row["measured_samples"])
        assert row["response"] in ("audio", "haptic")
        assert float(row["response_time_s"]) > 0
    # each offset exactly `repetitions` times, in a seeded order that depends on the participant
    offsets = [float(r["requested_ms"]) for r in rows]
    assert sorted(offsets) == sorted([-20.0, -2.0, -0.5, 0.0, 0.5, 2.0, 20.0] * 2)
    again = run_study(d, tmp_path / "r2.csv", "P1")
    assert again.completed
    assert [float(r["requested_ms"]) for r in read_rows(tmp_path / "r2.csv")] == offsets
    run_study(d, tmp_path / "r3.csv", "P2")
    assert [float(r["requested_ms"]) for r in read_rows(tmp_path / "r3.csv")] != offsets
    header = read_header(tmp_path / "r.csv")
    assert header["participant"] == "P1" and header["sessions"][0]["completed"]
    assert header["sessions"][0]["software"]["numpy"] == np.__version__
    assert header["design"]["method"]["offsets_ms"][1] == -2.0


def test_the_pilot_example_reproduces_the_seed_design(tmp_path):
    d = load_design(ROOT / "examples" / "pilot_study.toml")
    assert d.task == "toj" and d.method["offsets_ms"] == [-2.0, 2.0]
    result = run_study(d, tmp_path / "pilot.csv", "SIM")
    rows = read_rows(tmp_path / "pilot.csv")
    assert result.completed and len(rows) == 2 * d.method["repetitions"]
    assert {int(r["measured_samples"]) for r in rows} == {-96, 96}


# --------------------------------------------------------------------------- models, fits, observers
def _profile_by_scipy(model, x, y, name, value):
    """max over the other parameters of the log likelihood with ``name`` fixed (scipy)."""
    from jassy.study.fitting import aggregate

    levels, k, n = aggregate(x, y)
    others = [p for p in model.params if p.name != name]

    def nll(v):
        theta = {name: value}
        for p, t in zip(others, v, strict=True):
            theta[p.name] = math.exp(t) if p.scale else t
        theta["lapse"] = min(max(theta["lapse"], 0.0), 0.1)
        q = np.clip(model.prob(levels, **theta), 1e-12, 1 - 1e-12)
        return -np.sum(k * np.log(q) + (n - k) * np.log1p(-q))

    starts = [
        [math.log(s0) if p.scale else (0.0 if p.name == "pss" else 0.02) for p in others]
        for s0 in (8, 20, 60)
    ]
    return -min(
        minimize(nll, s0, method="Nelder-Mead", options={"xatol": 1e-7, "fatol": 1e-10}).fun for s0 in starts
    )


@pytest.mark.parametrize("task, function", [("toj", "gaussian"), ("toj", "logistic"), ("sj", "gaussian")])
def test_fit_is_the_likelihood_maximum_and_its_interval_ends_are_where_the_profile_drops_by_1_92(
    task, function
):
    model = make_model(task, function)
    rng = np.random.default_rng(11)
    truth = {"pss": 6.0, "sigma": 18.0 if task == "toj" else 40.0, "lapse": 0.03}
    x = np.repeat(np.linspace(-90.0, 90.0, 9) * (1 if task == "toj" else 1.6), 30)
    y = (rng.random(x.size) < model.prob(x, **truth)).astype(float)
    result = fit(model, x, y)
    e = result.estimates["pss"]
    assert e.identifiable and e.low < e.value < e.high
    top = _profile_by_scipy(model, x, y, "pss", e.value)
    assert result.loglik >= top - 1e-6  # no better maximum than the fit's
    for end in (e.low, e.high):  # the interval's ends, independently: profile = max - chi2/2
        assert _profile_by_scipy(model, x, y, "pss", end) == pytest.approx(
            result.loglik - CHI2_95 / 2, abs=0.06
        )


def test_jnd_is_the_distance_from_the_50_to_the_75_percent_point():
    x = np.repeat(np.linspace(-50, 50, 11), 40)
    rng = np.random.default_rng(5)
    for function in ("gaussian", "logistic"):
        model = make_model("toj", function)
        y = (rng.random(x.size) < model.prob(x, pss=3.0, sigma=12.0, lapse=0.0)).astype(float)
        est = fit(model, x, y).estimates
        pss, sigma = est["pss"].value, est["sigma"].value
        x75 = brentq(
            lambda v, m=model, c=pss, s=sigma: m.prob(v, pss=c, sigma=s, lapse=0.0) - 0.75,
            pss,
            pss + 10 * sigma,
        )
        assert est["jnd"].value == pytest.approx(x75 - pss, rel=1e-9)
        assert est["jnd"].low == pytest.approx(est["sigma"].low * (x75 - pss) / sigma, rel=1e-9)
    assert float(ndtri(0.75)) == pytest.approx(0.6744897501960817)


def test_models_have_their_defining_points():
    sj = make_model("sj", "gaussian")  # window = full width at half height
    assert sj.prob(10.0 + 0.5 * sj.derived({"sigma": 30.0})["window"], pss=10.0, sigma=30.0, lapse=0.0) == (
        pytest.approx(0.5)
    )
    diff = make_model("sj", "difference")  # each boundary is the 50 % point of its edge
    edge = diff.prob(np.array([-60.0, 0.0, 60.0]) + 5.0, pss=5.0, window=120.0, sigma=1e-3, lapse=0.0)
    assert edge == pytest.approx([0.5, 1.0, 0.5])
    for m in (2, 3):  # m-AFC: chance 1/m, halfway to 1 at the threshold, 1 - lapse (1 - 1/m) far above
        afc = make_model(f"{m}afc")
        p = afc.prob(np.array([0.0, -25.0, 1e4]), threshold=25.0, slope=2.0, lapse=0.06)
        assert p == pytest.approx([1 / m, 1 / m + 0.5 * (1 - 1 / m) * 0.94, 1 - 0.06 * (1 - 1 / m)])


@pytest.mark.parametrize("task, function", [("toj", "gaussian"), ("sj", "difference"), ("3afc", "weibull")])
def test_simulated_observer_answers_follow_its_model(task, function):
    spec = ObserverSpec(pss_ms=5.0, sigma_ms=10.0, window_ms=60.0, threshold_ms=12.0, slope=2.0, lapse=0.1)
    obs = SimulatedObserver(spec, seed=1, function=function)
    model = make_model(task, function)
    for offset in (-20.0, 5.0, 25.0):
        info = TrialInfo(0, None, offset, task, {}, 2)
        answers = [obs.respond(info).answer for _ in range(4000)]
        positive = {"toj": "haptic", "sj": "simultaneous", "3afc": "2"}[task]
        p = np.mean([a == positive for a in answers])
        expected = float(model.prob(offset, **spec.theta(model)))
        if task == "toj":  # closed form, independent of the model code
            expected = 0.05 + 0.9 * 0.5 * math.erfc(-(offset - 5.0) / 10.0 / math.sqrt(2))
        assert p == pytest.approx(expected, abs=4 * math.sqrt(expected * (1 - expected) / 4000) + 1e-3)


def test_the_pilot_design_is_reported_not_identifiable_without_intervals():
    # the pilot: +-2 ms, 20 repetitions, an observer with JND 20 ms (sigma 30): nothing to fit
    model = make_model("toj")
    rng = np.random.default_rng(2)
    for _ in range(10):
        x = np.repeat([-2.0, 2.0], 20)
        y = (rng.random(x.size) < model.prob(x, pss=0.0, sigma=30.0, lapse=0.02)).astype(float)
        est = fit(model, x, y).estimates
        assert not est["pss"].identifiable and not est["jnd"].identifiable
        assert est["pss"].low is None and est["jnd"].high is None


def test_coverage_of_the_95_percent_intervals_and_quest_plus_precision():
    """A smaller version of `jassy study coverage`: 20 simulated participants per task and
    method; the truth must lie inside the 95 % interval for at least 17 of them (85 %), and
    QUEST+ must reach the constant-stimuli interval width in fewer trials."""
    from jassy.study.validation import coverage, simulate, trials_for_precision

    for task in ("toj", "sj"):
        const = coverage(task, "constant", simulate(task, "constant", 20, 5))
        runs = simulate(task, "quest_plus", 20, 5, 180)
        quest = coverage(task, "quest_plus", runs)
        for row in (const, quest):
            assert row.not_identifiable == 0
            assert all(v >= 17 for v in row.covered.values()), (task, row)
        needed, _ = trials_for_precision(task, runs, const.median_width, step=30)
        assert needed is not None and needed < const.trials, (task, needed, const.trials)


# --------------------------------------------------------------------------- methods
def test_quest_plus_chooses_the_offsets_the_questplus_package_chooses():
    questplus = pytest.importorskip("questplus")
    offsets = np.arange(-100.0, 101.0, 10.0)
    means, sds, lapses = (
        np.linspace(-40, 40, 9),
        np.array([5.0, 10.0, 20.0, 40.0]),
        np.array([0.0, 0.02, 0.05]),
    )
    ref = questplus.QuestPlus(
        stim_domain={"intensity": offsets},
        param_domain={"mean": means, "sd": sds, "lapse_rate": lapses},
        outcome_domain={"response": ["Yes", "No"]},
        func="norm_cdf_2",
        stim_scale="linear",
    )
    # norm_cdf_2: lapse_rate + (1 - 2 lapse_rate) Phi = our TOJ model with lapse = 2 lapse_rate
    ours = QuestPlusTrack(
        "q",
        make_model("toj"),
        offsets,
        {"pss": means, "sigma": sds, "lapse": 2 * lapses},
        30,
        np.random.default_rng(0),
    )
    truth = make_model("toj")
    rng = np.random.default_rng(4)
    for _ in range(12):
        chosen = ours.next_offset()
        assert chosen == ref.next_stim["intensity"]
        positive = bool(rng.random() < truth.prob(chosen, pss=12.0, sigma=15.0, lapse=0.02))
        ours.update(chosen, positive, None)
        ref.update(stim={"intensity": chosen}, outcome={"response": "Yes" if positive else "No"})


def test_quest_tracks_converge_on_their_quantiles_and_stop_by_their_rule():
    model = make_model("toj")
    rng = np.random.default_rng(3)
    for target, z in ((0.25, -0.6745), (0.75, 0.6745)):
        q = QuestTrack("q", model, target, 0.0, 60.0, 20.0, 2.0, 0.02, 400, stop_sd_ms=2.0, min_trials=20)
        while (x := q.next_offset()) is not None:
            q.update(x, bool(rng.random() < model.prob(x, pss=10.0, sigma=20.0, lapse=0.02)), None)
        s = q.summary()
        assert s["sd_ms"] < 2.0 and s["trials"] < 400  # stopped by the precision rule
        assert s["estimate_ms"] == pytest.approx(10.0 + z * 20.0, abs=3 * 2.0 + 1.0)
    afc = make_model("2afc")
    target = 0.5 + 0.25 * 0.98
    q = QuestTrack("q", afc, target, 40.0, 30.0, 0.0, 2.0, 0.02, 150)
    while (x := q.next_offset()) is not None:
        q.update(x, bool(rng.random() < afc.prob(x, threshold=15.0, slope=2.0, lapse=0.02)), None)
    assert q.summary()["trials"] == 150 and q.summary()["estimate_ms"] == pytest.approx(15.0, rel=0.25)


# --------------------------------------------------------------------------- resume
def _responses(rows):
    return [(r["trial"], r["track"], r["requested_ms"], r["measured_samples"], r["response"]) for r in rows]


def test_an_interrupted_session_resumes_where_it_stopped(tmp_path):
    d = design(offsets_ms=[-30.0, -10.0, 0.0, 10.0, 30.0], repetitions=6)
    full = tmp_path / "full.csv"
    run_study(d, full, "P1", responder=SimulatedObserver(d.observer, 3))
    path = tmp_path / "cut.csv"
    first = run_study(d, path, "P1", responder=SimulatedObserver(d.observer, 3), max_trials=11)
    assert not first.completed and first.new_trials == 11
    # a write cut short by a crash: a partial line without its newline
    with open(path, "a") as f:
        f.write("11,P1,,10.0,48")
    rows = read_rows(path)
    assert len(rows) == 11

    # Ctrl-C in the middle of the next session: everything answered so far is on disk
    count = {"n": 0}
    observer = SimulatedObserver(d.observer, 3)

    def answer(trial):
        count["n"] += 1
        if count["n"] == 6:
            raise KeyboardInterrupt
        return observer.respond(trial).answer

    with pytest.raises(KeyboardInterrupt):
        run_study(d, path, "P1", responder=CallableResponder(answer))
    rows = read_rows(path)
    assert len(rows) == 16 and path.read_bytes().endswith(b"\n")
    header = read_header(path)
    assert [s["resumed_from"] for s in header["sessions"]] == [0, 11]
    assert header["sessions"][1]["trials"] == 5 and not header["sessions"][1]["completed"]

    last = run_study(d, path, "P1", responder=SimulatedObserver(d.observer, 4))
    assert last.completed and last.resumed_from == 16 and last.new_trials == 14
    rows, ref = read_rows(path), read_rows(full)
    assert [int(r["trial"]) for r in rows] == list(range(30))
    assert [r["requested_ms"] for r in rows] == [r["requested_ms"] for r in ref]  # the same seeded list
    assert _responses(rows[:11]) == _responses(ref[:11])
    # a finished session stays finished
    assert run_study(d, path, "P1").new_trials == 0


def test_a_staircase_resumes_with_its_state(tmp_path):
    d = design(
        kind="staircase",
        rule="2down1up",
        tracks=["audio_first", "haptic_first"],
        start_ms=20.0,
        steps_ms=[4.0, 2.0, 1.0],
        min_ms=0.5,
        max_ms=60.0,
        reversals=6,
        max_trials=40,
    )

    def deterministic(trial):  # correct iff |offset| > 6.3 ms, then wrong every 5th trial
        right = abs(trial.offset_ms) > 6.3 and trial.index % 5 != 4
        first = "audio" if trial.offset_ms < 0 else "haptic"
        return first if right else ("haptic" if first == "audio" else "audio")

    full = run_study(d, tmp_path / "full.csv", "P1", responder=CallableResponder(deterministic))
    run_study(d, tmp_path / "cut.csv", "P1", responder=CallableResponder(deterministic), max_trials=9)
    resumed = run_study(d, tmp_path / "cut.csv", "P1", responder=CallableResponder(deterministic))
    assert full.completed and resumed.completed
    assert _responses(read_rows(tmp_path / "cut.csv")) == _responses(read_rows(tmp_path / "full.csv"))
    assert resumed.tracks == full.tracks
    for track in full.tracks.values():
        assert len(track["reversals"]) == 6 or track["trials"] == 40


def test_resume_refuses_another_design_or_participant(tmp_path):
    d = design()
    run_study(d, tmp_path / "r.csv", "P1", max_trials=3)
    with pytest.raises(ResultsError, match="another design"):
        run_study(design(seed=8), tmp_path / "r.csv", "P1")
    with pytest.raises(ResultsError, match="participant"):
        run_study(d, tmp_path / "r.csv", "P2")
    assert len(read_rows(tmp_path / "r.csv")) == 3


# --------------------------------------------------------------------------- staircase rules
def test_two_down_one_up_staircase_follows_the_rules():
    s = Staircase("haptic_first", 1.0, "2down1up", 10.0, [4.0, 2.0], 1.0, 12.0, 100, 100)
    seq = [True, True, True, True, False, True, True, False, False, True, True, True, True]
    mags = []
    for c in seq:
        s.update(s.next_offset(), c, c)
        mags.append(s.magnitude)
    # down 4 (10->6), down 4 (6->2), up: reversal at 2, step 2 (2->4), down (4->2): reversal at 4,
    # up (2->4): reversal at 2, up (4->6), down: reversal at 6 (6->4), down (4->2); clamp at min 1
    assert mags == [10, 6, 6, 2, 4, 4, 2, 4, 6, 6, 4, 4, 2]
    assert s.reversal_values == [2, 4, 2, 6]
    assert s.threshold() == pytest.approx(4.0)
    one = Staircase("audio_first", -1.0, "1down1up", 3.0, [2.0], 1.0, 5.0, 100, 100)
    for c in (True, True, False, False, False):
        one.update(one.next_offset(), c, c)
    assert one.next_offset() == -5.0  # 3 -> 1 -> 1 (min) -> 3 -> 5 -> 5 (max)


# --------------------------------------------------------------------------- design errors
@pytest.mark.parametrize(
    "over, match",
    [
        ({"task": "louder"}, "task"),
        ({"kind": "quest_plus"}, "offsets_ms"),
        ({"offsets_ms": []}, "offsets_ms"),
        ({"repetitions": 0}, "repetitions"),
        ({"kind": "bayes"}, "kind"),
        ({"sigma_ms": -1.0}, "sigma_ms"),
        ({"trial_duration": -1}, "trial_duration"),
        ({"kind": "staircase", "rule": "4down"}, "rule"),
        ({"kind": []}, "kind"),  # (values a dict cannot hold: a list or a table, not a crash)
        ({"task": ["toj"]}, "task"),
        ({"kind": "staircase", "rule": {"a": 1}}, "rule"),
        ({"kind": "staircase", "tracks": [["audio_first"]]}, "tracks"),
    ],
)
def test_bad_designs_are_rejected_with_the_key(over, match):
    with pytest.raises(DesignError, match=match):
        design(**over)


# --------------------------------------------------------------------------- CLI
def _cli(argv):
    from jassy.study.cli import add_command

    parser = argparse.ArgumentParser(prog="jassy")
    add_command(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(argv)
    return args.func(args)


def test_cli_run_and_analyze(tmp_path, capsys):
    out = tmp_path / "sim.csv"
    pilot = str(ROOT / "examples" / "pilot_study.toml")
    common = [
        "study",
        "run",
        pilot,
        "-p",
        "SIM",
        "--responses",
        "simulated",
        "--present",
        "none",
        "-o",
        str(out),
    ]
    assert _cli([*common, "--max-trials", "10"]) == 0
    assert "stopped" in capsys.readouterr().out
    assert _cli(common) == 0
    text = capsys.readouterr().out
    assert "resuming" in text and "40 in total; complete" in text
    pytest.importorskip("matplotlib")
    png = tmp_path / "fit.png"
    assert _cli(["study", "analyze", str(out), "--plot", str(png), "--export", str(tmp_path / "e")]) == 0
    text = capsys.readouterr().out
    assert "correct" in text and "not identifiable" in text and "[" not in text.split("correct")[0]
    fits = (tmp_path / "e_fits.csv").read_text().splitlines()
    assert fits[0].startswith("condition,who,trials,pss,pss_low") and ",SIM,40,,,,0," in fits[1]
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with pytest.raises(JassyError, match="no such design"):
        _cli(
            ["study", "run", str(tmp_path / "missing.toml"), "--responses", "simulated", "--present", "none"]
        )
    with pytest.raises(JassyError, match="no such results"):
        _cli(["study", "analyze", str(tmp_path / "missing.csv")])


# --------------------------------------------------------------------------- stimulus patch
def test_wall_tap_patch_is_a_force_pulse_and_a_bright_short_sound():
    from jassy.engines.offline import OfflineEngine
    from jassy.patchfile import load_patch

    patch = load_patch("wall_tap")
    r = OfflineEngine(patch.graph, patch.score, FS, 64).render(patch.duration)
    peak_db = 20 * np.log10(np.max(np.abs(r.audio)))
    assert -13.0 < peak_db < -3.0  # a loud click, not clipped (after the radiation stage: -10.4 dB)
    first = r.haptic[0, : int(0.5 * FS)]
    assert np.sum(first) / FS == pytest.approx(0.003, rel=1e-9)  # the impulse, N s
    assert np.max(first) == pytest.approx(2 * 0.003 / 0.0015, rel=1e-3)  # 1 - cos pulse peak, N
    seg = r.audio[0, TAP_FRAME : TAP_FRAME + 4096]
    spectrum = np.abs(np.fft.rfft(seg * np.hanning(seg.size)))
    freqs = np.fft.rfftfreq(seg.size, 1 / FS)
    assert 700 < freqs[np.argmax(spectrum)] < 1500  # lowest modes of the panel (780, 1430 Hz)
    energy = np.cumsum(r.audio[0, TAP_FRAME : TAP_FRAME + FS // 2] ** 2)
    assert np.searchsorted(energy, 0.99 * energy[-1]) < 0.1 * FS  # a short ring: 99 % within 100 ms


# --------------------------------------------------------------------------- live
# ``jack`` (tests/conftest.py): skipped only where jackd or PortAudio is missing; a server
# that is installed but does not come up or answer fails the test, saying why.


def test_live_presentation_measures_the_offset_the_device_received(jack, tmp_path):
    d = design(offsets_ms=[-2.0, 2.0], repetitions=1, pause=0.0)
    seen = []

    def answer(trial):
        seen.append(trial.offset_ms)
        return "audio" if trial.offset_ms < 0 else "haptic"

    result = run_study(d, tmp_path / "live.csv", "L1", responder=CallableResponder(answer), present="live")
    rows = read_rows(tmp_path / "live.csv")
    assert result.completed and len(rows) == 2
    clean = [row for row in rows if int(row["underruns"]) == 0]  # a dropout may move what was heard
    assert clean  # each trial had three chances of a clean presentation
    for row in clean:
        expected = -96 if float(row["requested_ms"]) < 0 else 96
        assert int(row["measured_samples"]) == int(row["requested_samples"]) == expected
    assert sorted(seen) == [-2.0, 2.0]
    header = read_header(tmp_path / "live.csv")
    assert header["sessions"][0]["presentation"]["mode"] == "live"
    assert header["sessions"][0]["device_stats"]["callbacks"] > 0
    assert 0 < header["sessions"][0]["presentation"]["latency_s"] < 0.05
    # the device latency measured for each trial, in the row and in the sidecar
    live = header["sessions"][0]["live_trials"]
    assert [t[0] for t in live] == [0, 1] and all(0 < t[1] < 0.05 for t in live)
    assert [float(r["latency_s"]) for r in rows] == pytest.approx([t[1] for t in live], abs=1e-6)


def test_a_live_presentation_with_an_underrun_is_played_again(monkeypatch):
    from jassy.study.runner import LivePresenter, Presented

    underruns = iter([2, 1, 0, 5, 4, 3])
    played = []

    def play(self, offset_ms, condition):
        played.append(offset_ms)
        return Presented(100, 4, 96, next(underruns), 0.004)

    monkeypatch.setattr(LivePresenter, "_play", play)
    d = design()
    presenter = LivePresenter(d, max_presentations=3)
    assert presenter.present(2.0, d.conditions[0]).underruns == 0  # the third, clean one is answered
    assert presenter.present(-2.0, d.conditions[0]).underruns == 3  # three dropouts: the last is logged
    assert played == [2.0] * 3 + [-2.0] * 3
    assert presenter.close()["repeated_presentations"] == 4
    with pytest.raises(JassyError, match="max_presentations"):
        LivePresenter(design(), max_presentations=0)


# --------------------------------------------------------------------------- keyboard
def test_keyboard_responses_single_keys_on_a_terminal_and_lines_otherwise(tmp_path):
    import threading
    import time

    from jassy.study import KeyboardResponder
    from jassy.study.observer import TrialInfo

    d = design(instructions="Press a or h.")
    out = io.StringIO()
    kb = KeyboardResponder(io.StringIO("go\nx\nh\n\na\nq\n"), out)
    kb.begin(d)
    answers = [kb.respond(TrialInfo(i, 3, 2.0, "toj")).answer for i in range(3)]
    assert answers == ["haptic", "audio", None]  # unknown keys are ignored, q quits
    assert "Press a or h." in out.getvalue() and "[1/3] Which came first?" in out.getvalue()

    master, slave = os.openpty()  # a real terminal: single keys, no Enter, keys typed early dropped
    stdin = open(slave, encoding="utf-8", closefd=True)  # noqa: SIM115
    kb = KeyboardResponder(stdin, io.StringIO())
    os.write(master, b"a")  # typed during the stimulus: flushed at the prompt

    def type_later():
        time.sleep(0.3)
        os.write(master, b"zH")

    threading.Thread(target=type_later).start()
    response = kb.respond(TrialInfo(0, None, 2.0, "toj"))
    assert response.answer == "haptic" and 0.25 < response.time < 5.0
    stdin.close()
    os.close(master)


# --------------------------------------------------------------------------- designs
def test_balanced_latin_square_orders_each_block_pair_equally_often():
    for k in range(2, 7):
        rows = balanced_latin_square(k)
        assert len(rows) == (k if k % 2 == 0 else 2 * k)
        for row in rows:
            assert sorted(row) == list(range(k))
        for pos in range(k):  # each block in each position equally often
            assert sorted(r[pos] for r in rows) == sorted(list(range(k)) * (len(rows) // k))
        pairs = {}
        for row in rows:
            for a, b in zip(row, row[1:], strict=False):
                pairs[(a, b)] = pairs.get((a, b), 0) + 1
        assert len(pairs) == k * (k - 1) and len(set(pairs.values())) == 1  # carry-over balanced


def _write(path, text):
    path.write_text(text)
    return path


BASE = """
[study]
name = "t"
stimulus = "wall_tap"
task = "toj"
trial_duration = 0.45
seed = 3
{study}
[method]
kind = "constant"
offsets_ms = [10.0, 60.0]
repetitions = 2
{rest}
"""


def test_conditions_file_factors_blocks_latin_square_practice_and_summary(tmp_path):
    _write(
        tmp_path / "conds.csv",
        "force_level,leading,wall.gain\n0.5,audio,1.0\n0.5,haptic,1.0\n2.0,audio,1.0\n2.0,haptic,1.0\n",
    )
    text = BASE.format(
        study='conditions = "conds.csv"\nbreaks_every = 3',
        rest="""
[factors]
material = ["steel", "wood"]
[materials.steel]
[materials.wood]
set = ["out.gain=60.0"]
[blocks]
by = "force_level"
order = "latin_square"
instructions = { "0.5" = "light", "2.0" = "hard" }
[practice]
trials = 3
offsets_ms = [-150.0, 150.0]
""",
    )
    d = load_design(_write(tmp_path / "d.toml", text))
    assert len(d.conditions) == 8 and d.factor_names == ["force_level", "leading", "material"]
    messages = []

    class Recorder(SimulatedObserver):
        def rest(self, message):
            messages.append(message)
            return True

        def feedback(self, message):
            messages.append(message)

    orders = {}
    for who in ("P1", "P2", "P3"):
        out = tmp_path / f"{who}.csv"
        result = run_study(d, out, who, Recorder(d.observer, 1))
        rows = read_rows(out)
        assert result.completed and len(rows) == 3 + 8 * 2 * 2
        assert [r["practice"] for r in rows[:3]] == ["1"] * 3 and {r["practice"] for r in rows[3:]} == {"0"}
        orders[who] = list(dict.fromkeys(r["block_name"] for r in rows[3:]))
        for r in rows[3:]:  # the leading modality sets the sign, the block the force level
            assert (float(r["requested_ms"]) < 0) == (r["leading"] == "audio")
            assert r["force_level"] == r["block_name"]
    assert orders == {"P1": ["0.5", "2.0"], "P2": ["2.0", "0.5"], "P3": ["0.5", "2.0"]}
    assert "Practice." in messages[0] and messages.count("Block 2.0. hard") == 3
    assert any(m.startswith("Break") for m in messages) and {"Correct.", "Wrong."} & set(messages)
    # wide summary: one row per condition, counts and proportions per offset, recounted here
    rows = [r for r in read_rows(tmp_path / "P1.csv") if r["practice"] == "0"]
    summary = list(csv.DictReader(io.StringIO((tmp_path / "P1_summary.csv").read_text())))
    assert len(summary) == 8
    for line in summary:
        mine = [r for r in rows if r["condition"] == line["condition"]]
        for x in (-60, -10, 10, 60):
            at = [r for r in mine if float(r["measured_ms"]) == x]
            assert int(line[f"n@{x}"]) == len(at)
            if at:
                assert float(line[f"p_haptic_first@{x}"]) == pytest.approx(
                    np.mean([r["positive"] == "1" for r in at]), abs=1e-4
                )


def test_force_level_scales_the_impulse_and_material_overrides_the_patch(tmp_path):
    text = BASE.format(
        study="",
        rest='[factors]\nforce_level = [1.0, 2.0]\nmaterial = ["a", "b"]\n[materials.a]\n[materials.b]\n'
        'set = ["out.gain=480.0"]\n',
    )
    d = load_design(_write(tmp_path / "d.toml", text))
    peaks = {}
    for c in d.conditions:
        r = render_trial(d, 0.0, c)
        peaks[(c.factors["force_level"], c.factors["material"])] = (
            np.abs(r.haptic).max(),
            np.abs(r.audio).max(),
        )
    # the haptic pulse peak is 2 impulse / duration: doubles with the force level (linear models)
    assert peaks[(2.0, "a")][0] == pytest.approx(2 * peaks[(1.0, "a")][0], rel=1e-9)
    assert peaks[(2.0, "a")][1] == pytest.approx(2 * peaks[(1.0, "a")][1], rel=1e-6)
    assert peaks[(1.0, "b")][1] == pytest.approx(2 * peaks[(1.0, "a")][1], rel=1e-6)  # gain 480 vs 240
    assert peaks[(1.0, "b")][0] == peaks[(1.0, "a")][0]


@pytest.mark.parametrize("task", ["2afc", "3afc"])
def test_forced_choice_sessions_recover_the_threshold(tmp_path, task):
    text = BASE.format(study="", rest="[observer]\nthreshold_ms = 20.0\nslope = 2.5\nlapse = 0.02\n")
    text = text.replace('task = "toj"', f'task = "{task}"').replace(
        "[10.0, 60.0]", "[4.0, 10.0, 20.0, 35.0, 60.0]"
    )
    text = text.replace("repetitions = 2", "repetitions = 30")
    d = load_design(_write(tmp_path / "d.toml", text))
    run_study(d, tmp_path / "a.csv", "A1")
    rows = read_rows(tmp_path / "a.csv")
    m = int(task[0])
    assert {r["interval"] for r in rows} == {str(i) for i in range(1, m + 1)}
    assert all((r["response"] == r["interval"]) == (r["correct"] == "1") for r in rows)
    est = analyze([tmp_path / "a.csv"])["conditions"]["all"]["participants"]["A1"]["threshold"]
    assert est["identifiable"] and est["ci95"][0] <= 20.0 <= est["ci95"][1]


@pytest.mark.parametrize(
    "method, trials",
    [
        ('kind = "quest"\nmax_trials = 12', 24),  # TOJ: two tracks (25 % and 75 %)
        (
            'kind = "quest_plus"\noffsets_ms = [-80.0, -40.0, -10.0, 0.0, 10.0, 40.0, 80.0]\n'
            "max_trials = 14\nchoose_from = 3",
            14,
        ),
    ],
)
def test_quest_and_quest_plus_sessions_resume_with_their_state(tmp_path, method, trials):
    text = BASE.format(study="", rest="").split("[method]")[0] + f"[method]\n{method}\n"
    d = load_design(_write(tmp_path / "d.toml", text))
    run_study(d, tmp_path / "full.csv", "P1", SimulatedObserver(d.observer, 5))
    run_study(d, tmp_path / "cut.csv", "P1", SimulatedObserver(d.observer, 5), max_trials=5)
    run_study(d, tmp_path / "cut.csv", "P1", SimulatedObserver(d.observer, 6))
    full, cut = read_rows(tmp_path / "full.csv"), read_rows(tmp_path / "cut.csv")
    assert len(cut) == len(full) == trials
    assert [r["requested_ms"] for r in cut[:6]] == [r["requested_ms"] for r in full[:6]]  # replayed state


def test_dated_file_names_resume_the_unfinished_session_and_ids_stay_in_the_folder(tmp_path, capsys):
    pilot = str(ROOT / "examples" / "pilot_study.toml")
    common = [
        "study",
        "run",
        pilot,
        "--responses",
        "simulated",
        "--present",
        "none",
        "--data-dir",
        str(tmp_path),
    ]
    assert _cli([*common, "-p", "S07", "--session", "2", "--max-trials", "5"]) == 0
    files = list(tmp_path.glob("S07_pilot-2ms_s2_*[0-9].csv"))
    assert len(files) == 1 and re.fullmatch(
        r"S07_pilot-2ms_s2_\d{4}-\d\d-\d\d_\d\dh\d\d\.\d\d\.\d{3}.csv", files[0].name
    )
    assert _cli([*common, "-p", "S07", "--session", "2"]) == 0  # resumes the same file
    assert "resuming" in capsys.readouterr().out and len(list(tmp_path.glob("S07_*_s2_*[0-9].csv"))) == 1
    assert read_header(files[0])["session"] == "2" and len(read_rows(files[0])) == 40
    for bad in ("../evil", "a/b", "..", "x y"):
        with pytest.raises(JassyError, match="participant"):
            _cli([*common, "-p", bad])
    assert sorted(p.name for p in tmp_path.iterdir() if p.suffix == ".csv")[0].startswith("S07")


def test_bad_design_files_exit_2_with_one_line_naming_file_and_key(tmp_path, capsys):
    from jassy.apps.cli import main

    cases = {
        "task": ('task = "toj"', 'task = "louder"'),
        "offsets_ms": ("offsets_ms = [10.0, 60.0]", "offsets_ms = []"),
        "blocks: by": ("repetitions = 2", 'repetitions = 2\n[blocks]\nby = "colour"'),
        "conditions": ("seed = 3", 'seed = 3\nconditions = "missing.csv"'),
    }
    for key, (old, new) in cases.items():
        path = _write(tmp_path / "bad.toml", BASE.format(study="", rest="").replace(old, new))
        code = main(["study", "run", str(path), "--responses", "simulated", "--present", "none"])
        lines = capsys.readouterr().err.strip().splitlines()
        assert code == 2 and len(lines) == 1, (key, lines)
        assert str(path) in lines[0] and key in lines[0], (key, lines[0])


@pytest.mark.parametrize("name", ["pilot", "toj", "sj", "force", "afc"])
def test_every_example_design_runs_and_is_analysed_from_the_cli(tmp_path, capsys, name):
    design_file = ROOT / "examples" / f"{name}_study.toml"
    d = load_design(design_file)
    common = ["--responses", "simulated", "--present", "none", "--data-dir", str(tmp_path), "-q"]
    for who in ("SIM01", "SIM02"):
        assert _cli(["study", "run", str(design_file), "-p", who, "--max-trials", "30", *common]) == 0
    results = sorted(str(p) for p in tmp_path.glob("SIM0*[0-9].csv"))
    assert len(results) == 2
    assert _cli(["study", "analyze", *results, "--export", str(tmp_path / "fit")]) == 0
    text = capsys.readouterr().out
    assert f"task {d.task}" in text
    fits = list(csv.DictReader(io.StringIO((tmp_path / "fit_fits.csv").read_text())))
    assert {row["who"] for row in fits} >= {"SIM01", "SIM02"}  # force: each in its first block
