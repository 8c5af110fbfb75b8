"""The haptic channel offline: clamp, slew limit, offsets in exact samples, UDP frames."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from jassy import Event, Graph, JassyError, render
from jassy.engines.hapticframes import FLAG_CLAMPED, FLAG_FINAL, decode, encode, parse_address
from jassy.haptics import HapticSafety, channel_delays, limit_force
from ugens.impact import ImpactForce
from ugens.mix import Gain

FS = 48000


@settings(max_examples=50, deadline=None)
@given(
    data=st.lists(
        st.one_of(st.floats(-1e6, 1e6), st.just(float("nan")), st.just(float("inf"))),
        min_size=1,
        max_size=300,
    ),
    max_force=st.floats(0.1, 100.0),
    max_step=st.floats(1e-3, 50.0),
)
def test_clamp_and_slew_limits_always_hold(data, max_force, max_step):
    buf = np.array([data], dtype=np.float64)
    last = np.zeros(1)
    limit_force(buf, buf.shape[1], last, max_force, max_step)
    y = np.concatenate([[0.0], buf[0]])
    assert np.all(np.isfinite(y))
    assert np.all(np.abs(y) <= max_force + 1e-12)
    assert np.all(np.abs(np.diff(y)) <= max_step * (1 + 1e-12))


def test_limits_leave_a_gentle_signal_untouched_and_flag_clamping():
    t = np.arange(4800) / FS
    x = 2.0 * np.sin(2 * np.pi * 5 * t)[None, :]
    buf = x.copy()
    assert limit_force(buf, buf.shape[1], np.zeros(1), 10.0, 1.0) == 0
    np.testing.assert_array_equal(buf, x)
    assert limit_force(x, x.shape[1], np.zeros(1), 1.0, 1.0) & FLAG_CLAMPED


def test_haptic_offset_is_applied_exactly_in_samples():
    hit = ImpactForce(name="hit")
    out = Gain(hit, gain=1e-4, name="out")
    score = [Event(0.1 + 0.3 / FS, "hit", "impact", {"impulse": 0.01})]
    plain = render(Graph(out, haptic=hit), score, 0.3, FS, 64, limiter=False)
    shifted = render(Graph(out, haptic=hit), score, 0.3, FS, 64, limiter=False, offsets_ms={"haptic": 2.0})
    np.testing.assert_array_equal(shifted.audio, plain.audio)
    np.testing.assert_array_equal(shifted.haptic[0, 96:], plain.haptic[0, :-96])
    assert np.flatnonzero(shifted.haptic[0])[0] - np.flatnonzero(shifted.audio[0])[0] == 96
    lead = render(Graph(out, haptic=hit), score, 0.3, FS, 64, limiter=False, offsets_ms={"audio": 2.0})
    assert np.flatnonzero(lead.audio[0])[0] - np.flatnonzero(lead.haptic[0])[0] == 96
    np.testing.assert_array_equal(channel_delays({"audio": -1.0, "haptic": 1.0}, 2, 1, 44100), [0, 0, 88])
    with pytest.raises(JassyError, match="unknown channel kind 'video'"):
        channel_delays({"video": 1.0}, 1, 1, FS)


def test_render_applies_the_safety_limits():
    hit = ImpactForce(name="hit")
    graph = Graph(Gain(hit, gain=1e-4), haptic=hit)
    score = [Event(0.01, "hit", "impact", {"impulse": 0.5})]
    r = render(graph, score, 0.1, FS, haptic_safety=HapticSafety(max_force=5.0, max_slew=2000.0))
    assert np.max(np.abs(r.haptic)) <= 5.0
    assert np.max(np.abs(np.diff(r.haptic[0]))) <= 2000.0 / FS * (1 + 1e-12)
    with pytest.raises(JassyError, match="--max-force"):
        HapticSafety(max_force=0.0)


def test_udp_frame_format_round_trips_and_rejects_bad_datagrams():
    force, torque = np.array([1.5, -2.0, np.nan]), np.array([0.25])
    data = encode(7, 336, 0.123456789, FLAG_CLAMPED | FLAG_FINAL, force, torque, FS)
    assert len(data) == 40 + 4 * 4 and data[:4] == b"JHAP"
    frame = decode(data)
    assert (frame.sequence, frame.sample_time, frame.flags) == (7, 336, FLAG_CLAMPED | FLAG_FINAL)
    assert frame.device_time == 0.123456789 and frame.sample_rate == FS
    np.testing.assert_array_equal(frame.force, [1.5, -2.0, 0.0])  # NaN never leaves the engine
    np.testing.assert_array_equal(frame.torque, [0.25])
    with pytest.raises(JassyError, match="expected at least 40"):
        decode(b"short")
    with pytest.raises(JassyError, match="version 2"):
        decode(b"XXXX" + data[4:])
    with pytest.raises(JassyError, match="do not hold"):
        decode(data[:-4])
    with pytest.raises(JassyError, match="HOST:PORT"):
        parse_address("nowhere")
