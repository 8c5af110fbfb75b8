"""Sample-accurate scheduling: block-size invariance, exact onsets, smoothing."""

import numpy as np
import pytest
from helpers import ArraySource, max_abs_diff

from jassy import Event, Graph, ModalModel, PatchError, render
from jassy.patchfile import load_patch
from ugens.impact import ImpactForce
from ugens.mix import Gain, Mixer
from ugens.modal import ModalBank

FS = 48000
BLOCKS = (1, 64, 1000)


def busy_graph_and_score(seed=0, seconds=1.5):
    """Two banks, many impacts at random sub-sample times and locations, smoothed and jump
    parameter changes on several nodes."""
    rng = np.random.default_rng(seed)
    model = ModalModel(
        np.geomspace(80, 15000, 60),
        np.geomspace(0.5, 300, 60),
        rng.uniform(-1, 1, (4, 60)),
        ("a", "b", "c", "d"),
    )
    hit = ImpactForce(name="hit", duration=0.0005)
    tap = ImpactForce(name="tap", duration=0.002)
    b1 = ModalBank(model, name="b1")(hit)
    b2 = ModalBank(model, name="b2", freq_scale=0.7)(tap)
    mix = Mixer(Gain(b1, name="g1", gain=0.5), Gain(b2, name="g2", gain=0.5), name="mix")
    graph = Graph(mix, haptic=[hit, tap])
    score = []
    for _ in range(150):
        t = float(rng.uniform(0, seconds))
        node = str(rng.choice(["hit", "tap"]))
        w = rng.dirichlet([1, 1, 1])
        loc = {
            "vertices": [int(v) for v in rng.choice(4, 3, replace=False)],
            "weights": [float(x) for x in w],
        }
        score.append(Event(t, node, "impact", {"impulse": float(rng.uniform(0.01, 0.2)), "location": loc}))
    for _ in range(40):
        t = float(rng.uniform(0, seconds))
        kind = rng.integers(4)
        if kind == 0:
            score.append(
                Event(t, "g1", "set", {"gain": float(rng.uniform(0, 1))}, jump=bool(rng.integers(2)))
            )
        elif kind == 1:
            score.append(Event(t, "b1", "set", {"freq_scale": float(rng.uniform(0.5, 1.3))}))
        elif kind == 2:
            score.append(Event(t, "b2", "set", {"decay_scale": float(rng.uniform(0.5, 3))}, jump=True))
        else:
            score.append(Event(t, "b2", "set", {"location": "c", "gain": float(rng.uniform(0.5, 2))}))
    return graph, score


@pytest.mark.parametrize("seed", [0, 1])
def test_block_sizes_1_64_1000_render_the_same(seed):
    graph, score = busy_graph_and_score(seed)
    outs = [render(graph, score, 1.5, FS, b, limiter=False) for b in BLOCKS]
    scale = np.max(np.abs(outs[0].audio))
    assert scale > 0.01
    for other in outs[1:]:
        assert max_abs_diff(outs[0].audio, other.audio) < 1e-6
        assert max_abs_diff(outs[0].haptic, other.haptic) < 1e-6


def test_builtin_patches_are_block_size_invariant():
    for name in ("bell", "bar"):
        patch = load_patch(name)
        outs = [render(patch.graph, patch.score, 2.5, FS, b).audio for b in BLOCKS]
        assert max_abs_diff(outs[0], outs[1]) < 1e-6
        assert max_abs_diff(outs[0], outs[2]) < 1e-6


@pytest.mark.parametrize("block", BLOCKS)
@pytest.mark.parametrize("t", [0.0, 0.01, 480.5 / FS, 12345.999 / FS])
def test_rendered_onset_equals_requested_onset(block, t):
    hit = ImpactForce(name="hit", duration=0.001)
    f = render(
        Graph(hit), [Event(t, "hit", "impact", {"impulse": 1.0})], 0.5, FS, block, limiter=False
    ).audio[0]
    first = np.flatnonzero(f)[0]
    # the pulse is zero at t itself; its first non-zero sample is the first frame after t
    assert first == int(np.floor(t * FS + 1e-6)) + 1


def test_parameter_change_is_a_linear_ramp_from_the_event_sample():
    one = ArraySource(np.ones(FS))
    g = Gain(one, gain=1.0, name="g", smooth=0.01)
    t = 0.1 + 0.3 / FS
    y = render(Graph(g), [Event(t, "g", "set", {"gain": 0.0})], 0.2, FS, 64, limiter=False).audio[0]
    start = int(np.ceil(t * FS))  # first frame at or after the event
    ramp = int(round(0.01 * FS))
    assert np.all(y[:start] == 1.0)
    expected = 1.0 - np.arange(0, ramp + 1) / ramp  # the line through (start, 1) and (start + ramp, 0)
    np.testing.assert_allclose(y[start : start + ramp + 1], expected, atol=1e-12)
    assert np.all(y[start + ramp :] == 0.0)


def test_jump_applies_at_the_event_sample():
    g = Gain(ArraySource(np.ones(FS)), gain=1.0, name="g")
    y = render(
        Graph(g), [Event(0.05, "g", "set", {"gain": 0.25}, jump=True)], 0.1, FS, 1000, limiter=False
    ).audio[0]
    k = int(round(0.05 * FS))
    assert np.all(y[:k] == 1.0) and np.all(y[k:] == 0.25)


