"""``jassy analyze FILE``: perceptual features of a recording or a render over time.

The file plays through a Sampler at its own sample rate into the analysis ugens
(``ugens.analysis``); their outputs are read every ``hop`` samples (the onset column
holds 1 where an onset fell within the hop) and written as CSV (time in s, one column per
feature), optionally plotted under the waveform. :func:`feature_events` turns a curve into
parameter events, so a recording can drive any parameter of a patch.
"""

from __future__ import annotations

import argparse
import csv
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from jassy.errors import JassyError, suggest

#: Feature name -> what it measures (the CSV column is the name).
FEATURES = {
    "rms": "RMS envelope (one-pole, time constant = one hop)",
    "zcr": "zero crossings per second over one frame",
    "centroid": "spectral centroid (Hz)",
    "spread": "spectral spread (Hz)",
    "flatness": "spectral flatness (0 tonal .. 0.56 white noise)",
    "rolloff": "85 % power rolloff frequency (Hz)",
    "flux": "spectral flux between frames",
    "pitch": "YIN fundamental frequency (Hz, 0 unvoiced)",
    "clarity": "YIN clarity (1 - d')",
    "onset": "1 where an onset was detected in the hop",
}


class Features(NamedTuple):
    """Feature curves sampled every hop: times (s) and one array per feature."""

    times: np.ndarray
    values: dict[str, np.ndarray]
    signal: np.ndarray
    sample_rate: float


def parse_features(text: str | None) -> list[str]:
    """Feature names from a comma-separated list (all when None); JassyError if unknown."""
    if text is None:
        return list(FEATURES)
    names = [t.strip() for t in text.split(",") if t.strip()]
    for name in names:
        if name not in FEATURES:
            raise JassyError(
                f"--features: unknown feature {name!r}{suggest(name, FEATURES)}; "
                f"expected a comma-separated list of {', '.join(FEATURES)}"
            )
    if not names:
        raise JassyError(f"--features: expected a comma-separated list of {', '.join(FEATURES)}")
    return names


def analyze(path: str, features: Sequence[str], size: int = 2048, hop: int = 512) -> Features:
    """Features of the audio file ``path`` every ``hop`` samples (frames of ``size``)."""
    from jassy import Graph, render
    from ugens.analysis import EnvelopeFollower, Onset, Pitch, SpectralFeatures, ZeroCrossings
    from ugens.sampler import Sampler, load_audio

    signal, rate = load_audio(path, "FILE")
    source = Sampler(name="file", file=path)
    spectral = SpectralFeatures(source, name="spectral", size=size, hop=hop)
    pitch = Pitch(source, name="pitch", size=max(size, 2048), hop=hop)
    taps = {
        "rms": EnvelopeFollower(source, name="rms", attack=hop / rate, release=hop / rate),
        "zcr": ZeroCrossings(source, name="zcr", window=size / rate),
        "centroid": spectral,
        "spread": spectral.tap("spread"),
        "flatness": spectral.tap("flatness"),
        "rolloff": spectral.tap("rolloff"),
        "flux": spectral.tap("flux"),
        "pitch": pitch,
        "clarity": pitch.tap("clarity"),
        "onset": Onset(source, name="onset", size=size, hop=hop),
    }
    nodes = [taps[name] for name in features]
    rendering = render(Graph(source, nodes), (), duration=signal.size / rate, sample_rate=rate, limiter=False)
    frames = np.arange(hop, signal.size, hop)
    values = {}
    for name, curve in zip(features, rendering.haptic, strict=True):
        if name == "onset":  # an impulse: did one fall within the hop ending here?
            padded = np.concatenate([curve, np.zeros((-curve.size) % hop)])
            values[name] = padded.reshape(-1, hop).max(axis=1)[: frames.size]
        else:
            values[name] = curve[frames]
    return Features(frames / rate, values, signal, rate)


