"""The ``jassy`` command line: render, list, info, bench.

Exit codes: 0 success, 2 bad input (one line on stderr, no output file created or
overwritten), 130 interrupted (Ctrl-C), 143 terminated (SIGTERM), 129 hung up (SIGHUP).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time

from jassy.apps.cli_checks import (
    LineParser,
    check_arguments,
    check_render_arguments,
    scene_options,
    signals_stop,
)
from jassy.engines.offline import OFFLINE_BLOCK
from jassy.errors import JassyError, suggest
from patches.scenes import SCENES

DEFAULT_RATE = 48000


def _render_scene(args: argparse.Namespace) -> int:
    import importlib

    module_name, function = SCENES[args.patch]
    module = importlib.import_module(module_name)
    render = getattr(module, function)
    options = scene_options(args.patch, args.set or (), render, getattr(module, "run_experiment", None))
    kwargs = {"duration": args.duration} if args.duration is not None else {}
    summary = render(
        args.output,
        args.haptic,
        args.csv,
        sample_rate=args.sr or DEFAULT_RATE,
        block=args.block,
        **kwargs,
        **options,
    )
    for warning in summary.get("warnings", ()) if isinstance(summary, dict) else ():
        print(f"jassy: warning: {warning}", file=sys.stderr)
    if not args.quiet:
        written = ", ".join(p for p in (args.output, args.haptic, args.csv) if p)
        print(f"wrote {written}")
        print(_summary_lines(summary))
    return 0


def _summary_lines(summary, indent: str = "  ") -> str:
    """A scene's summary dict as aligned ``name: value`` lines (numbers to 4 digits)."""
    if not isinstance(summary, dict):
        return f"{indent}{summary}"
    lines = []
    for key, value in summary.items():
        if key == "warnings":
            continue
        if isinstance(value, dict):
            lines.append(f"{indent}{key.replace('_', ' ')}:")
            lines.append(_summary_lines(value, indent + "  "))
            continue
        if isinstance(value, float):
            value = f"{value:.4g}"
        elif isinstance(value, (list, tuple)):
            value = ", ".join(f"{v:.4g}" if isinstance(v, float) else str(v) for v in value) or "-"
        lines.append(f"{indent}{key.replace('_', ' ')}: {value}")
    return "\n".join(lines)


def _cmd_render(args: argparse.Namespace) -> int:
    from jassy.engines.offline import OfflineEngine
    from jassy.patchfile import load_patch

    check_render_arguments(args)  # bad values and output names fail before any work
    if not args.quiet:
        from jassy.apps.startup import first_run_notice

        first_run_notice(lambda line: print(line, file=sys.stderr, flush=True))
    if args.normalise and args.patch in SCENES:
        raise JassyError(f"--normalise: physics scenes ({', '.join(SCENES)}) are not normalised; use a gain")
    if args.target is not None and not args.normalise:
        raise JassyError("--target: needs --normalise peak|lufs")
    if args.target is not None and not (math.isfinite(args.target) and -70.0 <= args.target <= 0.0):
        raise JassyError(f"--target: expected dB between -70 and 0, got {args.target}")
    if args.plot:
        from jassy.apps.preview import check_png, require_matplotlib

        require_matplotlib("--plot")
        check_png(args.plot, "--plot")
    if args.patch in SCENES:
        status = _render_scene(args)
        _plot_render(args)
        return status
    if args.csv:
        raise JassyError(f"--csv: only physics scenes ({', '.join(SCENES)}) write a CSV")
    patch = load_patch(args.patch, args.set or (), args.event or ())
    rate = args.sr or patch.sample_rate or DEFAULT_RATE
    duration = args.duration if args.duration is not None else patch.duration
    if duration is None:
        raise JassyError("--duration: the patch sets no duration; give one in seconds")
    if args.haptic and not patch.graph.haptic:
        raise JassyError(f"--haptic: patch {patch.name!r} has no haptic output ([outputs] haptic = ...)")
    from jassy.apps.cli_checks import check_render_size

    check_render_size(args, patch.graph, duration, rate)
    if args.mode_budget is not None:
        from jassy.anytime import ModeBudget

        patch.graph.budget = ModeBudget(max_modes=args.mode_budget)
    t0 = time.perf_counter()
    safety, offsets = _haptic_options(args)
    from jassy.engines.coldstart import program_cached

    engine = OfflineEngine(
        patch.graph, patch.score, rate, args.block, limiter=not args.normalise, haptic_safety=safety,
        offsets_ms=offsets, program=program_cached(patch.graph),  # node by node until compiled: the same bits
    )  # fmt: skip
    if args.normalise:
        from jassy.apps.loudness import TARGETS, render_normalised

        target = TARGETS[args.normalise] if args.target is None else args.target
        summary = render_normalised(
            engine, args.output, duration, args.format, args.haptic, args.normalise, target, not args.quiet
        )
    else:
        summary = engine.render_to_file(
            args.output, duration, args.format, args.haptic, progress=not args.quiet
        )
    elapsed = time.perf_counter() - t0
    for warning in summary["warnings"]:
        print(f"jassy: warning: {warning}", file=sys.stderr)
    if not args.quiet:
        from jassy.levels import spl_summary

        peak_db = 20 * math.log10(summary["peak"]) if summary["peak"] > 0 else float("-inf")
        print(
            f"wrote {args.output}: {summary['duration']:.3f} s at {rate:g} Hz, "
            f"{len(patch.graph.audio)} ch, peak {peak_db:.1f} dBFS"
            + ("" if args.normalise else spl_summary(patch.graph.audio, peak_db))
            + f", rendered in {elapsed:.2f} s"
            + (f"; haptic -> {args.haptic}" if args.haptic else "")
            + (
                f"; normalised by {summary['gain_db']:+.1f} dB to {summary['level']:.1f} "
                + ("LUFS" if args.normalise == "lufs" else "dBFS peak")
                if args.normalise
                else ""
            )
        )
    _plot_render(args)
    return 0


