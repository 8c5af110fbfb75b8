"""Benchmarks (``jassy bench NAME``): throughput beside references measured in the same run.

Machines are noisy, so every figure is reported with a reference timed in the same
process, and the ratio is the number to read.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numba as nb
import numpy as np

from jassy.events import Event
from jassy.graph import Graph
from jassy.modal_model import ModalModel
from jassy.offline import OfflineEngine

SAMPLE_RATE = 48000


@nb.njit(fastmath=True, cache=True)
def plain_modal_loop(force, out, c1, c2, g, y1, y2):
    """Reference: the textbook loop, sample-outer and mode-inner, fastmath."""
    for n in range(force.shape[0]):
        f = force[n]
        acc = 0.0
        for k in range(c1.shape[0]):
            y = c1[k] * y1[k] - c2[k] * y2[k] + g[k] * f
            y2[k] = y1[k]
            y1[k] = y
            acc += y
        out[n] = acc


def random_model(n_modes: int, seed: int = 0) -> ModalModel:
    """Modes log-spread over 20 Hz - 20 kHz, decays 0.5 - 50 1/s."""
    rng = np.random.default_rng(seed)
    f = np.exp(rng.uniform(np.log(20.0), np.log(20000.0), n_modes))
    return ModalModel(f, rng.uniform(0.5, 50.0, n_modes), rng.uniform(0.1, 1.0, (1, n_modes)))


def _best_time(fn: Callable[[], None], repeats: int = 3) -> float:
    fn()  # warm-up (JIT, caches)
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


class _Source:
    """Stand-in for an upstream ugen: a force buffer read as ``.out``."""

    def __init__(self, data: np.ndarray):
        self.out = data


def _modal_row(k: int, seconds: float, block: int) -> dict:
    from scipy.signal import lfilter

    from ugens.modal import ModalBank, design

    model = random_model(k)
    frames = int(seconds * SAMPLE_RATE * min(1.0, 1024 / k) * 4) // block * block
    force = np.random.default_rng(1).standard_normal(frames)

    bank = ModalBank(model)
    src = _Source(np.zeros(block))
    bank.sources["input"] = src
    bank.prepare(SAMPLE_RATE, block)

    def run_bank():
        for start in range(0, frames, block):
            src.out = force[start : start + block]
            bank.process(start, block)

    c1, c2, s = design(model.frequencies, model.decays, SAMPLE_RATE)
    g = s * model.gains[0] / SAMPLE_RATE
    out = np.zeros(block)

    def run_plain():
        y1, y2 = np.zeros(k), np.zeros(k)
        for start in range(0, frames, block):
            plain_modal_loop(force[start : start + block], out, c1, c2, g, y1, y2)

    scipy_frames = max(block, frames // 16)

    def run_scipy():
        acc = np.zeros(scipy_frames)
        for i in range(k):
            acc += lfilter([g[i]], [1.0, -c1[i], c2[i]], force[:scipy_frames])

    return {
        "modes": k,
        "block": block,
        "jassy": k * frames / _best_time(run_bank),
        "plain_numba": k * frames / _best_time(run_plain),
        "scipy_lfilter": k * scipy_frames / _best_time(run_scipy, repeats=1),
    }


def modal_bench(mode_counts=(64, 1024, 16384), seconds: float = 1.0, block: int = 64) -> list[dict]:
    """Mode-samples per second of ModalBank vs a plain numba loop and a scipy lfilter loop.

    All three run on the same random force in calls of ``block`` frames (jassy through
    ``ModalBank.process``, so its per-call overhead counts); the scipy loop runs 1/16 of
    the frames (its cost is linear in frames).
    """
    return [_modal_row(k, seconds, block) for k in mode_counts]


def graph_bench(n_modes: int = 1000, seconds: float = 10.0, block: int = 64) -> dict:
    """The bell patch with an n-mode bell, rendered whole, vs the bare kernel on the same force."""
    from patches.models import bell_model
    from ugens.impact import ImpactForce
    from ugens.mix import Gain
    from ugens.modal import ModalBank, resonate

    model = bell_model(n_modes)
    clapper = ImpactForce(name="clapper", duration=0.0008)
    out = Gain(ModalBank(model, name="bell")(clapper), gain=0.05, name="out")
    graph = Graph(out, haptic=clapper)
    places = ["soundbow", "lip", "waist", "shoulder"]
    score = [
        Event(0.05 + 1.25 * i, "clapper", "impact", {"impulse": 0.5, "location": places[i % 4]})
        for i in range(int(seconds / 1.25))
    ]

    result = {}

    def run_graph():
        engine = OfflineEngine(graph, score, SAMPLE_RATE, block)
        result["rendering"] = engine.render(seconds)

    t_graph = _best_time(run_graph)
    force = result["rendering"].haptic[0].copy()
    bank = graph.nodes["bell"]
    frames = force.size

    def run_kernel():
        bank.reset()
        c, y = bank.coef, bank.y
        resonate(force, np.zeros(frames), frames, c[0], c[1], c[2], y[0], y[1], c.shape[1])

    t_kernel = _best_time(run_kernel)
    return {
        "modes": n_modes,
        "seconds": seconds,
        "block": block,
        "graph_s": t_graph,
        "kernel_s": t_kernel,
        "ratio": t_graph / t_kernel,
        "realtime_factor": seconds / t_graph,
    }


def print_modal(rows: list[dict], graph: dict) -> None:
    print(f"ModalBank throughput at {SAMPLE_RATE} Hz, block {rows[0]['block']} (mode-samples/s, best of 3)")
    print(
        f"{'modes':>7} {'jassy':>10} {'plain numba':>12} {'scipy loop':>11} {'vs plain':>9} {'vs scipy':>9}"
    )
    for r in rows:
        print(
            f"{r['modes']:>7} {r['jassy']:>10.3g} {r['plain_numba']:>12.3g} {r['scipy_lfilter']:>11.3g} "
            f"{r['jassy'] / r['plain_numba']:>8.2f}x {r['jassy'] / r['scipy_lfilter']:>8.0f}x"
        )
    print(
        f"bell patch, {graph['modes']} modes, {graph['seconds']:g} s, block {graph['block']}: "
        f"graph {graph['graph_s'] * 1e3:.1f} ms, bare kernel {graph['kernel_s'] * 1e3:.1f} ms, "
        f"ratio {graph['ratio']:.2f} ({graph['realtime_factor']:.0f}x real time)"
    )
