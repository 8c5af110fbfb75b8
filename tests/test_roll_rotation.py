"""Rolling with rotation: the sound of a ball turning at v / (2 pi r).

Steady rolls of the ``roll`` patch's 30 mm ball on its steel plate, rendered at a few
speeds; the audio envelope's strongest modulation (5 ms RMS frames, after the plate has
built up) against the closed form v / (2 pi r), and the spectral centroid over speeds 10 %
apart (no step larger than 30 %).
"""

import math

import numba as nb
import numpy as np
import pytest

from jassy import Event, render
from jassy.patchfile import load_patch
from ugens.driving_point import free_motion, press

FS = 48000
RADIUS = 0.015
SETTLE = 1.0  # s: the plate's energy builds up over 1 / (2 d) ~ 0.3 s


def steady_roll(speed, seconds, overrides=()):
    """Audio of the patch's ball rolling at ``speed`` from t = 0, after SETTLE s."""
    patch = load_patch("roll", overrides=list(overrides))
    events = [
        Event(0.0, "ball", "set", {"force": 1.08, "speed": speed}, jump=True),
        Event(0.0, "hops", "set", {"speed": speed}, jump=True),
    ]
    return render(patch.graph, events, SETTLE + seconds, FS, 256, limiter=False).audio[0][int(SETTLE * FS) :]