def _plot_render(args: argparse.Namespace) -> None:
    """``--plot``: a preview PNG of the file just written."""
    if args.plot:
        from jassy.apps.preview import plot_file

        plot_file(args.output, args.plot)
        if not args.quiet:
            print(f"wrote {args.plot}")


def _haptic_options(args: argparse.Namespace):
    from jassy.haptics import HapticSafety

    safety = HapticSafety(max_force=args.max_force, max_slew=args.max_slew)
    offsets = {"audio": args.audio_offset, "haptic": args.haptic_offset}
    return safety, offsets


def _cmd_play(args: argparse.Namespace) -> int:
    from jassy.engines.live import LiveEngine
    from jassy.patchfile import load_patch

    patch = load_patch(args.patch, args.set or ())
    rate = args.sr or patch.sample_rate or DEFAULT_RATE
    if args.duration is not None and not args.duration >= 0:
        raise JassyError(f"--duration: expected seconds >= 0 (0 = until stopped), got {args.duration}")
    duration = args.duration or None  # none or 0: until stopped
    safety, offsets = _haptic_options(args)
    engine = LiveEngine(
        patch.graph,
        patch.score,
        rate,
        args.block,
        args.ring,
        args.device,
        haptic_to_card=not args.no_haptic_card,
        haptic_udp=args.haptic_udp,
        haptic_safety=safety,
        offsets_ms=offsets,
        mode=args.mode,
    )
    why = f" ({engine.mode_reason})" if engine.mode_reason else ""
    print(f"mode: {engine.mode}{why}", flush=True)
    osc = None
    if args.osc:
        from jassy.engines.osc import OscControl, parse_address

        host, port = parse_address(args.osc)
        osc = OscControl(patch.graph, engine.post, origin=0.0, host=host, port=port)
    engine.start()
    if osc is not None:
        osc.origin = time.time()  # the stream's frame 0, as near as the wall clock tells
        osc.start()
        print(f"OSC on {host}:{osc.address[1]}: /NODE/PARAM, /NODE/ACTION, /event", flush=True)
    try:
        print(
            f"playing {patch.name} at {rate:g} Hz, block {args.block}: latency "
            f"{engine.stats().latency * 1e3:.2f} ms; "
            + (f"{duration:g} s" if duration else "until stopped (Ctrl-C)"),
            flush=True,
        )
        end = time.monotonic() + duration if duration else None
        while end is None or time.monotonic() < end:
            time.sleep(max(0.0, min(0.5, end - time.monotonic())) if end else 0.5)
            if not args.quiet:
                print(f"\r{engine.stats().summary()}", end="", flush=True)
    finally:
        if osc is not None:
            osc.stop()
        stats = engine.stop()
        print(f"\n{stats.summary()}", flush=True)
    return 0


