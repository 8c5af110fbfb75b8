"""A resonator rubbed and struck at once: Friction's ``strike`` input is a force on the same
modes. Without contact the response is the closed-form modal response to the strike; after
the bow lifts, the strike's response adds to the ringing bowed motion (superposition)."""

from __future__ import annotations

import numpy as np
import pytest

from jassy import Event, Graph, ModalModel, render
from ugens import Friction, ImpactForce

FS = 48000
MODEL = ModalModel([420.0, 1130.0, 2290.0], [3.0, 6.0, 11.0], [[2e-3, 1e-3, 5e-4]])


#: The same modes heard at a pickup with signed gains (the loop uses the driving-point rows).
SIGNED = ModalModel(MODEL.frequencies, MODEL.decays, [[2e-3, -1e-3, 5e-4]], driving=[[2e-3, 1e-3, 5e-4]])


def run(
    bow: bool, strike: bool, strike_time: float = 0.4, model: ModalModel = MODEL
) -> tuple[np.ndarray, np.ndarray]:
    hit = ImpactForce(name="hit")
    rub = Friction(model, name="rub", speed=0.1)
    rub(strike=hit)
    score = []
    if bow:  # press, then lift the bow at 0.3 s
        score += [Event(0.0, "rub", "set", {"force": 1.0}, jump=True)]
        score += [Event(0.3, "rub", "set", {"force": 0.0}, jump=True)]
    if strike:
        score.append(Event(strike_time, "hit", "impact", {"impulse": 2e-3}))
    result = render(Graph(rub, haptic=hit), score, duration=0.6, sample_rate=FS, limiter=False)
    return result.audio[0], result.haptic[0]


@pytest.mark.parametrize("model", [MODEL, SIGNED], ids=["driving-point", "signed-pickup"])
def test_a_strike_without_contact_is_the_closed_form_modal_response(model):
    x, force = run(bow=False, strike=True, model=model)
    # x[n] = sum_m F[m] / fs * h((n - m + 1) / fs): the resonator hears F[n] at sample n
    h = model.impulse_response((len(x) + 1) / FS, FS)[1:]
    expected = np.convolve(force, h)[: len(x)] / FS
    assert np.max(np.abs(x)) > 1e-7
    np.testing.assert_allclose(x, expected, atol=1e-9 * np.max(np.abs(expected)))


def test_after_the_bow_lifts_a_strike_adds_to_the_ringing_bowed_motion():
    both, _ = run(bow=True, strike=True)
    bowed, _ = run(bow=True, strike=False)
    struck, _ = run(bow=False, strike=True)
    # the bowed motion still rings when the strike comes, as loud as the strike's response
    assert np.max(np.abs(bowed[int(0.4 * FS) :])) > 0.1 * np.max(np.abs(struck))
    np.testing.assert_allclose(both - bowed, struck, atol=1e-9 * np.max(np.abs(both)))


def test_a_strike_while_bowing_changes_the_motion():
    both, _ = run(bow=True, strike=True, strike_time=0.1)
    bowed, _ = run(bow=True, strike=False)
    start = int(0.1 * FS)
    np.testing.assert_array_equal(both[:start], bowed[:start])
    assert np.max(np.abs(both[start:] - bowed[start:])) > 1e-3 * np.max(np.abs(bowed))
