"""Checks of command-line arguments made before any work, and clean stops on signals.

* :class:`LineParser`: argparse whose usage errors are one line (exit 2).
* :func:`check_arguments`: every command's numbers are finite (unless the option's default
  is infinite, meaning "none") and integers fit in 53 bits; ``--sr`` is a real rate;
  the resource limits (``--max-memory`` ...) are taken over (see :mod:`jassy.limits`).
* :func:`check_render_arguments`, :func:`check_render_size`: ``jassy render``'s values,
  outputs (writable, distinct, not a directory) and the memory and length of the work.
* :func:`signals_stop`: SIGTERM and SIGHUP stop a command like Ctrl-C (KeyboardInterrupt,
  so every ``finally`` and atomic write cleans up); the exit code is 128 + the signal.
"""

from __future__ import annotations

import argparse
import contextlib
import inspect
import math
import signal
import sys
import threading
from collections.abc import Callable, Iterator
from typing import Any

from jassy.errors import JassyError
from jassy.inputs import number, parse_toml, require_extra, seconds
from jassy.limits import check_memory, check_seconds, configure

#: Sample rates accepted on the command line (Hz).
MIN_RATE, MAX_RATE = 1000, 768000
#: Largest --block (frames per block).
MAX_BLOCK = 2**20
#: Largest |--audio-offset| / |--haptic-offset| (ms).
MAX_OFFSET_MS = 60_000.0


class LineParser(argparse.ArgumentParser):
    """An ArgumentParser whose errors are one line on stderr: ``jassy CMD: error: ...``."""

    def error(self, message: str):
        print(f"{self.prog}: error: {' '.join(message.split())}", file=sys.stderr)
        raise SystemExit(2)


def add_limit_options(subparsers) -> None:
    """Add --max-memory, --max-seconds and --max-variants to every command."""
    for parser in set(subparsers.choices.values()):
        group = parser.add_argument_group("resource limits (see README: Limits)")
        group.add_argument(
            "--max-memory",
            metavar="SIZE",
            help="refuse work estimated above SIZE (e.g. 8G; default: half the RAM)",
        )
        group.add_argument(
            "--max-seconds",
            metavar="S",
            help="refuse rendering/analysing more than S s of audio (default 3600)",
        )
        group.add_argument(
            "--max-variants", metavar="N", help="refuse batches of more than N variants (default 100000)"
        )


def _infinite_defaults(parser: argparse.ArgumentParser) -> set[str]:
    """Destinations of options, in ``parser`` and its subcommands, whose default is infinite
    (meaning "no limit"; giving ``inf`` explicitly is then the same)."""
    found, stack = set(), [parser]
    while stack:
        for action in stack.pop()._actions:
            if isinstance(action, argparse._SubParsersAction):
                stack.extend(action.choices.values())
            elif isinstance(action.default, float) and math.isinf(action.default):
                found.add(action.dest)
    return found


def check_arguments(args: argparse.Namespace, parser: argparse.ArgumentParser) -> None:
    """Checks every command shares: limits, finite numbers, bounded integers, sample rate."""
    configure(
        getattr(args, "max_memory", None),
        getattr(args, "max_seconds", None),
        getattr(args, "max_variants", None),
    )
    unlimited = _infinite_defaults(parser)
    for key, value in vars(args).items():
        option = "--" + key.replace("_", "-")
        values = value if isinstance(value, list) else [value]
        for v in values:
            if isinstance(v, float) and not math.isfinite(v) and not (key in unlimited and v == math.inf):
                raise JassyError(f"{option}: expected a finite number, got {v}")
            if isinstance(v, int) and not isinstance(v, bool) and abs(v) > 2**53:
                raise JassyError(f"{option}: expected an integer of at most 2^53, got {v}")
            if isinstance(v, str) and "\0" in v:
                raise JassyError(f"{option}: unexpected NUL character in {v!r}")
    rate = getattr(args, "sr", None)
    if rate is not None:
        number(rate, "--sr", MIN_RATE, MAX_RATE, integer=True)
    for key, option in (("audio_offset", "--audio-offset"), ("haptic_offset", "--haptic-offset")):
        if getattr(args, key, None) is not None:
            number(getattr(args, key), option, -MAX_OFFSET_MS, MAX_OFFSET_MS)
    if isinstance(getattr(args, "block", None), int):
        number(args.block, "--block", 1, MAX_BLOCK, integer=True)
    if getattr(args, "plot", None):
        from jassy.files import check_output

        require_extra("matplotlib", "plot", "--plot")
        check_output(args.plot, "--plot")
    if getattr(args, "parquet", None) is True:
        require_extra("pyarrow", "parquet", "--parquet")