def feature_events(
    features: Features, feature: str, node: str, param: str, scale: float = 1.0, offset: float = 0.0
) -> list:
    """Score events making ``node.param`` follow a feature curve: ``offset + scale * value``
    set at every hop time, ramped linearly to the next (so the parameter is the curve's
    piecewise-linear interpolation, one hop late). E.g. a voice's ``rms`` driving a scrape's
    ``force``: ``render(graph, feature_events(f, "rms", "scrape", "force", 40.0), ...)``."""
    from jassy.events import Event

    times, values = features.times, features.values[feature]
    hop = float(times[1] - times[0]) if times.size > 1 else 0.0
    return [
        Event(float(t), node, "set", {param: float(offset + scale * v)}, ramp=hop)
        for t, v in zip(times, values, strict=True)
    ]


def write_csv(features: Features, path: str) -> None:
    """time_s and one column per feature, written atomically."""
    from jassy.files import atomic_path

    with atomic_path(path) as tmp, open(tmp, "w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(["time_s", *features.values])
        for i, t in enumerate(features.times):
            writer.writerow([f"{t:.6f}", *(f"{v[i]:.6g}" for v in features.values.values())])


def plot(features: Features, path: str, title: str) -> None:
    """The waveform and each feature curve over time, one panel each (PNG)."""
    try:
        import matplotlib
    except ImportError:
        raise JassyError("--plot needs matplotlib (pip install 'jassy[plot]')") from None
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from jassy.files import atomic_path

    rows = 1 + len(features.values)
    fig, axes = plt.subplots(rows, 1, figsize=(10, 1.6 * rows), sharex=True)
    t = np.arange(features.signal.size) / features.sample_rate
    axes[0].plot(t, features.signal, lw=0.4, color="0.3")
    axes[0].set_ylabel("signal")
    axes[0].set_title(title)
    for ax, (name, curve) in zip(axes[1:], features.values.items(), strict=True):
        ax.plot(features.times, curve, lw=0.9)
        ax.set_ylabel(name)
    axes[-1].set_xlabel("time (s)")
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=100)
    plt.close(fig)


def _cmd_analyze(args: argparse.Namespace) -> int:
    from jassy.files import check_distinct, check_output

    names = parse_features(args.features)
    if args.hop < 1 or args.size < 64 or args.size & (args.size - 1):
        raise JassyError(
            f"--size/--hop: expected a power of two >= 64 and a hop >= 1, got {args.size}/{args.hop}"
        )
    if args.output:
        check_output(args.output, "-o", (".csv",))
    if args.plot:
        check_output(args.plot, "--plot", (".png",))
    check_distinct({"-o": args.output, "--plot": args.plot})
    features = analyze(args.file, names, size=args.size, hop=args.hop)
    if args.output:
        write_csv(features, args.output)
    if args.plot:
        plot(features, args.plot, args.file)
    for name, curve in features.values.items():
        summary = f"{int(curve.sum())} onsets" if name == "onset" else f"mean {np.mean(curve):.4g}"
        print(f"{name:<9} {summary:<18} {FEATURES[name]}")
    return 0


def add_command(subparsers) -> argparse.ArgumentParser:
    """Add ``jassy analyze`` to the CLI's subparsers."""
    p = subparsers.add_parser("analyze", help="perceptual features of a sound file over time (CSV, plot)")
    p.add_argument("file", help="audio file (WAV, FLAC, ...)")
    p.add_argument(
        "--features", metavar="LIST", help=f"comma-separated, of: {', '.join(FEATURES)} (default all)"
    )
    p.add_argument("-o", "--output", metavar="FEATURES.csv", help="write the curves as CSV")
    p.add_argument("--plot", metavar="FEATURES.png", help="plot the curves under the waveform")
    p.add_argument("--size", type=int, default=2048, help="FFT frame in samples (default 2048)")
    p.add_argument("--hop", type=int, default=512, help="samples between frames (default 512)")
    p.set_defaults(func=_cmd_analyze)
    return p
