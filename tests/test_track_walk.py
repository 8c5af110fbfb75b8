"""A contact moving along a texture track: gains follow the track's points, not a blend of
the ramp's two ends.

The truth: a model whose gains along the track are sampled from known functions of the
track coordinate s; gains in between are the linear interpolation of those samples
(np.interp over coordinates written here from the naming rule: t{i} at s = i, t{i}_{j} at
i + j / (m + 1)). A bank struck repeatedly while its location ramps is linear in its input
gains and keeps its poles, so its output is the closed-form modal response
sum_k G_k(s) f[m] / fs e^{-d_k t} sin(2 pi f_k t) of each force sample f[m], with G_k taken
where the contact is when that sample enters the bank (one frame later), plus the bank's
same-sample (Euler-Maclaurin) term f[m] sum_k G_k 2 pi f_k / (12 fs^2).
"""

import numpy as np
import pytest

from jassy import Event
from jassy.engines.offline import OfflineEngine
from jassy.graph import Graph
from jassy.modal_model import Location, ModalModel
from ugens.impact import ImpactForce
from ugens.modal import ModalBank

FS = 16000
BETWEEN = 3  # points between t{i} and t{i+1}
NAMED = 3  # t0, t1, t2
FREQS = np.array([310.0, 770.0, 1330.0, 2150.0, 3020.0, 4410.0])
DECAYS = np.array([3.0, 4.0, 6.0, 8.0, 11.0, 15.0])


def coordinates_and_names():
    names, coords = [f"t{i}" for i in range(NAMED)], [float(i) for i in range(NAMED)]
    for i in range(NAMED - 1):
        for j in range(1, BETWEEN + 1):
            names.append(f"t{i}_{j}")
            coords.append(i + j / (BETWEEN + 1))
    return np.array(coords), names


def shape(s):
    """Gains (points x modes) at track coordinates s: sinusoids of the coordinate."""
    k = np.arange(1, FREQS.size + 1)
    return np.cos(np.outer(s, k) * 1.3 + k) * (1.0 + 0.2 * k)


def model():
    coords, names = coordinates_and_names()
    return ModalModel(FREQS, DECAYS, shape(coords), tuple(names), "track test")


def gains_along(s):
    """Linear interpolation of the stored points' gains at coordinates s (the truth)."""
    coords, _ = coordinates_and_names()
    order = np.argsort(coords)
    rows = shape(coords)[order]
    return np.stack([np.interp(s, coords[order], rows[:, k]) for k in range(FREQS.size)], axis=1)


def graph():
    mallet = ImpactForce(name="mallet", duration=0.001)
    bank = ModalBank(model(), name="bank", location="t0")(mallet)
    return Graph(bank, haptic=mallet)


def expected(force, position):
    """Closed-form output of the bank for ``force`` with the contact at ``position`` (s per
    frame)."""
    n = force.size
    t = np.arange(n) / FS
    out = np.zeros(n)
    for m in np.flatnonzero(force):
        g = gains_along(np.array([position[min(m + 1, n - 1)]]))[0]
        tt = t[: n - m - 1] + 1 / FS
        modes = np.exp(-np.outer(tt, DECAYS)) * np.sin(2 * np.pi * np.outer(tt, FREQS))
        out[m + 1 :] += force[m] / FS * modes @ g
        here = gains_along(np.array([position[m]]))[0]
        out[m] += force[m] * (here @ (2 * np.pi * FREQS)) / (12 * FS**2)  # the bank's direct term
    return out


def strikes(times):
    return [Event(t, "mallet", "impact", {"impulse": 0.01}) for t in times]


def positions(n, walks):
    """s per frame from s = 0: ``walks`` = [(start frame, end frame, goal)], each from where
    the contact is at its start, linear in frames."""
    s = np.zeros(n)
    frames = np.arange(n)
    for start, end, goal in walks:
        origin = s[start]
        s[start:] = origin + (goal - origin) * np.clip((frames[start:] - start) / (end - start), 0, 1)
    return s