def check_render_arguments(args: argparse.Namespace) -> None:
    """``jassy render``: every value and output name checked before the patch is built."""
    from jassy.files import AUDIO_FORMATS, audio_format, check_distinct, check_output

    check_output(args.output, "-o/--output", tuple(AUDIO_FORMATS))
    audio_format(args.output, args.format)
    if args.haptic is not None:
        check_output(args.haptic, "--haptic", (".wav", ".npz", ".csv"))
    if args.csv is not None:
        check_output(args.csv, "--csv", (".csv",))
    check_distinct({"-o/--output": args.output, "--haptic": args.haptic, "--csv": args.csv})
    if args.duration is not None:
        seconds(args.duration, "--duration")
    number(args.block, "--block", 1, MAX_BLOCK, integer=True)
    for option, value in (("--audio-offset", args.audio_offset), ("--haptic-offset", args.haptic_offset)):
        number(value, option, -MAX_OFFSET_MS, MAX_OFFSET_MS)
    for option, value in (("--max-force", args.max_force), ("--max-slew", args.max_slew)):
        if value != math.inf:
            number(value, option, 0.0, 1e30, low_open=True)
    if args.mode_budget is not None:
        number(args.mode_budget, "--mode-budget", 0, 2**31 - 1, integer=True)


def check_render_size(args: argparse.Namespace, graph, duration: float, rate: float) -> None:
    """Refuse a render longer than the --max-seconds limit or whose buffers exceed --max-memory:
    the haptic track kept for its file (frames x channels), the per-node blocks, the offset delay."""
    check_seconds(duration, "render")
    frames = duration * rate
    n_audio, n_haptic = len(graph.audio), len(graph.haptic)
    held = frames * n_haptic * 8 if args.haptic else 0.0
    blocks = args.block * 8 * (4 * len(graph.nodes) + n_audio + n_haptic)
    delay = abs(args.audio_offset - args.haptic_offset) / 1000 * rate * 8 * (n_audio + n_haptic)
    check_memory(held + blocks + delay, "render")


def scene_options(
    scene: str, texts: tuple[str, ...] | list[str], render: Callable, experiment: Callable | None
) -> dict[str, Any]:
    """``--set NAME=VALUE`` for a physics scene: NAME must be a keyword of the scene's render
    (or experiment) function, VALUE of its default's type; counts may grow to 8x their
    default, other quantities to 1000x (and keep the default's sign), so one option cannot
    ask for a simulation that would not end."""
    fixed = {"out_wav", "haptic_path", "csv_path", "duration", "sample_rate", "block", "volume"}
    defaults: dict[str, Any] = {}
    for function in (experiment, render):
        if function is None:
            continue
        for name, param in inspect.signature(function).parameters.items():
            if param.default is not inspect.Parameter.empty and name not in fixed:
                defaults[name] = param.default
    options: dict[str, Any] = {}
    for text in texts:
        key, sep, raw = text.partition("=")
        key = key.strip()
        if not sep or not key:
            raise JassyError(f"--set {text!r}: expected name=value for scene {scene!r}")
        if key not in defaults:
            known = ", ".join(sorted(defaults))
            raise JassyError(f"--set {text!r}: scene {scene!r} has no option {key!r}; expected {known}")
        try:
            value = parse_toml(f"v = {raw.strip()}", "--set")["v"]
        except JassyError:
            value = raw.strip()
        default = defaults[key]
        where = f"--set {key}"
        if isinstance(default, (bool, str)) or default is None:
            if type(value) is not type(default) and default is not None:
                raise JassyError(f"{where}: expected {type(default).__name__}, got {value!r}")
        elif isinstance(default, int):
            high = 2**32 - 1 if default <= 1 else 8 * default
            value = number(value, where, 0 if default >= 0 else -high, high, integer=True)
        elif isinstance(default, float):
            high = 1000 * abs(default) if default else 1e6
            low, high = (0.0, high) if default >= 0 else (-high, 0.0)
            value = number(value, where, low, high)
        options[key] = value
    return options


class _Stop:
    """The signal that stopped a command (SIGINT unless SIGTERM or SIGHUP arrived)."""

    signal = signal.SIGINT


@contextlib.contextmanager
def signals_stop() -> Iterator[_Stop]:
    """While active (main thread only), SIGTERM and SIGHUP raise KeyboardInterrupt like Ctrl-C;
    the yielded record names the signal. Previous handlers are restored afterwards."""
    stop = _Stop()
    if threading.current_thread() is not threading.main_thread():
        yield stop
        return

    from jassy import stopflag

    def handler(signum, frame):
        stop.signal = signum
        stopflag.requested.set()
        raise KeyboardInterrupt

    stopflag.requested.clear()

    saved = {}
    for sig in (signal.SIGTERM, getattr(signal, "SIGHUP", None)):
        if sig is not None:
            saved[sig] = signal.signal(sig, handler)
    try:
        yield stop
    finally:
        for sig, previous in saved.items():
            signal.signal(sig, previous)
        stopflag.requested.clear()
