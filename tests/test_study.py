"""User-study scripts: exact offsets, simulated observers, resume, fits, CLI, live.

Independent checks: onsets against the impact's first frame computed from its time,
offsets against round(ms * fs / 1000), fits against scipy minimisation from many starts
and against the generating parameters, the JND against a root of the fitted function,
staircases against hand-computed sequences.
"""

from __future__ import annotations

import argparse
import math
import os
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import brentq, minimize
from scipy.special import ndtri

from jassy.errors import JassyError
from jassy.study import (
    CallableResponder,
    SimulatedObserver,
    fit_psychometric,
    measure_offset,
    p_positive,
    parse_design,
    read_rows,
    render_trial,
    run_study,
)
from jassy.study.analysis import _bounds, _fit_batch, _nll, analyze
from jassy.study.design import DesignError, ObserverSpec, Staircase, load_design
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
        "question": "which_first",
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
    assert d.question == "which_first" and d.method["offsets_ms"] == [-2.0, 2.0]
    result = run_study(d, tmp_path / "pilot.csv", "SIM")
    rows = read_rows(tmp_path / "pilot.csv")
    assert result.completed and len(rows) == 2 * d.method["repetitions"]
    assert {int(r["measured_samples"]) for r in rows} == {-96, 96}


# --------------------------------------------------------------------------- observer & fits
def test_batched_fit_finds_the_scipy_minimum():
    rng = np.random.default_rng(11)
    x = np.repeat([-60.0, -30, -15, -5, 5, 15, 30, 60], 30)
    levels = np.unique(x)
    n = np.full(levels.size, 30.0)
    for question in ("which_first", "simultaneous"):
        for _ in range(4):
            mu, sigma, lapse = rng.uniform(-15, 15), rng.uniform(5, 40), rng.uniform(0, 0.08)
            k = rng.binomial(30, p_positive(levels, mu, sigma, lapse, question)).astype(float)
            bounds = _bounds(x)
            theta, value = _fit_batch(levels, k[None], n[None], question, "gaussian", bounds)
            best = min(
                (
                    minimize(
                        _nll,
                        (m0, math.log(s0), 0.03),
                        args=(levels, k, n, question, "gaussian"),
                        method="Nelder-Mead",
                        bounds=bounds,
                        options={"xatol": 1e-8, "fatol": 1e-10, "maxiter": 4000},
                    )
                    for m0 in (-20, 0, 20)
                    for s0 in (5, 20, 50)
                ),
                key=lambda r: r.fun,
            )
            assert value[0] <= best.fun + 1e-6


def test_jnd_is_the_distance_from_the_50_to_the_75_percent_point():
    x = np.repeat(np.linspace(-50, 50, 11), 40)
    rng = np.random.default_rng(5)
    for function in ("gaussian", "logistic"):
        y = (rng.random(x.size) < p_positive(x, 3.0, 12.0, 0.0, "which_first", function)).astype(float)
        f = fit_psychometric(x, y, function=function, bootstrap=0)
        core = lambda v, f=f, fn=function: p_positive(v, f.pss, f.sigma, 0.0, "which_first", fn)  # noqa: E731
        x75 = brentq(lambda v, core=core: core(v) - 0.75, f.pss, f.pss + 10 * f.sigma)
        assert f.jnd == pytest.approx(x75 - f.pss, rel=1e-9)
    assert float(ndtri(0.75)) == pytest.approx(0.6744897501960817)


def test_simulated_observer_answers_follow_its_psychometric_function():
    obs = SimulatedObserver(ObserverSpec(pss_ms=5.0, sigma_ms=10.0, lapse=0.1), seed=1)
    from jassy.study.observer import TrialInfo

    for offset in (-20.0, 5.0, 25.0):
        answers = [obs.respond(TrialInfo(0, None, offset, "which_first")).answer for _ in range(4000)]
        p = np.mean([a == "haptic" for a in answers])
        expected = 0.05 + 0.9 * 0.5 * math.erfc(-(offset - 5.0) / 10.0 / math.sqrt(2))
        assert p == pytest.approx(expected, abs=4 * math.sqrt(expected * (1 - expected) / 4000) + 1e-3)


