"""Anytime synthesis: error falls with the budget, the budget holds, modes leave smoothly."""

import numpy as np
import pytest
from helpers import max_abs_diff

from jassy import Event, Graph, ModalModel, PatchError, render
from jassy.anytime import ModeBudget, a_weighting_power
from jassy.cli import main
from patches.models import bell_model
from ugens import ImpactForce, Mixer, ModalBank

FS = 48000


def scene(budget, seconds=2.0, seed=0):
    """Six bells of 150 modes struck 30 times at random."""
    rng = np.random.default_rng(seed)
    banks, hits = [], []
    for b in range(6):
        hit = ImpactForce(name=f"h{b}", duration=0.0005)
        banks.append(ModalBank(bell_model(150, prime=150 + 60 * b, seed=b), name=f"b{b}")(hit))
        hits.append(hit)
    score = [
        Event(float(t), f"h{int(b)}", "impact", {"impulse": float(j)})
        for t, b, j in zip(
            rng.uniform(0, seconds, 30), rng.integers(0, 6, 30), rng.uniform(0.05, 0.5, 30), strict=True
        )
    ]
    return Graph(Mixer(*banks), haptic=hits, budget=budget), score


def test_error_against_full_synthesis_falls_as_the_budget_grows():
    graph, score = scene(None)
    full = render(graph, score, 2.0, FS, 64, limiter=False).audio[0]
    errors = []
    for n in (20, 90, 225, 450, 900):
        graph, score = scene(ModeBudget(max_modes=n))
        y = render(graph, score, 2.0, FS, 64, limiter=False).audio[0]
        errors.append(np.sqrt(np.mean((y - full) ** 2) / np.mean(full**2)))
    assert all(a > b for a, b in zip(errors, errors[1:], strict=False)), errors
    assert errors[-1] < 1e-9  # everything fits: exact
    assert errors[2] < 0.3  # a quarter of the modes already gets within -10 dB


def test_budget_is_never_exceeded():
    budget = ModeBudget(max_modes=100)
    graph, score = scene(budget)
    banks = [graph.nodes[f"b{b}"] for b in range(6)]
    worst = [0]

    def audit(start, n):
        worst[0] = max(worst[0], sum(int(b.meta[0]) for b in banks))

    graph.prepare(FS, 64)
    original = Graph.prepare

    def prepare_with_audit(self, sample_rate, block):
        original(self, sample_rate, block)
        self.steps.append(audit)

    Graph.prepare = prepare_with_audit
    try:
        render(graph, score, 2.0, FS, 64, limiter=False)
    finally:
        Graph.prepare = original
    assert 90 <= worst[0] <= 100
    assert budget.peak_modes <= 100 and budget.decisions == int(np.ceil(2.0 * FS / budget.period))


def test_budgeted_render_is_block_size_invariant():
    outs = []
    for block in (1, 64, 1000):
        graph, score = scene(ModeBudget(max_modes=120), seconds=0.6)
        outs.append(render(graph, score, 0.6, FS, block, limiter=False).audio)
    assert max_abs_diff(outs[0], outs[1]) < 1e-6 and max_abs_diff(outs[0], outs[2]) < 1e-6


def test_a_displaced_mode_fades_out_before_the_new_one_enters():
    """Budget 1: a ringing 220 Hz mode must give way to a 1 kHz strike at 0.5 s."""
    low = ModalModel([220.0], [0.5], [[1.0]])
    high = ModalModel([1000.0], [3.0], [[1.0]])
    ha, hb = ImpactForce(name="ha"), ImpactForce(name="hb")
    mix = Mixer(ModalBank(low, name="a")(ha), ModalBank(high, name="b")(hb))
    score = [Event(0.0, "ha", "impact", {"impulse": 0.5}), Event(0.5, "hb", "impact", {"impulse": 1.0})]
    budget = ModeBudget(max_modes=1, period=512)
    y = render(Graph(mix, budget=budget), score, 1.0, FS, 64, limiter=False).audio[0]
    hb2 = ImpactForce(name="hb")
    b_only = render(Graph(ModalBank(high)(hb2)), score[1:], 1.0, FS, 64, limiter=False).audio[0]
    strike = int(0.5 * FS)
    fade_start = (strike // 512 - 1) * 512  # the decision one period before the strike's own
    # before the fade: the low mode rings untouched; during it: a smooth exponential decay
    ring = y[:fade_start]
    np.testing.assert_array_equal(
        ring,
        render(Graph(ModalBank(low)(ImpactForce(name="ha"))), score[:1], 1.0, FS, 64, limiter=False).audio[0][
            :fade_start
        ],
    )
    assert np.max(np.abs(np.diff(y[fade_start - 200 : strike]))) <= np.max(np.abs(np.diff(ring))) * 1.001
    before = np.abs(y[fade_start - 220 : fade_start]).max()  # one 220 Hz cycle before the fade
    assert np.abs(y[fade_start + 462 : fade_start + 512]).max() < 2e-3 * before  # -54 dB within the period
    assert np.max(np.abs(y[strike - 64 : strike])) < 2e-3 * np.max(np.abs(ring))
    # the 1 kHz strike is rendered in full from its first sample
    np.testing.assert_allclose(y[strike:], b_only[strike:], atol=1e-9)
    assert budget.peak_modes == 1


def test_a_weighting_is_normalised_and_shaped():
    w = a_weighting_power(np.array([1000.0, 100.0, 20.0, 4000.0]))
    assert w[0] == pytest.approx(1.0, rel=1e-3)
    assert 10 * np.log10(w[1]) == pytest.approx(-19.1, abs=0.2)  # IEC 61672 table values
    assert 10 * np.log10(w[2]) == pytest.approx(-50.5, abs=0.3)
    assert 10 * np.log10(w[3]) == pytest.approx(1.0, abs=0.2)


def test_budget_options_are_validated_and_reach_the_cli(tmp_path, capsys):
    with pytest.raises(PatchError, match="mode_budget: expected an integer >= 1"):
        ModeBudget(max_modes=0)
    assert (
        main(
            [
                "render",
                "bell",
                "-o",
                str(tmp_path / "b.wav"),
                "--duration",
                "0.5",
                "--mode-budget",
                "10",
                "-q",
            ]
        )
        == 0
    )


def test_cpu_budget_adapts_the_mode_count():
    budget = ModeBudget(cpu_fraction=1e-4)  # impossible to meet: shrinks to the floor of 16 modes
    graph, score = scene(budget, seconds=1.0)
    render(graph, score, 1.0, FS, 64, limiter=False)
    assert budget.limit == 16 and budget.peak_modes <= 900
