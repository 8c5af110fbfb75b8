"""Steady rolls of the ``roll`` patch: the audio centroid over speeds 10 % apart and the
envelope's rotation line, for the whole patch and each force layer alone.

    python benchmarks/roll_centroid.py
    python benchmarks/roll_centroid.py --set hops.contact_stiffness=0   # micro-impacts open loop
    python benchmarks/roll_centroid.py --seeds 7 --no-rotation   # the patch over other profiles

Each speed is a render of 1.5 s from rest at that speed; the centroid is taken over the last
0.5 s (Hann window), as tests/test_roll_rotation.py does; the rotation line is the strongest
modulation of the 5 ms RMS envelope between 0.5 Hz and 3 v / (2 pi r) + 3 Hz (after 1 s),
against v / (2 pi r). With ``--seeds N`` the whole patch's largest step is also given for
``hops.seed`` and ``ball.seed`` = 1 .. N (the other at its shipped value): everything after
the mixer is linear, so the patch's audio is the sum of its layers' renders, one sweep of
speeds per layer and seed."""

from __future__ import annotations

import argparse
import math

import numpy as np

from jassy import Event, render
from jassy.patchfile import load_patch

FS = 48000
RADIUS = 0.015  # m: the patch's ball
SETTLE = 1.0  # s


def steady_roll(speed: float, seconds: float, overrides: list[str]) -> np.ndarray:
    patch = load_patch("roll", overrides=overrides)
    events = [
        Event(0.0, "ball", "set", {"force": 1.08, "speed": speed}, jump=True),
        Event(0.0, "hops", "set", {"speed": speed}, jump=True),
    ]
    return render(patch.graph, events, SETTLE + seconds, FS, 256, limiter=False).audio[0][int(SETTLE * FS) :]


SPEEDS = 0.1 * 1.1 ** np.arange(32)  # m/s: 0.1 .. 1.9, 10 % apart


def sweep(overrides: list[str]) -> np.ndarray:
    """The last 0.5 s of a steady roll at each of SPEEDS (rows)."""
    return np.array([steady_roll(v, 0.5, overrides) for v in SPEEDS])


def report(name: str, c: np.ndarray) -> None:
    steps = np.maximum(c[1:] / c[:-1], c[:-1] / c[1:])
    print(
        f"{name:14s} centroid {c.min():5.0f}..{c.max():5.0f} Hz  largest step {steps.max():.2f}x "
        f"at {SPEEDS[np.argmax(steps)]:.3f} m/s, steps over 1.2x: {int((steps > 1.2).sum())}",
        flush=True,
    )


def centroid(x: np.ndarray) -> float:
    spec = np.abs(np.fft.rfft(x * np.hanning(x.size))) ** 2
    return float((spec * np.fft.rfftfreq(x.size, 1 / FS)).sum() / spec.sum())


def rotation_error(speed: float, overrides: list[str]) -> float:
    f_rot = speed / (2 * math.pi * RADIUS)
    x = steady_roll(speed, max(6 / f_rot, 2.0), overrides)
    hop = 240
    env = np.sqrt(np.mean(x[: x.size // hop * hop].reshape(-1, hop) ** 2, axis=1))
    spec = np.abs(np.fft.rfft((env - env.mean()) * np.hanning(env.size), 1 << 16))
    f = np.fft.rfftfreq(1 << 16, hop / FS)
    band = np.flatnonzero((f > 0.5) & (f < 3 * f_rot + 3))
    return float(f[band[np.argmax(spec[band])]] / f_rot - 1)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--set", action="append", default=[], help="patch override node.param=value (repeatable)")
    p.add_argument("--no-rotation", action="store_true", help="skip the rotation lines")
    p.add_argument("--seeds", type=int, default=0, help="also the patch with each layer's seed = 1 .. N")
    args = p.parse_args()
    mixer = next(n for n in load_patch("roll", overrides=args.set).graph.order if n.name == "contact")
    rumble, hops = mixer.values["gains"]
    layers = {
        "patch": [],
        "micro-impacts": [f"contact.gains=[0.0, {hops}]"],
        "rumble": [f"contact.gains=[{rumble}, 0.0]"],
    }
    for name, layer in layers.items():
        c = np.array([centroid(x) for x in sweep(args.set + layer)])
        report(name, c)
    if args.seeds:
        shipped = {n.name: n.values.get("seed") for n in load_patch("roll", overrides=args.set).graph.order}
        layer_of = {"ball": layers["rumble"], "hops": layers["micro-impacts"]}
        audio = {
            (node, seed): sweep(args.set + layer_of[node] + [f"{node}.seed={seed}"])
            for node in layer_of
            for seed in sorted({shipped[node], *range(1, args.seeds + 1)})
        }
        for node, other in (("hops", "ball"), ("ball", "hops")):
            for seed in range(1, args.seeds + 1):
                if seed != shipped[node]:
                    mix = audio[node, seed] + audio[other, shipped[other]]
                    report(f"{node}.seed={seed}", np.array([centroid(x) for x in mix]))
    if not args.no_rotation:
        for name, layer in layers.items():
            errors = [rotation_error(v, args.set + layer) for v in (0.1, 0.3, 0.6, 1.0, 1.4, 2.0)]
            print(
                f"{name:14s} rotation line at 0.1/0.3/0.6/1.0/1.4/2.0 m/s: "
                + " ".join(f"{100 * e:+.1f}%" for e in errors),
                flush=True,
            )


if __name__ == "__main__":
    main()
