"""``jassy study run``, ``jassy study analyze`` and ``jassy study coverage``: wired into
jassy/apps/cli.py by ``add_command(subparsers)``. Each subcommand is ``func(args) -> int``; bad
input raises a JassyError (one line on stderr, exit code 2)."""

from __future__ import annotations

import argparse
import contextlib
import json
import sys
from pathlib import Path

from jassy.errors import JassyError


def _ask(label: str, value: str | None, default: str, human: bool) -> str:
    """A session field from its option, else prompted (people at a terminal), else the default."""
    if value is not None:
        return value
    if human and sys.stdin.isatty():
        answer = input(f"{label} [{default}]: ").strip()
        return answer or default
    return default


def _rehearse(design) -> None:
    """Before any file is written: render every condition's stimulus at the largest offsets
    the design can ask for (both signs), so a stimulus that does not fit the trial is an
    input error now, not after the first trials were logged."""
    from jassy.study.runner import OfflinePresenter

    offsets = [0.0]
    for table in (design.method, design.practice or {}):
        for key, value in table.items():
            if key.endswith("_ms"):
                values = value if isinstance(value, (list, tuple)) else [value]
                offsets += [
                    abs(float(v)) for v in values if isinstance(v, (int, float)) and not isinstance(v, bool)
                ]
    largest = max(offsets)
    presenter = OfflinePresenter(design)
    for condition in design.conditions:
        for offset in {largest, -largest}:
            presenter.present(offset, condition)


@contextlib.contextmanager
def _no_files_without_trials(output: Path):
    """If a new session fails before its first trial is logged (a device that does not open,
    a stimulus that does not fit the trial), remove the files it created: no empty logs."""
    from jassy.study.runner import read_rows, sidecar_path, summary_path

    files = [output, sidecar_path(output), summary_path(output)]
    created = [p for p in files if not p.exists()]
    try:
        yield
    except BaseException:
        with contextlib.suppress(JassyError, OSError):
            if output in created and (not output.exists() or not read_rows(output)):
                for path in created:
                    path.unlink(missing_ok=True)
        raise


def _cmd_run(args: argparse.Namespace) -> int:
    from jassy.study.design import check_participant, load_design, parse_observer
    from jassy.study.observer import KeyboardResponder, SimulatedObserver, WindowResponder
    from jassy.study.runner import find_unfinished, read_rows, results_name, run_study

    design = load_design(args.design)
    human = args.responses != "simulated"
    participant = check_participant(_ask("participant", args.participant, "P01", human), "--participant")
    session = check_participant(_ask("session", args.session, "1", human), "--session")
    if args.participant_number is not None and args.participant_number < 1:
        raise JassyError(f"--participant-number: expected an integer >= 1, got {args.participant_number}")
    if args.output:
        output = Path(args.output)
    else:
        found = None if args.restart else find_unfinished(design, participant, session, args.data_dir)
        output = found or results_name(design, participant, session, args.data_dir)
    if args.restart and output.exists():
        raise JassyError(f"{output}: exists; --restart refuses to overwrite results, choose another -o")
    if args.responses == "simulated":
        spec = design.observer
        overrides = {
            k: v
            for k, v in (("pss_ms", args.pss), ("sigma_ms", args.sigma), ("lapse", args.lapse))
            if v is not None
        }
        if overrides:
            when = spec.when
            spec = parse_observer(
                {**{k: v for k, v in spec.__dict__.items() if k != "when"}, **overrides},
                "--pss/--sigma/--lapse",
            )
            spec.when = when
        seed = (
            args.observer_seed
            if args.observer_seed is not None
            else design.participant_seed(participant, session).spawn(1)[0]
        )
        responder = SimulatedObserver(spec, seed, design.function)
    elif args.responses == "keyboard":
        responder = KeyboardResponder()
    else:
        responder = WindowResponder()
    before = len(read_rows(output)) if output.exists() else 0
    if before and not args.quiet:
        print(f"resuming {output}: {before} trials already done")
    _rehearse(design)
    with _no_files_without_trials(output):
        result = run_study(
            design,
            output,
            participant,
            responder,
            args.present,
            args.device,
            args.max_trials,
            session=session,
            participant_number=args.participant_number,
        )
    if not args.quiet:
        state = "complete" if result.completed else "stopped (run the same command to resume)"
        print(f"{output}: {result.new_trials} trials run now, {result.total_trials} in total; {state}")
        for name, track in result.tracks.items():
            if track["method"] == "staircase":
                thr = track["threshold_ms"]
                print(
                    f"  staircase {name}: {track['trials']} trials, {len(track['reversals'])} reversals, "
                    f"threshold {'-' if thr is None else f'{thr:.2f} ms'}"
                )
            elif track["method"] == "quest":
                est, sd = track["estimate_ms"], track["sd_ms"]
                print(f"  QUEST {name}: {track['trials']} trials, {est:.2f} +- {sd:.2f} ms")
            elif track["method"] == "quest_plus":
                est = ", ".join(f"{k} {v:.3g}" for k, v in track["posterior_mean"].items())
                print(f"  QUEST+ {name}: {track['trials']} trials, posterior mean {est}")
    return 0