def envelope_peak(x, f_max):
    """Frequency (Hz) of the strongest modulation of the 5 ms RMS envelope in (0.5, f_max)."""
    hop = 240
    env = np.sqrt(np.mean(x[: x.size // hop * hop].reshape(-1, hop) ** 2, axis=1))
    env = env - env.mean()
    n = 1 << 16
    spec = np.abs(np.fft.rfft(env * np.hanning(env.size), n))
    f = np.fft.rfftfreq(n, hop / FS)
    band = np.flatnonzero((f > 0.5) & (f < f_max))
    return f[band[np.argmax(spec[band])]]


def centroid(x):
    spec = np.abs(np.fft.rfft(x * np.hanning(x.size))) ** 2
    return (spec * np.fft.rfftfreq(x.size, 1 / FS)).sum() / spec.sum()


def rotation_errors(speeds, overrides=()):
    errors = []
    for v in speeds:
        f_rot = v / (2 * math.pi * RADIUS)
        x = steady_roll(v, max(6 / f_rot, 2.0), overrides)
        errors.append(envelope_peak(x, 3 * f_rot + 3) / f_rot - 1)
    return np.array(errors)


def test_rolling_force_pulses_at_the_rotation_rate():
    """The continuous layer (Roll: the ball's own profile, one revolution long, and its
    out-of-roundness, under the contact filter) on the plate, alone, up to 1 m/s. (At 1.4
    m/s its envelope peaks at 3 v / (2 pi r): its lines are 15 Hz apart and most of its
    force lies near the ball's contact resonance, 1-2 kHz, where each of the plate's few
    strong modes picks one line, so the envelope follows their beats rather than the
    out-of-roundness's sidebands; the patch there is its micro-impacts, about 30 dB louder.)"""
    errors = rotation_errors([0.1, 0.3, 0.6, 1.0], ["contact.gains=[1.0, 0.0]"])
    assert np.max(np.abs(errors)) < 0.05, errors


def test_patch_pulses_at_the_rotation_rate_over_its_speeds():
    """The whole patch (with the micro-impacts) over the speeds it plays (up to 0.6 m/s)."""
    errors = rotation_errors([0.1, 0.3, 0.6])
    assert np.max(np.abs(errors)) < 0.05, errors


def test_patch_pulses_at_the_rotation_rate_up_to_2_m_s():
    """Where the micro-impacts dominate: their pattern repeats every turn (RathRoll reads
    the ball's own surface, one turn at a time)."""
    errors = rotation_errors([1.0, 2.0])
    assert np.max(np.abs(errors)) < 0.05, errors


def test_centroid_changes_smoothly_with_speed():
    """The micro-impacts reach the plate through the ball's contact spring and the plate
    gives way (RathRoll with the plate's model): a line or a burst of hops that lands on a
    lightly damped mode no longer drives it as if the plate were rigid."""
    speeds = 0.1 * 1.1 ** np.arange(32)  # 0.1 .. 1.9 m/s, 10 % apart
    c = np.array([centroid(steady_roll(v, 0.5)) for v in speeds])
    steps = np.maximum(c[1:] / c[:-1], c[:-1] / c[1:])
    assert np.max(steps) < 1.3, (speeds[np.argmax(steps)], np.max(steps))


@pytest.mark.timeout(300)
@pytest.mark.parametrize("seed", ["ball.seed=1", "hops.seed=2", "hops.seed=4"])
def test_centroid_changes_smoothly_over_other_profiles(seed):
    """Other profiles of the ball (the rumble's ``ball.seed``, the micro-impacts' ``hops.seed``)
    at the slow speeds where the layers are closest in level (0.1-0.16 m/s, 10 % apart).
    The rumble drove the plate open loop: a line of its turn's spectrum landing on one of the
    plate's few strong low modes raised its power by up to 10 dB between neighbouring speeds,
    and the patch's centroid with it (1.43x, 1.60x, 1.81x here). Under the contact filter
    the rumble grows with speed as the ball's inertia m w^2 r does, and sits lower there."""
    speeds = 0.1 * 1.1 ** np.arange(6)
    c = np.array([centroid(steady_roll(v, 0.5, [seed])) for v in speeds])
    steps = np.maximum(c[1:] / c[:-1], c[:-1] / c[1:])
    assert np.max(steps) < 1.3, (speeds[np.argmax(steps)], np.max(steps))


@nb.njit  # not cached: its cache would keep an old copy of the inlined press
def pressed(out, contact, n, modes, scratch, stiffness, gain_sum):
    """out[:n] through ``press``, one sample at a time, the spring acting while contact > 0."""
    for i in range(n):
        free = free_motion(modes, scratch, 0.0)
        f = press(modes, scratch, free, out[i], stiffness if contact[i] > 0.0 else 0.0, gain_sum)
        contact[i] += f - out[i]
        out[i] = f


def test_surface_that_gives_way_caps_the_force_at_resonance():
    """press against the z-transform of its loop: a sine force k h through a spring k onto
    one mode (ModalBank's recursion) settles at |k h / (1 + k H(e^{jw}))|, H(z) = g / (1 -
    c1 z^-1 + c2 z^-2) (no delay in the loop); at the mode's resonance that is far below k h.
    Where the ball is off the surface (contact <= 0) the force passes unchanged."""
    from ugens.modal import design

    f0, decay, a, k = 440.0, 4.0, 2e-3, 1e5  # Hz, 1/s, m per N s, N/m
    c1, c2, s = design(np.array([f0]), np.array([decay]), FS)
    g = s / FS * a
    n = 3 * FS
    t = np.arange(n) / FS
    for f in (f0, 1.37 * f0):
        w = 2 * math.pi * f
        modes = np.array([c1, c2, g, [0.0], [0.0]])
        out = np.sin(w * t)
        contact = np.ones(n)
        pressed(out, contact, n, modes, np.zeros(1), k, float(g[0]))
        z = np.exp(-1j * w / FS)
        expected = 1.0 / abs(1.0 + k * g[0] / (1.0 - c1[0] * z + c2[0] * z * z))
        tail = slice(2 * FS, n)  # the loop's transient has decayed (e^-8)
        basis = np.stack([np.sin(w * t[tail]), np.cos(w * t[tail])], axis=1)
        amplitude = np.hypot(*np.linalg.lstsq(basis, out[tail], rcond=None)[0])
        assert amplitude == pytest.approx(expected, rel=1e-6), f
        assert np.allclose(contact - 1.0, out - np.sin(w * t))  # contact moves with the force
    assert expected > 0.5  # off resonance the surface hardly gives way ...
    on = 1.0 / abs(1.0 + k * a / (2.0 * decay))  # ... at resonance: receptance a / (2 d) >> 1 / k
    assert on < 0.05

    free = np.sin(np.arange(100) * 0.1)
    out = free.copy()
    pressed(out, np.zeros(100), 100, np.array([c1, c2, g, [0.3], [0.2]]), np.zeros(1), k, float(g[0]))
    np.testing.assert_array_equal(out, free)


def test_rolling_contact_filter_against_its_z_transform():
    """roll_over: a sine roughness r under a ball of mass m on a spring k with a dashpot c,
    on one mode (ModalBank's recursion), settles at |F| = |K r / (1 + K (B + H))| per
    unit r, K(z) = k + c fs (1 - z^-1), B(z) = 1 / (m fs^2 (1 - z^-1)^2) the ball's
    impulse-invariant mass, H(z) the mode's recursion. In the continuous limit this is the
    rolling contact filter 1 / (1/k - 1/(m w^2) + alpha(w)): far below the contact
    resonance the force is the ball's inertia m w^2 r."""
    from ugens.driving_point import roll_over
    from ugens.modal import design

    f0, decay, a = 300.0, 40.0, 2e-4  # the mode: Hz, 1/s, m per N s
    m, k, c = 0.11, 1.1e7, 300.0  # kg, N/m, N s/m
    c1, c2, s = design(np.array([f0]), np.array([decay]), FS)
    g = s / FS * a
    n = 2 * FS
    t = np.arange(n) / FS
    for f in (80.0, f0, 2500.0):
        w = 2 * math.pi * f
        out = np.sin(w * t)  # r = out * inv_height with inv_height = 1
        modes = np.array([c1, c2, g, [0.0], [0.0]])
        law = np.array([k, c, FS])
        roll_over(
            out, np.ones(n), n, modes, np.zeros(1), np.zeros(3), law, 1.0, 1.0 / (m * FS**2), float(g[0])
        )
        z = np.exp(-1j * w / FS)
        K = k + c * FS * (1 - z)
        B = 1.0 / (m * FS**2 * (1 - z) ** 2)
        H = g[0] / (1.0 - c1[0] * z + c2[0] * z * z)
        expected = abs(K / (1.0 + K * (B + H)))
        tail = slice(n - FS // 2, n)
        basis = np.stack([np.sin(w * t[tail]), np.cos(w * t[tail])], axis=1)
        amplitude = np.hypot(*np.linalg.lstsq(basis, out[tail], rcond=None)[0])
        assert amplitude == pytest.approx(expected, rel=1e-4), f
        if f == 80.0:  # below the contact resonance (1.6 kHz): the ball's inertia, m w^2
            assert amplitude == pytest.approx(m * w * w, rel=0.05)
    out = np.sin(np.arange(100) * 0.1)  # lifted off (no load): no contact force
    roll_over(
        out, np.zeros(100), 100, modes, np.zeros(1), np.zeros(3), law, 1.0, 1.0 / (m * FS**2), float(g[0])
    )
    assert np.all(out == 0.0)


def test_rolling_contact_returns_without_drift():
    """roll_over: while the load is off the ball rides on the surface (no drift at its last
    speed), so when a ramped load returns the contact force is back at its steady level at
    once (a ball drifting at w r for 0.1 s would hit with k w r 0.1 s, thousands of times
    it)."""
    from ugens.driving_point import roll_over
    from ugens.modal import design

    f0, decay, a = 300.0, 40.0, 2e-4  # the surface's mode: Hz, 1/s, m per N s
    m, k, c = 0.11, 1.1e7, 300.0  # kg, N/m, N s/m
    c1, c2, s = design(np.array([f0]), np.array([decay]), FS)
    g = s / FS * a
    n = FS
    w = 2 * math.pi * 80.0
    off, on, ramp = int(0.3 * FS), int(0.4 * FS), int(0.02 * FS)
    load = np.ones(n)  # N
    load[off - ramp : off] = np.linspace(1.0, 0.0, ramp)
    load[off:on] = 0.0
    load[on : on + ramp] = np.linspace(0.0, 1.0, ramp)
    out = 1e-6 * np.sin(w * np.arange(n) / FS)  # m of roughness
    modes = np.array([c1, c2, g, [0.0], [0.0]])
    law = np.array([k, c, FS])
    roll_over(out, load, n, modes, np.zeros(1), np.zeros(3), law, 1.0, 1.0 / (m * FS**2), float(g[0]))
    steady = np.abs(out[int(0.2 * FS) : off - ramp]).max()
    assert steady == pytest.approx(m * w * w * 1e-6, rel=0.1)  # below the contact resonance
    assert np.abs(out[on:]).max() < 1.2 * steady
    assert np.all(out[off:on] == 0.0)


def test_roll_with_a_model_needs_a_positive_stiffness():
    """The output over ``stiffness`` is the roughness the contact filter reads: 0 is refused
    in one line naming the key, not a ZeroDivisionError in the first block."""
    from jassy.errors import PatchError

    patch = load_patch("roll", overrides=["ball.stiffness=0.0"])
    with pytest.raises(PatchError, match=r"nodes\.ball\.stiffness: expected > 0 with a model"):
        render(patch.graph, [], 0.01, FS, 256, limiter=False)