def _cmd_demo(args: argparse.Namespace) -> int:
    from patches import demo

    if args.script:
        from jassy.files import write_signal

        rendering = demo.render_script(demo.stroke(), 2.0, args.mode)
        write_signal(args.script, rendering.audio, rendering.sample_rate)
        print(f"wrote {args.script}: a scripted tap and {args.mode} stroke (2 s)")
        return 0
    run = demo.run_headless if args.headless else demo.run_window
    run(
        args.mode,
        args.probe_udp,
        block=args.block,
        ring_blocks=args.ring,
        device=args.device,
        haptic_udp=args.haptic_udp,
    )
    return 0


def _cmd_haptic_bridge(args: argparse.Namespace) -> int:
    from jassy.apps.bridge import run_bridge, scripted_path, write_log
    from jassy.engines.hapticframes import parse_address

    parse_address(args.engine, "--engine")  # bad addresses fail before anything starts
    parse_address(args.listen, "--listen")
    if args.duration is not None and not args.duration >= 0:
        raise JassyError(f"--duration: expected seconds >= 0 (0 = until stopped), got {args.duration}")
    ticks = []
    print(f"haptic bridge: poses to {args.engine}, frames on {args.listen}; Ctrl-C stops", flush=True)
    try:
        counts = run_bridge(
            args.engine,
            args.listen,
            scripted_path(),
            duration=args.duration or None,
            rate=args.rate,
            on_tick=ticks.append if args.log else None,
        )
        print(
            f"{counts['ticks']} ticks, {counts['frames']} frames ({counts['lost']} lost), "
            f"{counts['finals']} final",
            flush=True,
        )
    finally:
        if args.log:
            write_log(args.log, ticks)
    return 0


def _cmd_devices(args: argparse.Namespace) -> int:
    from jassy.engines.devices import describe, list_devices

    print(describe(list_devices()))
    return 0


def _first_line(text: str | None) -> str:
    return (text or "").strip().splitlines()[0] if (text or "").strip() else ""


def _cmd_list(args: argparse.Namespace) -> int:
    from jassy.patchfile import builtin_patches, load_patch
    from jassy.registry import ugen_types

    if args.objects:
        from patches.objects import OBJECTS

        print("objects (model files beside the built-in patches; 'jassy doc FILE' for modes and points):")
        for name, info in OBJECTS.items():
            print(f"  {name:<13} {info.file:<24} {info.size}")
            print(f"  {'':<13} {info.description}; points: {', '.join(info.points)}")
        return 0

    print("patches:")
    for name in sorted(builtin_patches()):
        print(f"  {name:<12} {load_patch(name).description}")
    print("scenes (physics, then sound):")
    for name in sorted(SCENES):
        module, function = SCENES[name]
        print(f"  {name:<12} {module}.{function}")
    print("ugens:")
    for name, cls in ugen_types().items():
        params = ", ".join(cls.all_specs())  # with the common `smooth`
        actions = ", ".join(cls.actions)
        extra = f"; actions: {actions}" if actions else ""
        print(f"  {name:<14} {_first_line(cls.__doc__)}")
        print(f"  {'':<14} params: {params or '-'}{extra}")
    return 0


def _cmd_info(args: argparse.Namespace) -> int:
    from jassy.patchfile import is_model_file, load_patch

    if is_model_file(args.patch):
        from physics.modal.cli import describe_model

        print(describe_model(args.patch))
        return 0

    from jassy.apps.doc import describe_patch

    patch = load_patch(args.patch, args.set or ())
    print(describe_patch(patch))
    for node in patch.graph.order:
        model = node.values.get("model")
        if model is not None:
            print(
                f"model of {node.name}: {model.n_modes} modes, {model.frequencies.min():.1f}-"
                f"{model.frequencies.max():.1f} Hz, {model.n_points} location(s)"
                + (f" ({', '.join(model.points)})" if model.points else "")
            )
    return 0


def _add_haptic_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--max-force", type=float, default=float("inf"), help="haptic force clamp, N (default none)"
    )
    p.add_argument("--max-slew", type=float, default=float("inf"), help="haptic slew-rate limit, N/s")
    p.add_argument("--audio-offset", type=float, default=0.0, metavar="MS", help="delay audio by MS ms")
    p.add_argument(
        "--haptic-offset",
        type=float,
        default=0.0,
        metavar="MS",
        help="delay haptics by MS ms (2 = audio leads by 2 ms, applied exactly in samples)",
    )