def test_a_simulated_observer_is_recovered_within_the_95_percent_intervals(tmp_path):
    true_pss, true_sigma, lapse = 6.0, 18.0, 0.03
    true_jnd = true_sigma * float(ndtri(0.75))
    offsets = [-60.0, -35.0, -20.0, -8.0, 4.0, 16.0, 30.0, 55.0]
    # the full pipeline (render, present none, log, analyze) for two participants, 400 trials each
    d = design(
        offsets_ms=offsets,
        repetitions=50,
        pss_ms=true_pss,
        sigma_ms=true_sigma,
        lapse=lapse,
        trial_duration=0.3,
    )
    paths = []
    for who in ("S1", "S2"):
        result = run_study(d, tmp_path / f"{who}.csv", who)
        assert result.completed and result.total_trials == 400
        paths.append(tmp_path / f"{who}.csv")
    report = analyze(paths, bootstrap=300, seed=1)
    assert set(report["participants"]) == {"S1", "S2"}
    pooled = report["pooled"]
    assert pooled["n"] == 800
    assert pooled["pss_ci"][0] <= true_pss <= pooled["pss_ci"][1]
    assert pooled["jnd_ci"][0] <= true_jnd <= pooled["jnd_ci"][1]
    # coverage over many seeds: the observer plus the fit alone (the rendering is exact)
    x = np.repeat(offsets, 50)
    covered_pss = covered_jnd = 0
    seeds = range(20)
    for seed in seeds:
        obs = SimulatedObserver(ObserverSpec(true_pss, true_sigma, lapse), seed=100 + seed)
        from jassy.study.observer import TrialInfo

        y = np.array([obs.respond(TrialInfo(0, None, v, "which_first")).answer == "haptic" for v in x], float)
        f = fit_psychometric(x, y, bootstrap=300, seed=seed)
        covered_pss += f.pss_ci[0] <= true_pss <= f.pss_ci[1]
        covered_jnd += f.jnd_ci[0] <= true_jnd <= f.jnd_ci[1]
        assert abs(f.pss - true_pss) < 8 and abs(f.jnd - true_jnd) < 8
    assert covered_pss >= 16 and covered_jnd >= 16, (covered_pss, covered_jnd)


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
    assert resumed.staircases == full.staircases
    for track in full.staircases.values():
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
        s.update(c)
        mags.append(s.magnitude)
    # down 4 (10->6), down 4 (6->2), up: reversal at 2, step 2 (2->4), down (4->2): reversal at 4,
    # up (2->4): reversal at 2, up (4->6), down: reversal at 6 (6->4), down (4->2); clamp at min 1
    assert mags == [10, 6, 6, 2, 4, 4, 2, 4, 6, 6, 4, 4, 2]
    assert s.reversal_values == [2, 4, 2, 6]
    assert s.threshold() == pytest.approx(4.0)
    one = Staircase("audio_first", -1.0, "1down1up", 3.0, [2.0], 1.0, 5.0, 100, 100)
    for c in (True, True, False, False, False):
        one.update(c)
    assert one.offset_ms == -5.0  # 3 -> 1 -> 1 (min) -> 3 -> 5 -> 5 (max)


# --------------------------------------------------------------------------- design errors
@pytest.mark.parametrize(
    "over, match",
    [
        ({"question": "louder"}, "question"),
        ({"offsets_ms": []}, "offsets_ms"),
        ({"repetitions": 0}, "repetitions"),
        ({"kind": "quest"}, "kind"),
        ({"sigma_ms": -1.0}, "sigma_ms"),
        ({"trial_duration": -1}, "trial_duration"),
        ({"kind": "staircase", "rule": "4down"}, "rule"),
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
    assert _cli(["study", "analyze", str(out), "--bootstrap", "100", "--plot", str(png)]) == 0
    text = capsys.readouterr().out
    assert "correct" in text and "not identifiable" in text
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with pytest.raises(JassyError, match="no such design"):
        _cli(
            ["study", "run", str(tmp_path / "missing.toml"), "--responses", "simulated", "--present", "none"]
        )
    with pytest.raises(JassyError, match="no such results"):
        _cli(["study", "analyze", str(tmp_path / "missing.csv")])


# --------------------------------------------------------------------------- stimulus patch
def test_wall_tap_patch_is_a_force_pulse_and_a_bright_short_sound():
    from jassy.offline import OfflineEngine
    from jassy.patchfile import load_patch

    patch = load_patch("wall_tap")
    r = OfflineEngine(patch.graph, patch.score, FS, 64).render(patch.duration)
    peak_db = 20 * np.log10(np.max(np.abs(r.audio)))
    assert -7.5 < peak_db < -5.0
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
@pytest.fixture(scope="module")
def jack():
    import ctypes.util

    from jassy.jackserver import dummy_jack
    from jassy.portaudio import LiveError

    if ctypes.util.find_library("portaudio") is None:
        pytest.skip("libportaudio2 is not installed (apt-get install libportaudio2)")
    try:
        with dummy_jack(f"jassy-study-{os.getpid()}", FS, 64, channels=4) as name:
            yield name
    except LiveError as exc:
        pytest.skip(f"no JACK dummy server: {exc}")


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


def test_a_live_presentation_with_an_underrun_is_played_again(monkeypatch):
    from jassy.study.runner import LivePresenter, Presented

    underruns = iter([2, 1, 0, 5, 4, 3])
    played = []

    def play(self, offset_ms):
        played.append(offset_ms)
        return Presented(100, 4, 96, next(underruns))

    monkeypatch.setattr(LivePresenter, "_play", play)
    presenter = LivePresenter(design(), max_presentations=3)
    assert presenter.present(2.0).underruns == 0  # the third, clean presentation is answered
    assert presenter.present(-2.0).underruns == 3  # three dropouts: the last one is logged
    assert played == [2.0] * 3 + [-2.0] * 3
    assert presenter.close()["repeated_presentations"] == 4
    with pytest.raises(JassyError, match="max_presentations"):
        LivePresenter(design(), max_presentations=0)


# --------------------------------------------------------------------------- keyboard
def test_keyboard_responses_single_keys_on_a_terminal_and_lines_otherwise(tmp_path):
    import io
    import threading
    import time

    from jassy.study import KeyboardResponder
    from jassy.study.observer import TrialInfo

    d = design(instructions="Press a or h.")
    out = io.StringIO()
    kb = KeyboardResponder(io.StringIO("go\nx\nh\n\na\nq\n"), out)
    kb.begin(d)
    answers = [kb.respond(TrialInfo(i, 3, 2.0, "which_first")).answer for i in range(3)]
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
    response = kb.respond(TrialInfo(0, None, 2.0, "which_first"))
    assert response.answer == "haptic" and 0.25 < response.time < 5.0
    stdin.close()
    os.close(master)