def _cmd_analyze(args: argparse.Namespace) -> int:
    from jassy.study.analysis import analyze, export_fits, format_report, plot_report

    if args.plot:
        from jassy.apps.cli_checks import require_extra
        from jassy.files import check_output

        require_extra("matplotlib", "plot", "--plot")
        check_output(args.plot, "--plot")
    report = analyze(args.results, args.function, args.use)
    if args.plot:
        plot_report(report, args.plot)
    exported = export_fits(report, args.export) if args.export else ()
    data = report.pop("_data")
    if args.json:
        print(json.dumps(report, indent=2))
    else:
        print(format_report(report))
        print(
            f"{data.x.size} trials from {len(data.sources)} file(s)"
            + (f"; plot -> {args.plot}" if args.plot else "")
            + (f"; fits -> {', '.join(map(str, exported))}" if exported else "")
        )
    return 0


def _cmd_coverage(args: argparse.Namespace) -> int:
    from jassy.study.validation import run_coverage

    if args.participants < 2:
        raise JassyError(f"--participants: expected an integer >= 2, got {args.participants}")
    print(run_coverage(args.participants, args.seed, args.quest_trials, args.plot))
    return 0


def add_command(subparsers) -> argparse.ArgumentParser:
    """Add ``study`` (with ``run``, ``analyze`` and ``coverage``) to the jassy command's subparsers."""
    study = subparsers.add_parser("study", help="audio-haptic asynchrony user studies: run and analyze")
    sub = study.add_subparsers(dest="study_command", required=True, metavar="SUBCOMMAND")

    p = sub.add_parser("run", help="run (or resume) a study session from a design file")
    p.add_argument("design", help="study design (.toml), e.g. examples/toj_study.toml")
    p.add_argument(
        "-o",
        "--output",
        help="results CSV (default DATA_DIR/PARTICIPANT_STUDY_sSESSION_DATE.csv, or the unfinished one "
        "of this participant and session); header in .json, wide summary in _summary.csv beside it",
    )
    p.add_argument("--data-dir", default="data", help="folder of dated results files (default data)")
    p.add_argument("-p", "--participant", help="participant id (prompted at a terminal; default P01)")
    p.add_argument("--session", help="session id (prompted at a terminal; default 1)")
    p.add_argument(
        "--participant-number",
        type=int,
        help="row of the Latin square of block orders (default: the digits ending the participant id)",
    )
    p.add_argument(
        "--responses",
        default="keyboard",
        choices=["keyboard", "window", "simulated"],
        help="keyboard: single keys in the terminal; window: a tkinter dialog; "
        "simulated: the design's [observer] (rehearsal, tests)",
    )
    p.add_argument(
        "--present",
        default="live",
        choices=["live", "none"],
        help="live: play each trial on the device; none: render only (simulated observers)",
    )
    p.add_argument("--device", help="output device index or name substring (see 'jassy devices')")
    p.add_argument("--max-trials", type=int, help="stop after this many trials (resume later)")
    p.add_argument("--pss", type=float, help="simulated observer: PSS, ms")
    p.add_argument("--sigma", type=float, help="simulated observer: spread, ms")
    p.add_argument("--lapse", type=float, help="simulated observer: lapse rate")
    p.add_argument("--observer-seed", type=int, help="simulated observer: RNG seed")
    p.add_argument("--restart", action="store_true", help="refuse to resume: fail if the results file exists")
    p.add_argument("-q", "--quiet", action="store_true")
    p.set_defaults(func=_cmd_run)

    p = sub.add_parser("analyze", help="fit psychometric functions per condition: PSS, JND/window, intervals")
    p.add_argument("results", nargs="+", help="results CSV file(s); several participants are pooled")
    p.add_argument(
        "--function",
        choices=["gaussian", "logistic", "difference", "weibull"],
        help="model (default: the design's)",
    )
    p.add_argument("--use", default="measured", choices=["measured", "requested"], help="offsets to fit")
    p.add_argument("--plot", metavar="OUT.png", help="plot data and fits, one panel per condition")
    p.add_argument("--export", metavar="PREFIX", help="write PREFIX_fits.csv and PREFIX_fits.json")
    p.add_argument("--json", action="store_true", help="print the report as JSON")
    p.set_defaults(func=_cmd_analyze)

    p = sub.add_parser(
        "coverage", help="coverage of the 95%% intervals and QUEST+ vs constant stimuli (simulated)"
    )
    p.add_argument("--participants", type=int, default=50, help="simulated participants per row (default 50)")
    p.add_argument("--seed", type=int, default=1, help="seed (default 1)")
    p.add_argument(
        "--quest-trials", type=int, default=200, help="QUEST+ trials per participant (default 200)"
    )
    p.add_argument("--plot", metavar="OUT.png", help="plot interval width against trials")
    p.set_defaults(func=_cmd_coverage)
    return study
