"""A jump of a ModalBank's freq_scale or decay_scale retunes each ringing mode in place: it
keeps its amplitude and phase and rings on at the new frequency and decay, at any sample
rate.

The truth is the decaying sine itself: fitted (least squares on sin/cos) to the samples
before the jump, continued to the jump's frame, and from there A R_new^k sin(phi + k theta_new)
with the new pole. Reading the old state with the new pole instead scales the amplitude by
about sin theta_old / sin theta_new (the bar patch's octave put its top mode 15 dB too loud
at 48 kHz).
"""

import numpy as np
import pytest

from jassy import Event, Graph, render
from jassy.modal_model import ModalModel
from ugens import ImpactForce, ModalBank

F0, D0 = 11748.0, 4.2  # the bar's fifth mode (Hz, 1/s)
JUMP = 0.05  # s


def ringing(rate, change):
    hit = ImpactForce(name="hit", duration=0.0005)
    bank = ModalBank(ModalModel([F0], [D0], [[1.0]]), name="bank")(hit)
    score = [Event(0.001, "hit", "impact", {"impulse": 1.0}), Event(JUMP, "bank", "set", change, jump=True)]
    return render(Graph(bank), score, 0.08, rate, 64, limiter=False).audio[0]


@pytest.mark.parametrize("rate", [48000, 192000])
@pytest.mark.parametrize("change", [{"freq_scale": 2.0}, {"freq_scale": 0.6, "decay_scale": 30.0}])
def test_a_jump_keeps_each_modes_amplitude_and_phase(rate, change):
    y = ringing(rate, change)
    n0 = int(round(JUMP * rate))
    k = np.arange(int(0.01 * rate), n0)  # after the strike, before the jump
    theta, r = 2 * np.pi * F0 / rate, np.exp(-D0 / rate)
    basis = np.stack([r**k * np.sin(theta * k), r**k * np.cos(theta * k)], axis=1)
    (a, b), *_ = np.linalg.lstsq(basis, y[k], rcond=None)
    assert np.max(np.abs(basis @ [a, b] - y[k])) < 1e-9 * np.max(np.abs(y))
    amplitude, phase = np.hypot(a, b) * r**n0, np.arctan2(b, a) + theta * n0  # at frame n0
    theta_new = theta * change.get("freq_scale", 1.0)
    r_new = np.exp(-D0 * change.get("decay_scale", 1.0) / rate)
    m = np.arange(y.size - n0)
    expected = amplitude * r_new**m * np.sin(phase + theta_new * m)
    assert np.max(np.abs(y[n0:] - expected)) < 1e-9 * np.max(np.abs(y))


def test_the_ringing_after_a_jump_does_not_depend_on_the_rate():
    """Level 10 ms after the jump over the level 10 ms before it (the strike's own
    spectrum differs slightly between rates)."""
    ratio = {}
    for rate in (48000, 192000):
        y = np.abs(ringing(rate, {"freq_scale": 2.0}))
        before, after = (int(t * rate) for t in (JUMP - 0.01, JUMP + 0.01))
        ratio[rate] = np.max(y[after : after + rate // 500]) / np.max(y[before : before + rate // 500])
    assert abs(20 * np.log10(ratio[48000] / ratio[192000])) < 0.1, ratio
