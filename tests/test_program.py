"""The graph's program (one numba function over the nodes' own arrays) renders the same bits
as running the nodes one by one, and says why a graph cannot run as a program."""

import subprocess
import sys

import numpy as np
import pytest

from jassy import Event, Graph, ModalModel
from jassy.engines.offline import OfflineEngine
from jassy.program import why_not_compiled
from ugens import Gain, ImpactForce, Mixer, ModalBank
from ugens.filters import Biquad
from ugens.radiation import Radiation
from ugens.scrape import ResonantScrape, Scrape

FS = 48000


def plate_model():
    rng = np.random.default_rng(5)
    f = np.geomspace(80.0, 15000.0, 30)
    return ModalModel(f, rng.uniform(1.0, 60.0, 30), rng.uniform(0.1, 1.0, (3, 30)))


def contact_graph(gain=0.05):
    """A tap, a scrape and a rubbed stick on a plate: every kind of program node."""
    tap = ImpactForce(name="tap", duration=0.0007)
    scrape = Scrape(name="scrape", force=1.0, speed=0.0, patch=0.002)
    stick = ResonantScrape(name="stick", force=0.0, speed=0.0)
    force = Mixer(tap, scrape, stick, name="force", gains=[1.0, 0.5, 0.2])
    plate = ModalBank(plate_model(), name="plate")(force)
    high = Biquad(plate, name="high", mode="highpass", freq=60.0)
    radiated = Radiation(high, name="radiated", radius=0.2)
    out = Gain(radiated, gain=gain, name="out")
    return Graph(out, haptic=force)


def contact_score():
    score = []
    for k in range(12):
        t = 0.013 * k + 0.37 / FS * k
        score.append(Event(t, "tap", "impact", {"impulse": 0.002 * (k + 1), "location": k % 3}))
    score += [
        Event(0.02, "scrape", "set", {"speed": 0.3, "force": 2.0}, ramp=0.05),
        Event(0.07 + 3.5 / FS, "stick", "set", {"speed": 0.2, "force": 1.0}, jump=True),
        Event(0.09, "plate", "set", {"freq_scale": 1.1, "decay_scale": 2.0}, ramp=0.01),
        Event(0.1 + 10.25 / FS, "out", "set", {"gain": 0.02}, ramp=0.003),
        Event(0.11, "high", "set", {"freq": 300.0}, ramp=0.01),
        Event(0.14, "plate", "set", {"location": 2}, jump=True),
        Event(0.15, "scrape", "set", {"speed": 0.0}, jump=True),
    ]
    return score


@pytest.mark.parametrize("block", [1, 64, 4096])
def test_program_renders_the_same_bits_as_the_nodes_one_by_one(block):
    rendered = []
    for program in (False, True):
        engine = OfflineEngine(contact_graph(), contact_score(), FS, block, program=program)
        assert (engine.program is not None) == program
        rendered.append(engine.render(0.2))
    assert np.any(rendered[0].audio != 0) and np.any(rendered[0].haptic != 0)
    np.testing.assert_array_equal(rendered[1].audio, rendered[0].audio)
    np.testing.assert_array_equal(rendered[1].haptic, rendered[0].haptic)


def test_compiled_runs_of_any_length_render_the_same_bits(monkeypatch):
    # runs of 333 frames (30 runs, cut between the events' frames) against the paced runs
    from jassy.engines import offline

    paced = OfflineEngine(contact_graph(), contact_score(), FS, 64).render(0.2)
    monkeypatch.setattr(offline, "RENDER_FRAMES", 333)
    monkeypatch.setattr(offline, "RUN_GROWTH", 1)
    short = OfflineEngine(contact_graph(), contact_score(), FS, 64).render(0.2)
    assert np.any(paced.audio != 0) and np.any(paced.haptic != 0)
    np.testing.assert_array_equal(short.audio, paced.audio)
    np.testing.assert_array_equal(short.haptic, paced.haptic)


@pytest.mark.parametrize("block", [1, 64])
def test_python_events_output_limits_and_offsets_match_the_nodes_one_by_one(block):
    """A program graph's render applies its events as records inside compiled runs; a pole
    jump (which keeps each ringing mode's phase) is left to Python between runs; the
    limiter, the haptic force and slew limits and the per-channel offsets run compiled.
    All of it must give the node-by-node render's bits, with every limit active."""
    from jassy.haptics import HapticSafety

    score = contact_score() + [
        Event(0.16, "plate", "set", {"freq_scale": 0.8}, jump=True),
        Event(0.16, "tap", "impact", {"impulse": 0.3, "location": 1}),  # the same frame
        Event(0.17 + 7.5 / FS, "plate", "set", {"decay_scale": 1.0}, jump=True),
    ]
    safety = HapticSafety(max_force=0.6, max_slew=300.0)
    rendered = []
    for program in (False, True):
        graph = contact_graph(gain=50.0)  # loud: the limiter works
        engine = OfflineEngine(
            graph, score, FS, block, haptic_safety=safety, offsets_ms={"haptic": 0.5}, program=program
        )
        assert (engine.program is not None) == program
        rendered.append((engine.render(0.2), engine.haptic_flags, engine.limiter_meter.report(FS)))
    (node, node_flags, node_meter), (compiled, flags, meter) = rendered
    assert node_meter["pinned_frames"] > 0 and node_flags == 6  # clamped and slew-limited
    np.testing.assert_array_equal(compiled.audio, node.audio)
    np.testing.assert_array_equal(compiled.haptic, node.haptic)
    assert (flags, meter) == (node_flags, node_meter)