def test_inline_events_apply_at_their_frame_without_splitting_the_sub_block():
    """Impacts and location jumps (inline events) land mid-block at their exact frame while
    a continuous force drives the bank; only the event on a Gain (not inline) splits."""
    model = ModalModel([300.0, 1700.0], [4.0, 9.0], [[1.0, 0.2], [0.1, 1.5]], ("a", "b"))
    n = 4000
    drive = ArraySource(np.sin(2 * np.pi * 50 * np.arange(n) / FS), name="drive")
    hit = ImpactForce(name="hit", duration=0.001)
    bank = ModalBank(model, name="bank")(Mixer(drive, hit, name="force"))
    out = Gain(bank, name="g")
    score = [
        Event(1234.25 / FS, "bank", "set", {"location": "b"}, jump=True),
        Event(1500.5 / FS, "hit", "impact", {"impulse": 0.1, "location": "a"}),
        Event(2100.0 / FS, "bank", "set", {"gain": 0.5}),
        Event(3333.7 / FS, "g", "set", {"gain": 0.5}, jump=True),
    ]
    calls = []
    counted = out.process

    def process(start, count):
        calls.append((start, count))
        counted(start, count)

    out.process = process
    whole = render(Graph(out), score, n / FS, FS, 1000, limiter=False).audio[0]
    assert calls == [(0, 1000), (1000, 1000), (2000, 1000), (3000, 334), (3334, 666)]
    calls.clear()
    framewise = render(Graph(out), score, n / FS, FS, 1, limiter=False).audio[0]
    assert len(calls) == n
    assert np.max(np.abs(whole)) > 1e-4
    assert max_abs_diff(whole, framewise) < 1e-12 * np.max(np.abs(whole))


def test_rendering_twice_gives_the_same_result():
    graph, score = busy_graph_and_score(2, 0.5)
    a = render(graph, score, 0.5, FS, 64).audio
    b = render(graph, score, 0.5, FS, 64).audio
    np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize(
    "event, match",
    [
        (Event(-1.0, "hit", "impact", {}), r"score\[0\]\.time"),
        (Event(0.0, "nope", "impact", {}), r"score\[0\]\.node: unknown node 'nope'"),
        (Event(0.0, "hit", "explode", {}), r"no action 'explode'"),
        (Event(0.0, "hit", "impact", {"impulse": "big"}), r"impact\.impulse: expected a number"),
        (Event(0.0, "hit", "impact", {"force": 1.0}), r"impact\.force: unknown argument"),
        (Event(0.0, "g", "set", {"gian": 1.0}), r"set\.gian: Gain has no parameter"),
        (Event(0.0, "g", "set", {"smooth": 1.0}), r"cannot change during a render"),
        (Event(0.0, "hit", "impact", {"location": 7}), r"vertex 7 out of range"),
    ],
)
def test_bad_events_are_rejected_before_rendering(event, match):
    model = ModalModel([440.0], [1.0], [[1.0]])
    hit = ImpactForce(name="hit")
    g = Gain(ModalBank(model, name="bank")(hit), name="g")
    with pytest.raises(PatchError, match=match):
        render(Graph(g), [event], 0.01)


def track_graph():
    """A bank on a three-point track (t0, t0_1, t1) struck by a hammer."""
    gains = np.array([[1.0, 0.5, 0.2], [0.5, 1.0, 0.4], [0.2, 0.4, 1.0]])
    model = ModalModel([300.0, 900.0, 2000.0], [3.0, 5.0, 8.0], gains, ("t0", "t0_1", "t1"))
    hit = ImpactForce(name="hit", duration=0.001)
    bank = ModalBank(model, name="bank", location="t0")(hit)
    return Graph(bank, haptic=hit), bank


def test_a_prepared_score_is_reused_only_for_the_same_score_rate_and_parameters():
    from jassy.scheduler import prepare_score

    def fresh(score, rate):
        return prepare_score(track_graph()[0], score, rate)

    graph, bank = track_graph()
    score = [
        Event(0.01, "hit", "impact", {"impulse": 0.1}),
        Event(0.02, "bank", "set", {"location": "t1"}, ramp=0.013),
    ]
    first = prepare_score(graph, score, FS)
    assert len(first) == 3  # the ramp walks through t0_1
    again = prepare_score(graph, score, FS)
    assert again == first and again is not first
    # the walk's links land on the frames of the rate: another rate, other times
    assert prepare_score(graph, score, 44100) == fresh(score, 44100) != first
    score[1].args["location"] = "t0_1"  # an event changed in place: no walk now
    assert prepare_score(graph, score, FS) == fresh(score, FS)
    assert len(prepare_score(graph, score, FS)) == 2
    score[0].args["impulse"] = 1
    prepare_score(graph, score, FS)
    score[0].args["impulse"] = True  # equal to 1, but no number: compared with its type
    with pytest.raises(PatchError, match=r"score\[0\]"):
        prepare_score(graph, score, FS)
    score[0].args["impulse"] = 0.1
    prepare_score(graph, score, FS)
    # a node given another model: its locations are validated again
    bank.configure("model", ModalModel([300.0], [3.0], np.array([[1.0]]), ("t0",)))
    with pytest.raises(PatchError, match=r"score\[1\].*unknown point 't0_1'"):
        prepare_score(graph, score, FS)