@pytest.mark.parametrize("program", [True, False])
def test_a_ramp_walks_the_track_points(program):
    duration = 0.5
    n = int(duration * FS)
    score = [Event(0.05, "bank", "set", {"location": "t2"}, ramp=0.3), *strikes(np.arange(0.02, 0.48, 0.037))]
    engine = OfflineEngine(graph(), score, FS, 64, limiter=False, program=program)
    assert (engine.program is not None) == program
    out = engine.render(duration)
    force = out.haptic[0]
    truth = expected(force, positions(n, [(800, 5600, 2.0)]))
    error = np.max(np.abs(out.audio[0] - truth)) / np.max(np.abs(truth))
    assert error < 1e-9, error
    # the old behaviour, a blend of the two end rows, is far from it
    blend = np.clip((np.arange(n) - 800) / 4800, 0, 1)
    crossfade = np.zeros(n)
    for m in np.flatnonzero(force):
        g = shape(np.array([0.0, 2.0]))
        w = blend[min(m + 1, n - 1)]
        tt = np.arange(1, n - m) / FS
        modes = np.exp(-np.outer(tt, DECAYS)) * np.sin(2 * np.pi * np.outer(tt, FREQS))
        crossfade[m + 1 :] += force[m] / FS * modes @ ((1 - w) * g[0] + w * g[1])
    assert np.max(np.abs(crossfade - truth)) / np.max(np.abs(truth)) > 0.1


def test_a_new_location_stops_a_walk_and_starts_where_the_contact_is():
    duration = 0.5
    n = int(duration * FS)
    score = [
        Event(0.05, "bank", "set", {"location": "t2"}, ramp=0.3),
        Event(0.25, "bank", "set", {"location": "t0_1"}, ramp=0.1),
        *strikes(np.arange(0.02, 0.48, 0.031)),
    ]
    out = OfflineEngine(graph(), score, FS, 64, limiter=False).render(duration)
    truth = expected(out.haptic[0], positions(n, [(800, 5600, 2.0), (4000, 5600, 0.25)]))
    error = np.max(np.abs(out.audio[0] - truth)) / np.max(np.abs(truth))
    assert error < 1e-3, error  # the walk back reaches each point at the nearest frame


def test_a_location_on_the_track_is_the_point_at_its_mean_coordinate():
    m = model()
    far = Location(("t0", "t1"), (0.5, 0.5))  # not neighbours: t0_1 .. t0_3 lie between
    assert np.allclose(m.gains_at(far), gains_along(np.array([0.5]))[0], rtol=0, atol=1e-12)
    assert np.allclose(m.gains_at(far), m.gains_at("t0_2"), rtol=0, atol=1e-12)
    near = Location(("t1_2", "t1_3"), (0.25, 0.75))  # neighbours: their blend, bit for bit
    rows = m.gains[[m.points.index("t1_2"), m.points.index("t1_3")]]
    assert np.array_equal(m.gains_at(near), 0.25 * rows[0] + 0.75 * rows[1])
    assert np.allclose(m.gains_at(near), gains_along(np.array([1 + 2.75 / 4]))[0], rtol=0, atol=1e-12)


def test_models_without_a_track_keep_barycentric_blends():
    m = ModalModel(FREQS, DECAYS, shape(np.array([0.0, 1.0, 2.0])), ("p0", "p1", "p2"))
    assert m.track is None
    loc = Location(("p0", "p2"), (0.5, 0.5))
    assert np.array_equal(m.gains_at(loc), 0.5 * m.gains[0] + 0.5 * m.gains[2])


def test_the_device_walks_as_the_offline_render():
    from test_callback import play

    from jassy.engines.callback import CallbackRenderer
    from jassy.haptics import HapticSafety

    score = [
        Event(0.01, "bank", "set", {"location": "t2"}, ramp=0.1),
        *strikes(np.arange(0.005, 0.15, 0.013)),
    ]
    renderer = CallbackRenderer(graph(), score, FS, 64)
    heard = play(renderer, int(0.15 * FS), 64)
    ref = OfflineEngine(graph(), score, FS, 64, haptic_safety=HapticSafety()).render(0.15)
    assert np.any(heard[0] != 0)
    np.testing.assert_array_equal(heard[0], ref.audio[0].astype(np.float32))
