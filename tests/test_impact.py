"""ImpactForce: exact impulse, raised-cosine shape, sub-sample onsets, overlaps."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from jassy import Event, Graph, render
from ugens.impact import ImpactForce

FS = 48000


def force(events, seconds=0.05, block=64, **params):
    imp = ImpactForce(name="hit", **params)
    return render(Graph(imp), events, seconds, FS, block, limiter=False).audio[0]


@settings(max_examples=60, deadline=None)
@given(
    t=st.floats(0.0, 0.02),
    impulse=st.floats(1e-6, 10.0),
    tau=st.floats(1e-5, 0.01),
)
def test_time_integral_equals_impulse(t, impulse, tau):
    f = force([Event(t, "hit", "impact", {"impulse": impulse, "duration": tau})], seconds=0.04)
    assert f.sum() / FS == pytest.approx(impulse, rel=1e-12)
    assert np.all(f >= 0)


@settings(max_examples=40, deadline=None)
@given(frac=st.floats(0.0, 0.999), tau_samples=st.floats(2.5, 200.0))
def test_shape_is_raised_cosine_starting_between_samples(frac, tau_samples):
    t0 = 100 + frac  # fractional sample time
    f = force([Event(t0 / FS, "hit", "impact", {"impulse": 1.0, "duration": tau_samples / FS})], seconds=0.01)
    n = np.arange(f.size)
    x = n - t0
    inside = (x > 1e-6) & (x < tau_samples)
    shape = np.where(inside, 1 - np.cos(2 * np.pi * x / tau_samples), 0.0)
    amp = FS / shape.sum()
    np.testing.assert_allclose(f, amp * shape, rtol=1e-9, atol=1e-9 * amp)
    assert np.flatnonzero(f)[0] == math.floor(t0) + 1  # first sample strictly after t0


def test_duration_below_two_samples_is_lengthened_to_two():
    f = force([Event(0.001, "hit", "impact", {"impulse": 1.0, "duration": 1e-7})])
    assert 1 <= np.count_nonzero(f) <= 2
    assert f.sum() / FS == pytest.approx(1.0)


def test_overlapping_impacts_add():
    a = Event(0.0101, "hit", "impact", {"impulse": 0.3, "duration": 0.004})
    b = Event(0.0113, "hit", "impact", {"impulse": 0.7, "duration": 0.002})
    both = force([a, b])
    np.testing.assert_allclose(both, force([a]) + force([b]), atol=1e-9)


def test_many_overlapping_impacts_grow_the_pulse_table():
    events = [
        Event(0.001 + i * 1e-5, "hit", "impact", {"impulse": 1e-3, "duration": 0.005}) for i in range(40)
    ]
    f = force(events)
    assert f.sum() / FS == pytest.approx(40e-3, rel=1e-12)
