"""HuntCrossleyImpact at high frequency: mode levels after a short contact against an
accurate ODE solution (scipy DOP853) of the same continuous model."""

from __future__ import annotations

import numpy as np
from scipy.integrate import solve_ivp

from jassy.engines.offline import render
from jassy.events import Event
from jassy.graph import Graph
from jassy.modal_model import ModalModel
from ugens.nonlinear_impact import HuntCrossleyImpact

FS = 48000


def test_mode_levels_match_dop853_up_to_12_khz_for_a_six_sample_contact():
    """Hammer 10 g at 1 m/s, k = 1e9 N/m^1.5 (Hertz), five light modes 1-12 kHz: the contact
    lasts about 6 samples; every mode's amplitude 1 ms later is within 0.5 dB of DOP853."""
    f = np.array([1000.0, 3000.0, 6000.0, 9000.0, 12000.0])
    d = np.full(5, 20.0)
    a = np.full(5, 1e-6)
    m, k, alpha, lam, v0 = 0.01, 1e9, 1.5, 0.3, 1.0
    w = 2 * np.pi * f

    def rhs(t, y):
        q, p = y[2:7], y[7:12]
        x, xd = y[0] - q.sum(), y[1] - p.sum()
        force = k * x**alpha * max(0.0, 1.0 + lam * xd) if x > 0 else 0.0
        return np.concatenate([[y[1], -force / m], p, a * w * force - 2 * d * p - (w * w + d * d) * q])

    steps = 48
    sol = solve_ivp(rhs, (0.0, steps / FS), np.concatenate([[0.0, v0], np.zeros(10)]), method="DOP853",
                    rtol=1e-11, atol=1e-20, max_step=1e-7)  # fmt: skip

    def amplitude(q, p):
        return np.sqrt(q * q + ((p + d * q) / w) ** 2)

    ref = amplitude(sol.y[2:7, -1], sol.y[7:12, -1])
    hc = HuntCrossleyImpact(ModalModel(f, d, a[None, :]), name="hc", mass=m, stiffness=k, alpha=alpha,
                            dissipation=lam, floor=0.0)  # fmt: skip
    t0 = 480
    render(Graph(hc), [Event(t0 / FS, "hc", "strike", {"speed": v0})], (t0 + steps) / FS, FS, 64)
    assert 5.5 < hc.contact_time * FS < 7.0
    hc._commit_force()
    back = np.argsort(hc.order)
    levels = 20 * np.log10(amplitude(hc.state[0][back], hc.state[1][back]) / ref)
    assert np.max(np.abs(levels)) < 0.5
