"""Signed modal gains in the closed-loop contacts: the loop runs on the driving-point gains
phi(c)^2 / M, the main output on the signed strike-to-pickup gains phi(c) phi(p) / M."""

import numpy as np
import pytest
from scipy import linalg, signal

from jassy import Event, Graph, ModalModel, render
from jassy.errors import PatchError
from patches.models_surface import steel_plate_model
from ugens.friction import Friction
from ugens.nonlinear_impact import HuntCrossleyImpact

FS = 48000
T0 = 0.01  # s: strike time (a whole frame)


def strike(model, duration, **params):
    """Main output, ``contact``, ``force`` and ``energy`` of one strike at T0."""
    hc = HuntCrossleyImpact(model, name="hc", **params)
    graph = Graph([hc, hc.tap("contact")], [hc.tap("force"), hc.tap("energy")])
    r = render(graph, [Event(T0, "hc", "strike", {"speed": 1.0})], duration, FS, 64, limiter=False)
    return (*r.audio, *r.haptic)


def linear_contact_closed_form(t, f0, a, mass, k, v0):
    """Contact displacement q(t) of a hammer (mass, speed v0) on one undamped mode (driving
    gain a: q'' + w^2 q = a w F) through a linear spring F = k max(x_h - q, 0): in contact
    a linear system, y(t) = expm(A t) y(0); the separation found by bisection; then the mode
    rings freely (an independent computation)."""
    w = 2 * np.pi * f0
    contact = np.array(
        [[0, 1, 0, 0], [-k / mass, 0, k / mass, 0], [0, 0, 0, 1], [a * w * k, 0, -w * w - a * w * k, 0]]
    )
    y0 = np.array([0.0, v0, 0.0, 0.0])

    def state(time):
        return linalg.expm(contact * time) @ y0

    lo, hi = 1e-9, 1e-9
    while state(hi)[0] - state(hi)[2] > 0:
        lo, hi = hi, 2 * hi
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if state(mid)[0] - state(mid)[2] > 0 else (lo, mid)
    end = 0.5 * (lo + hi)
    _, _, q_end, p_end = state(end)
    touching = t < end
    q = np.array([state(time)[2] for time in t[touching]])
    tau = t[~touching] - end
    return np.concatenate([q, q_end * np.cos(w * tau) + p_end / w * np.sin(w * tau)])


def test_single_mode_contact_and_heard_output_against_closed_form():
    f0, mass_mode, hammer, k = 200.0, 0.5, 0.02, 1e6
    a = 1 / (mass_mode * 2 * np.pi * f0)  # phi(c)^2 / M
    b = -0.4 * a  # phi(c) phi(p) / M: the pickup moves against the contact point
    model = ModalModel([f0], [0.0], [[b]], driving=[[a]], name="one-mode")
    heard, contact, force, _ = strike(model, 0.03, mass=hammer, stiffness=1e6, alpha=1.0, dissipation=0.0)
    start = round(T0 * FS)
    t = (np.arange(heard.size - start) + 1) / FS  # output n: the state at the end of sample n
    q = linear_contact_closed_form(t, f0, a, hammer, k, 1.0)
    peak = np.max(np.abs(q))
    assert np.max(np.abs(contact[start:] - q)) < 0.01 * peak
    assert np.max(np.abs(heard[start:] - (b / a) * q)) < 0.01 * abs(b / a) * peak
    assert np.all(force >= 0) and np.max(force) > 0


def test_steel_plate_works_with_hunt_crossley():
    plate = steel_plate_model()
    assert np.any(plate.gains < 0) and plate.driving is not None
    with pytest.raises(PatchError, match="model steel_plate has signed gains"):
        HuntCrossleyImpact(
            ModalModel(plate.frequencies, plate.decays, plate.gains, plate.points, "steel_plate"),
            location="t3",
        )
    params = dict(location="t3", mass=0.05, stiffness=1e8, floor=0.0)
    heard, contact, force, energy = strike(plate, 0.08, **params)
    assert np.all(np.isfinite(heard)) and np.max(np.abs(heard)) > 0
    # the loop is passive: it runs on the driving-point gains (signed gains would gain energy)
    start = round(T0 * FS)
    assert np.all(np.diff(energy[start:]) <= 1e-12 * energy[start])
    # the contact equals that of a plate whose gains are the driving-point ones
    unsigned = ModalModel(plate.frequencies, plate.decays, plate.driving, plate.points, "driving")
    _, same_contact, same_force, _ = strike(unsigned, 0.08, **params)
    assert np.array_equal(contact, same_contact) and np.array_equal(force, same_force)
    # heard = every mode under the contact force with its signed gain: scipy's zero-order-
    # hold discretisation of each mode, an independent computation
    gains = plate.gains_at("t3")
    state = np.zeros_like(heard)  # y[n] = C x[n], x[n + 1] = Ad x[n] + Bd force[n]
    for f, d, g in zip(plate.frequencies, plate.decays, gains, strict=True):
        w = 2 * np.pi * f
        a_c, b_c = np.array([[0, 1], [-(w * w + d * d), -2 * d]]), np.array([[0], [g * w]])
        a_d, b_d, c_d, d_d, _ = signal.cont2discrete(
            (a_c, b_c, np.array([[1, 0]]), np.array([[0]])), 1 / FS, "zoh"
        )
        num, den = signal.ss2tf(a_d, b_d, c_d, d_d)
        state += signal.lfilter(num[0], den, force)
    expected = np.append(state[1:], state[-1])  # heard[n]: the state after the force of sample n
    assert np.max(np.abs(heard[:-1] - expected[:-1])) < 1e-6 * np.max(np.abs(expected))


def test_friction_heard_output_is_the_signed_gain_times_the_contact():
    f0, a = 300.0, 1e-3
    model = ModalModel([f0], [2.0], [[-0.7 * a]], driving=[[a]], name="string")
    fr = Friction(model, name="fr", force=1.0, speed=0.2)
    r = render(Graph([fr, fr.tap("contact")]), (), 0.2, FS, 64, limiter=False)
    heard, contact = r.audio
    assert np.max(np.abs(contact)) > 0
    np.testing.assert_allclose(heard, -0.7 * contact, rtol=1e-9, atol=1e-12 * np.max(np.abs(contact)))