def test_many_overlapping_strikes_grow_the_pulse_table_between_compiled_runs():
    """Forty strikes inside one 5 ms pulse (the table starts with 16 rows) and more events
    than a run's queue holds (capacity 4096 records, 5000 strikes): the compiled render
    grows the table and the queue before its runs and matches the nodes one by one."""
    score = [
        Event(0.01 + 2.5e-5 * k, "hit", "impact", {"impulse": 1e-4, "location": k % 3}) for k in range(40)
    ]
    score += [Event(0.02 + 1e-5 * k, "hit", "impact", {"impulse": 1e-5}) for k in range(5000)]
    rendered = []
    for program in (False, True):
        hit = ImpactForce(name="hit", duration=0.005)
        plate = ModalBank(plate_model(), name="plate")(hit)
        engine = OfflineEngine(
            Graph(Gain(plate, gain=0.05, name="out"), haptic=hit), score, FS, 64, program=program
        )
        assert (engine.program is not None) == program
        rendered.append(engine.render(0.1))
    assert np.max(np.abs(rendered[0].haptic)) > 40 * 1e-4 * FS / 240  # the pulses overlap
    np.testing.assert_array_equal(rendered[1].audio, rendered[0].audio)
    np.testing.assert_array_equal(rendered[1].haptic, rendered[0].haptic)


def test_nan_in_a_program_graph_is_zeroed_reported_and_its_node_reset():
    """A bank driven to Inf (a gain of 1e308) produces non-finite samples in compiled code:
    they never leave the engine, the render says which node, and the node is reset."""
    hit = ImpactForce(name="hit", duration=0.001)
    bank = ModalBank(plate_model(), name="bank", gain=1e308)(hit)
    engine = OfflineEngine(
        Graph(Gain(bank, gain=1e10, name="out")), [Event(0.01, "hit", "impact", {"impulse": 1.0})], FS, 64
    )
    assert engine.program is not None
    r = engine.render(0.1)
    assert np.all(np.isfinite(r.audio))
    assert any("'bank' produced NaN/Inf" in w or "'out' produced NaN/Inf" in w for w in r.warnings)


def test_a_graph_with_a_node_without_kernel_says_which():
    from ugens.delay import Delay

    tap = ImpactForce(name="tap")
    graph = Graph(Delay(ModalBank(plate_model(), name="plate")(tap), name="echo", time=0.01))
    assert "'echo'" in why_not_compiled(graph)
    engine = OfflineEngine(graph, [], FS, 64)
    assert engine.program is None and "echo" in engine.why_not_program
    assert why_not_compiled(contact_graph()) is None


UNUSED_KINDS_STAY_UNCOMPILED = """
import numpy as np
from jassy import Event, Graph, ModalModel
from jassy.engines.offline import OfflineEngine
from jassy import program
from ugens import Gain, ImpactForce, ModalBank
from ugens import filters, pressure, radiation, scrape

model = ModalModel(np.array([440.0, 1250.0]), np.array([3.0, 8.0]), np.ones((1, 2)))
tap = ImpactForce(name="tap", duration=0.0007)
out = Gain(ModalBank(model, name="bank")(tap), gain=0.5, name="out")
engine = OfflineEngine(Graph(out), [Event(0.01, "tap", "impact", {"impulse": 0.01})], 48000)
assert engine.program is not None
assert np.any(engine.render(0.05).audio != 0)
assert sorted(program._compiled_nodes) == sorted([program.IMPACT, program.MODAL, program.GAIN])
for kernel in (scrape.profile_contact, scrape.resonant_noise, filters.biquad, filters.biquad_ramp,
               radiation.radiate, pressure.sound_pressure):
    assert not kernel.signatures and not kernel.overloads, kernel
"""


def test_a_program_compiles_only_the_kinds_its_graph_holds():
    """A first render compiles the kernels of its own node kinds, not every kind's (in a fresh
    process: this module's other tests compile every kind)."""
    done = subprocess.run(
        [sys.executable, "-c", UNUSED_KINDS_STAY_UNCOMPILED], capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, done.stderr[-2000:]


def test_staged_designs_are_freed_once_the_score_is_applied():
    """A ModalBank's retune stages its design (kept until the compiled run applies it); once
    the queue has drained the staged designs and strike counts are dropped, also when no
    event is left to translate."""
    score = [Event(0.02, "plate", "set", {"freq_scale": 1.1, "decay_scale": 2.0}, ramp=0.01)]
    engine = OfflineEngine(contact_graph(), score, FS, 64, program=True)
    engine.render(0.03)
    assert engine.compiled._designs  # staged in the run that applied it
    engine.render(0.01)
    assert engine.compiled._designs == [] and engine.compiled._strikes == {}