def _add_render(sub: argparse._SubParsersAction) -> None:
    """``jassy render``: a patch to an audio file (and haptic track, plot, CSV)."""
    p = sub.add_parser("render", help="render a patch to a WAV/FLAC file")
    p.add_argument("patch", help="patch file (.toml) or built-in patch name (see 'jassy list')")
    p.add_argument("-o", "--output", required=True, help="output file (.wav or .flac)")
    p.add_argument("--duration", type=float, help="seconds to render (default: the patch's)")
    p.add_argument("--sr", type=int, help=f"sample rate in Hz (default: the patch's or {DEFAULT_RATE})")
    p.add_argument(
        "--block",
        type=int,
        default=OFFLINE_BLOCK,
        help=f"block size in frames (default {OFFLINE_BLOCK}; the output does not depend on it)",
    )
    p.add_argument("--set", action="append", metavar="NODE.PARAM=VALUE", help="override a node parameter")
    p.add_argument(
        "--event",
        action="append",
        metavar="time=S,node=N,action=A,ARG=V,...",
        help="add a score event, e.g. 'time=1.0,node=hit,action=impact,impulse=0.02' (action default: set)",
    )
    p.add_argument(
        "--format",
        default="float32",
        choices=["float32", "pcm16", "pcm24"],
        help="sample format (default float32; FLAC needs pcm16/pcm24)",
    )
    p.add_argument("--haptic", metavar="FILE", help="also write the haptic force track (.wav, .npz or .csv)")
    p.add_argument(
        "--csv", metavar="FILE", help="physics scenes (drill): also write their measurements as CSV"
    )
    p.add_argument(
        "--mode-budget",
        type=int,
        metavar="N",
        help="anytime synthesis: compute at most N modes across all modal banks",
    )
    _add_haptic_arguments(p)
    p.add_argument("--plot", metavar="PNG", help="also draw waveform, spectrogram and level meter")
    p.add_argument(
        "--normalise",
        choices=["peak", "lufs"],
        help="scale to a peak level (default -1 dBFS) or integrated loudness (default -16 LUFS)",
    )
    p.add_argument("--target", type=float, metavar="DB", help="--normalise target: dBFS (peak) or LUFS")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar or summary line")
    p.set_defaults(func=_cmd_render)


def _add_play(sub: argparse._SubParsersAction) -> None:
    """``jassy play``: a patch live on the audio device (and haptic outputs, OSC control)."""
    p = sub.add_parser("play", help="play a patch live (audio + haptic channels on one clock)")
    p.add_argument("patch", help="patch file (.toml) or built-in patch name")
    p.add_argument("--device", help="output device index or name substring (see 'jassy devices')")
    p.add_argument(
        "--duration", type=float, help="seconds to play (default or 0: until stopped by Ctrl-C or a signal)"
    )
    p.add_argument("--sr", type=int, help=f"sample rate in Hz (default: the patch's or {DEFAULT_RATE})")
    p.add_argument("--block", type=int, default=64, help="frames per device callback (default 64)")
    p.add_argument("--ring", type=float, default=2.5, help="blocks rendered ahead (latency; default 2.5)")
    p.add_argument(
        "--mode",
        choices=["auto", "callback", "ring"],
        default="auto",
        help="callback: the graph rendered in the device callback (latency = the device's); "
        "ring: a producer renders ahead; auto (default): callback where the patch allows it",
    )
    p.add_argument("--set", action="append", metavar="NODE.PARAM=VALUE", help="override a node parameter")
    p.add_argument("--no-haptic-card", action="store_true", help="do not send haptic channels to the device")
    p.add_argument("--haptic-udp", metavar="HOST:PORT", help="also stream 1 kHz haptic frames over UDP")
    p.add_argument("--osc", metavar="HOST:PORT", help="take parameter changes and events over OSC (UDP)")
    _add_haptic_arguments(p)
    p.add_argument("-q", "--quiet", action="store_true", help="no running counters")
    p.set_defaults(func=_cmd_play)


