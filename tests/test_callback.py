"""The callback renderer (the graph's program run buffer by buffer, events from SPSC queues)
hands the device the offline rendering sample for sample, and a tap's sound and force
start on the same frame there, at device buffers of 1, 64 and 4096 frames. Driven here
without a device (the PortAudio callback only wraps :func:`render_into`); tests/test_live.py
plays it on a JACK dummy server."""

import numpy as np
import pytest
from test_program import contact_graph, contact_score

from jassy import Event, Graph
from jassy.engines.callback import CallbackRenderer, choose_mode, render_into, why_not_callback
from jassy.engines.offline import OfflineEngine
from jassy.errors import JassyError
from jassy.haptics import HapticSafety
from ugens import Gain, ImpactForce, ModalBank
from ugens.delay import Delay

FS = 48000


def play(renderer, frames, block):
    """What the device would receive over ``frames`` frames in buffers of ``block``."""
    out = np.zeros(frames * renderer.channels, np.float32)
    pos = 0
    while pos < frames:
        renderer.feed(int(0.25 * FS))  # the feeder thread's job, a buffer at a time here
        m = min(block, frames - pos)
        render_into(renderer.control, out[pos * renderer.channels :], m)
        pos += m
    return out.reshape(-1, renderer.channels).T


@pytest.mark.parametrize("block", [1, 64, 4096])
def test_the_device_receives_the_offline_rendering(block):
    seconds = 0.2 if block > 1 else 0.05
    renderer = CallbackRenderer(contact_graph(), contact_score(), FS, block)
    heard = play(renderer, int(seconds * FS), block)
    ref = OfflineEngine(contact_graph(), contact_score(), FS, block, haptic_safety=HapticSafety()).render(
        seconds
    )
    assert np.any(heard[0] != 0) and np.any(heard[1] != 0)
    np.testing.assert_array_equal(heard[0], ref.audio[0].astype(np.float32))
    np.testing.assert_array_equal(heard[1], ref.haptic[0].astype(np.float32))


@pytest.mark.parametrize("block", [1, 64, 4096])
def test_a_taps_sound_and_force_reach_the_device_on_the_same_frame(block):
    hit = ImpactForce(name="hit", duration=0.001)
    graph = Graph(
        Gain(ModalBank(contact_graph().nodes["plate"].model, name="bank")(hit), gain=0.1), haptic=hit
    )
    t = 0.01 + 17.4 / FS
    renderer = CallbackRenderer(graph, [Event(t, "hit", "impact", {"impulse": 0.01})], FS, block)
    heard = play(renderer, int(0.02 * FS), block)
    sound, force = np.flatnonzero(heard[0]), np.flatnonzero(heard[1])
    assert sound[0] == force[0] == int(np.floor(t * FS)) + 1


def test_posted_events_apply_at_the_next_buffer():
    hit = ImpactForce(name="hit", duration=0.001)
    renderer = CallbackRenderer(Graph(Gain(hit, gain=0.0), haptic=hit), [], FS, 64)
    play(renderer, 640, 64)
    stamped = renderer.post(Event(0.0, "hit", "impact", {"impulse": 0.01}))
    assert stamped == 640
    heard = play(renderer, 128, 64)
    assert np.flatnonzero(heard[1])[0] == 1  # the pulse's first non-zero frame: 641


def test_a_strike_stamped_with_a_frame_already_played_plays_whole_at_once():
    """A poster preempted between reading the frame and pushing (a loaded machine) stamps
    a frame the callback has played meanwhile: the pulse then starts at the next frame,
    whole, instead of being cut short or, a pulse length late, lost."""
    hit = ImpactForce(name="hit", duration=0.001)
    graph = Graph(Gain(hit, gain=0.0), haptic=hit)
    on_time, late = CallbackRenderer(graph, [], FS, 64), CallbackRenderer(graph, [], FS, 64)
    play(on_time, 640, 64)
    play(late, 840, 64)  # 200 frames (4 pulse lengths) played while the poster was away
    late.frame = lambda: 640  # the frame it read before it was preempted
    assert on_time.post(Event(0.0, "hit", "impact", {"impulse": 0.01})) == 640
    assert late.post(Event(0.0, "hit", "impact", {"impulse": 0.01})) == 640
    expected, heard = play(on_time, 128, 64)[1], play(late, 128, 64)[1]
    assert np.flatnonzero(heard)[0] == 1  # frame 841: the first after the one it was applied at
    np.testing.assert_array_equal(heard, expected)  # the whole pulse, shifted by 200 frames
    assert (late.stats().late_strikes, on_time.stats().late_strikes) == (1, 0)


def test_mode_falls_back_to_the_ring_and_says_why():
    hit = ImpactForce(name="hit")
    delayed = Graph(Delay(hit, name="echo", time=0.01), haptic=hit)
    mode, reason = choose_mode("auto", delayed, [], None, None)
    assert mode == "ring" and "'echo'" in reason
    graph = contact_graph()
    assert choose_mode("auto", graph, contact_score(), None, None) == ("callback", None)
    assert "offsets" in why_not_callback(graph, [], {"haptic": 2.0}, None)
    assert "UDP" in why_not_callback(graph, [], None, "127.0.0.1:9000")
    with pytest.raises(JassyError, match="callback mode: .*echo"):
        choose_mode("callback", delayed, [], None, None)
