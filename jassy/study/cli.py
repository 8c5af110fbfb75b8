"""``jassy study run`` and ``jassy study analyze``: wired into jassy/cli.py by
``add_command(subparsers)``. Each subcommand is ``func(args) -> int``; bad input raises a
JassyError (one line on stderr, exit code 2)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from jassy.errors import JassyError


def _cmd_run(args: argparse.Namespace) -> int:
    from jassy.files import check_output
    from jassy.study.design import load_design, parse_observer
    from jassy.study.observer import KeyboardResponder, SimulatedObserver, WindowResponder
    from jassy.study.runner import check_participant, read_rows, run_study

    check_participant(args.participant)  # it becomes part of the file name
    design = load_design(args.design)
    output = Path(args.output or f"{Path(args.design).stem}_{args.participant}.csv")
    check_output(output, "-o/--output", (".csv",))
    if args.restart and output.exists():
        raise JassyError(f"{output}: exists; --restart refuses to overwrite results, choose another -o")
    if args.responses == "simulated":
        spec = design.observer
        overrides = {
            k: v
            for k, v in (("pss_ms", args.pss), ("sigma_ms", args.sigma), ("lapse", args.lapse))
            if v is not None
        }
        spec = parse_observer({**spec.__dict__, **overrides}, "--pss/--sigma/--lapse")
        seed = (
            args.observer_seed
            if args.observer_seed is not None
            else design.participant_seed(args.participant).spawn(1)[0]
        )
        responder = SimulatedObserver(spec, seed)
    elif args.responses == "keyboard":
        responder = KeyboardResponder()
    else:
        responder = WindowResponder()
    before = len(read_rows(output)) if output.exists() else 0
    if before and not args.quiet:
        print(f"resuming {output}: {before} trials already done")
    result = run_study(
        design, output, args.participant, responder, args.present, args.device, args.max_trials
    )
    if not args.quiet:
        state = "complete" if result.completed else "stopped (run the same command to resume)"
        print(f"{output}: {result.new_trials} trials run now, {result.total_trials} in total; {state}")
        for name, track in result.staircases.items():
            thr = track["threshold_ms"]
            print(
                f"  staircase {name}: {track['trials']} trials, {len(track['reversals'])} reversals, "
                f"threshold {'-' if thr is None else f'{thr:.2f} ms'}"
            )
    return 0


def _cmd_analyze(args: argparse.Namespace) -> int:
    from jassy.study.analysis import analyze, format_report, plot_report

    if not 0 <= args.bootstrap <= 100_000:
        raise JassyError(f"--bootstrap: expected an integer in [0, 100000], got {args.bootstrap}")
    if args.plot:
        from jassy.cli_checks import require_extra
        from jassy.files import check_output

        require_extra("matplotlib", "plot", "--plot")
        check_output(args.plot, "--plot")
    report = analyze(args.results, args.function, args.bootstrap, args.seed, args.bootstrap_method, args.use)
    if args.plot:
        plot_report(report, args.plot)
    data = report.pop("_data")
    if args.json:
        print(json.dumps(report, indent=2))
    else:
        print(format_report(report))
        print(
            f"{data.x.size} trials from {len(data.sources)} file(s)"
            + (f"; plot -> {args.plot}" if args.plot else "")
        )
    return 0


def add_command(subparsers) -> argparse.ArgumentParser:
    """Add ``study`` (with ``run`` and ``analyze``) to the jassy command's subparsers."""
    study = subparsers.add_parser("study", help="audio-haptic asynchrony user studies: run and analyze")
    sub = study.add_subparsers(dest="study_command", required=True, metavar="SUBCOMMAND")

    p = sub.add_parser("run", help="run (or resume) a study session from a design file")
    p.add_argument("design", help="study design (.toml), e.g. examples/pilot_study.toml")
    p.add_argument(
        "-o", "--output", help="results CSV (default DESIGN_PARTICIPANT.csv); header in .json beside it"
    )
    p.add_argument("-p", "--participant", default="P01", help="participant id (default P01)")
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

    p = sub.add_parser("analyze", help="fit psychometric functions: PSS, JND, bootstrap CIs, plot")
    p.add_argument("results", nargs="+", help="results CSV file(s); several participants are pooled")
    p.add_argument("--function", default="gaussian", choices=["gaussian", "logistic"])
    p.add_argument("--bootstrap", type=int, default=1000, help="bootstrap samples (default 1000; 0 = none)")
    p.add_argument("--bootstrap-method", default="parametric", choices=["parametric", "nonparametric"])
    p.add_argument("--seed", type=int, default=0, help="bootstrap seed (default 0)")
    p.add_argument("--use", default="measured", choices=["measured", "requested"], help="offsets to fit")
    p.add_argument("--plot", metavar="OUT.png", help="plot data and fits to a PNG")
    p.add_argument("--json", action="store_true", help="print the report as JSON")
    p.set_defaults(func=_cmd_analyze)
    return study