def _add_demo(sub: argparse._SubParsersAction) -> None:
    """``jassy demo``: the interactive probe on a steel plate."""
    p = sub.add_parser(
        "demo", help="interactive probe on a steel plate: click to tap, drag to scrape or roll"
    )
    p.add_argument("--mode", default="scrape", choices=["scrape", "roll", "drill", "poke"])
    p.add_argument("--script", metavar="OUT.wav", help="no window: render a scripted probe stroke to a file")
    p.add_argument("--device", help="output device index or name substring")
    p.add_argument("--block", type=int, default=64, help="frames per device callback (default 64)")
    p.add_argument("--ring", type=float, default=2.5, help="blocks rendered ahead (default 2.5)")
    p.add_argument("--probe-udp", metavar="HOST:PORT", help="also take the probe's pose from a UDP device")
    p.add_argument("--haptic-udp", metavar="HOST:PORT", help="send 1 kHz haptic frames to a UDP device")
    p.add_argument("--headless", action="store_true", help="no window: play until stopped (UDP probe input)")
    p.set_defaults(func=_cmd_demo)


def _add_haptic_bridge(sub: argparse._SubParsersAction) -> None:
    """``jassy haptic-bridge``: the reference UDP haptic device."""
    p = sub.add_parser(
        "haptic-bridge",
        help="reference UDP haptic device: sends probe poses, receives forces, lets go safely",
    )
    p.add_argument(
        "--engine", required=True, metavar="HOST:PORT", help="the engine's probe input (demo --probe-udp)"
    )
    p.add_argument(
        "--listen", default="127.0.0.1:9021", metavar="HOST:PORT", help="where the engine sends haptic frames"
    )
    p.add_argument("--rate", type=float, default=1000.0, help="servo loop rate, Hz (default 1000)")
    p.add_argument("--duration", type=float, help="seconds (default or 0: until stopped)")
    p.add_argument("--log", metavar="FILE.csv", help="write every tick: time, position, force, frame age")
    p.set_defaults(func=_cmd_haptic_bridge)


def _add_application_commands(sub: argparse._SubParsersAction) -> None:
    """The subcommands the applications' own modules register (batch, analysis, study, modal)."""
    from jassy import batch
    from jassy.apps import analyze, audiocheck, doc, preview
    from jassy.study.cli import add_command as add_study
    from physics.modal.cli import add_commands as add_modal

    batch.add_command(sub)
    analyze.add_command(sub)
    audiocheck.add_command(sub)
    preview.add_command(sub)
    doc.add_command(sub)
    add_study(sub)
    add_modal(sub)


def _add_list_and_info(sub: argparse._SubParsersAction) -> None:
    """``jassy list`` (patches, ugen types, objects) and ``jassy info`` (one patch or model)."""
    p = sub.add_parser("list", help="list built-in patches and ugen types (or --objects)")
    p.add_argument("--objects", action="store_true", help="the object library: models of everyday objects")
    p.set_defaults(func=_cmd_list)
    p = sub.add_parser("info", help="show a patch's graph, models and score, or a model file's modes")
    p.add_argument("patch")
    p.add_argument("--set", action="append", metavar="NODE.PARAM=VALUE")
    p.set_defaults(func=_cmd_info)


def _add_bench(sub: argparse._SubParsersAction) -> None:
    """``jassy bench NAME``: throughput against references."""
    from jassy.apps.benches import BENCHES, bench_help, run_bench

    p = sub.add_parser("bench", help="measure throughput against references")
    p.add_argument("name", choices=list(BENCHES), help=bench_help())
    p.add_argument("--plot", metavar="PNG", help="anytime: plot the error against the budget")
    p.add_argument("--seconds", type=float, help="live: duration (default 60)")
    p.add_argument("--ring", type=float, default=2.5, help="live: blocks rendered ahead (default 2.5)")
    p.add_argument("--block", type=int, default=64, help="live: device buffer in frames (default 64)")
    p.add_argument(
        "--mode",
        choices=["auto", "callback", "ring"],
        default="auto",
        help="live: engine mode (default auto)",
    )
    p.add_argument(
        "--floor",
        action="store_true",
        help="live: then as long a run of a callback writing silence (the host's own underruns)",
    )
    p.add_argument("--quick", action="store_true", help="smaller sizes (for CI smoke runs)")
    p.add_argument("--json", action="store_true", help="print JSON instead of a table")
    p.set_defaults(func=run_bench)


