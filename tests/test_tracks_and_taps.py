"""ContactTrack interpolation to audio rate, per-event ramps, and extra outputs (taps)."""

import numpy as np
import pytest
from helpers import ArraySource

from jassy import ContactTrack, Event, Graph, ModalModel, PatchError, render
from jassy.events import track_events
from jassy.patchfile import build_patch
from ugens.impact import ImpactForce
from ugens.mix import Gain
from ugens.modal import ModalBank

FS = 48000


def test_track_parameter_is_the_linear_interpolation_of_the_track():
    t = np.arange(0.0, 0.6, 0.001) + 0.0123  # 1 kHz physics rate, not on the audio grid
    force = 1.0 + np.sin(2 * np.pi * 3 * t)
    track = ContactTrack((0, 1), t, force, np.zeros_like(t), np.zeros_like(t))
    g = Gain(ArraySource(np.ones(FS)), name="g")
    for block, fs in ((1, FS), (64, FS), (1000, FS), (64, 44100)):
        y = render(
            Graph(g), track_events(track, {"normal_force": ("g", "gain")}), 0.5, fs, block, limiter=False
        ).audio[0]
        # each track sample applies at the first frame at or after its time (parameters move
        # on the sample grid; only impacts keep sub-sample times), and ramps join them linearly
        anchors = np.ceil(t * fs - 1e-6)  # the line through (anchor_i, F_i) and (anchor_i+1, F_i+1)
        frames = np.arange(int(anchors[0]), y.size)
        np.testing.assert_allclose(y[frames], np.interp(frames, anchors, force), atol=1e-9)


def test_location_track_moves_gains_without_steps():
    model = ModalModel([500.0], [1.0], [[1.0], [-1.0]])
    src = ArraySource(np.full(FS, 1000.0))
    bank = ModalBank(model, name="bank")(src)
    t = np.linspace(0.0, 0.2, 201)
    locs = [{"vertices": [0, 1], "weights": [1 - w, w]} for w in np.linspace(0, 1, t.size)]
    track = ContactTrack((0, 1), t, np.zeros_like(t), np.zeros_like(t), np.zeros_like(t), locs)
    render(Graph(bank), track_events(track, {"locations": ("bank", "location")}), 0.1, FS, 64, limiter=False)
    # half way along the track the gain is the barycentric mix, i.e. near zero (0.5 * 1 + 0.5 * -1)
    assert abs(bank.coef[2, 0]) < 0.02 * abs(bank.target[2, 0] if bank.target[2, 0] else 1.0) + 1e-12


def test_event_ramp_overrides_the_smooth_time():
    g = Gain(ArraySource(np.ones(FS)), name="g", smooth=0.001)
    y = render(Graph(g), [Event(0.0, "g", "set", {"gain": 0.0}, ramp=0.1)], 0.2, FS, 64, limiter=False).audio[
        0
    ]
    np.testing.assert_allclose(
        y[: int(0.1 * FS) + 1], 1 - np.arange(0, int(0.1 * FS) + 1) / (0.1 * FS), atol=1e-12
    )
    with pytest.raises(PatchError, match=r"ramp: expected seconds >= 0"):
        render(Graph(g), [Event(0.0, "g", "set", {"gain": 0.0}, ramp=-1.0)], 0.01)


def test_tap_in_a_patch_reads_an_extra_output():
    from jassy.ugen import UGen

    class TwoOut(UGen):
        type_name = "TwoOut"
        outputs = ("double",)

        def process(self, start, n):
            self.out[:n] = 1.0
            self.extra["double"][:n] = 2.0

    from jassy.registry import register

    register(TwoOut)
    patch = build_patch(
        {
            "nodes": {"a": {"type": "TwoOut"}, "g": {"type": "Gain", "input": "a.double"}},
            "outputs": {"audio": ["g"], "haptic": ["a.double"]},
        }
    )
    r = render(patch.graph, [], 0.01, FS, 64, limiter=False)
    assert np.all(r.audio == 2.0) and np.all(r.haptic == 2.0)
    with pytest.raises(PatchError, match=r"nodes\.g\.input: .*no output 'triple'"):
        build_patch(
            {
                "nodes": {"a": {"type": "TwoOut"}, "g": {"type": "Gain", "input": "a.triple"}},
                "outputs": {"audio": ["g"]},
            }
        )


def test_impact_location_forwarding_reaches_banks_downstream():
    model = ModalModel([300.0], [1.0], [[1.0], [0.0]])
    hit = ImpactForce(name="hit")
    bank = ModalBank(model, name="bank")(Gain(hit))
    y = render(
        Graph(bank), [Event(0.0, "hit", "impact", {"impulse": 1.0, "location": 1})], 0.05, FS, limiter=False
    ).audio[0]
    assert np.all(y == 0.0)  # location 1 has zero gain