def _add_warm_and_rod(sub: argparse._SubParsersAction) -> None:
    """``jassy warm`` (compile scenes' kernels ahead) and ``jassy rod`` (2D-rod experiments)."""
    p = sub.add_parser("warm", help="compile the numba kernels of scenes ahead of their first render")
    p.add_argument("scenes", nargs="*", default=["bell", "wok"], help="patches or scenes (default: bell wok)")
    p.add_argument("--jobs", type=int, help="scenes compiled at once (default: one per core)")
    p.set_defaults(func=_cmd_warm)
    p = sub.add_parser("rod", help="run a 2D-rod experiment (prints JSON)")
    p.add_argument("name", help="experiment name (see 'jassy rod list')")
    p.add_argument("--plot", metavar="PNG", help="also write a plot")
    p.add_argument("--quick", action="store_true", help="smaller sizes")
    p.set_defaults(func=_cmd_rod)


def build_parser() -> argparse.ArgumentParser:
    """The ``jassy`` command line: every subcommand, in the order ``--help`` lists them."""
    parser = LineParser(prog="jassy", description="Physically based sound synthesis.")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    _add_render(sub)
    _add_play(sub)
    _add_demo(sub)
    _add_haptic_bridge(sub)
    sub.add_parser("devices", help="list audio output devices").set_defaults(func=_cmd_devices)
    _add_application_commands(sub)
    _add_list_and_info(sub)
    _add_bench(sub)
    _add_warm_and_rod(sub)
    from jassy.apps.cli_checks import add_limit_options

    add_limit_options(sub)
    return parser


def _cmd_warm(args: argparse.Namespace) -> int:
    from jassy.apps.startup import warm

    if args.jobs is not None and args.jobs < 1:
        raise JassyError(f"--jobs: expected a whole number >= 1, got {args.jobs}")
    for name in args.scenes:  # an unknown name fails here, in one line, before any compiling
        if name not in SCENES:
            from jassy.patchfile import load_patch

            load_patch(name, (), ())
    return 1 if warm(args.scenes, args.jobs) else 0


def _cmd_rod(args: argparse.Namespace) -> int:
    from physics.rod.experiments import EXPERIMENTS

    if args.name == "list":
        print("\n".join(sorted(EXPERIMENTS)))
        return 0
    if args.name not in EXPERIMENTS:
        raise JassyError(
            f"rod: unknown experiment {args.name!r}; expected one of {', '.join(sorted(EXPERIMENTS))}"
            f"{suggest(args.name, EXPERIMENTS)}"
        )
    if args.plot and not args.plot.lower().endswith(".png"):
        raise JassyError(f"--plot: expected a .png file name, got {args.plot!r}")
    if args.plot:
        from jassy.apps.cli_checks import require_extra
        from jassy.files import check_output

        require_extra("matplotlib", "plot", "--plot")
        check_output(args.plot, "--plot", (".png",))
    result = EXPERIMENTS[args.name](plot=args.plot, quick=args.quick)
    print(json.dumps(result, indent=2))
    return 0


#: Commands that play live: SIGINT, SIGTERM and SIGHUP end them in order (exit 128 + signal).
LIVE_COMMANDS = ("play", "demo", "study", "haptic-bridge")


def main(argv: list[str] | None = None) -> int:
    """Run one command; return its exit code (see the module docstring)."""
    from jassy.engines.signals import Stopped, stop_on_signals

    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help, or a usage error already printed as one line
        return exc.code if isinstance(exc.code, int) else 2
    live = args.command in LIVE_COMMANDS
    from jassy.limits import scoped

    with scoped(), stop_on_signals() if live else signals_stop() as stopped:
        try:
            check_arguments(args, parser)
            return args.func(args)
        except Stopped as exc:
            print(f"jassy: stopped by {exc}", file=sys.stderr)
            return exc.exit_code
        except JassyError as exc:
            print(f"jassy: error: {_one_line(exc)}", file=sys.stderr)
            return 2
        except MemoryError:
            print(
                "jassy: error: out of memory; ask for less work, or lower --max-memory so the "
                "estimate refuses it up front",
                file=sys.stderr,
            )
            return 2
        except RecursionError:
            print("jassy: error: input nested too deeply", file=sys.stderr)
            return 2
        except KeyboardInterrupt:
            code = 128 + (stopped.signal if stopped is not None else 2)
            names = {130: "interrupted", 143: "terminated (SIGTERM)", 129: "hung up (SIGHUP)"}
            print(f"jassy: {names.get(code, 'stopped')}", file=sys.stderr)
            return code


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split()) or type(exc).__name__


if __name__ == "__main__":
    sys.exit(main())
