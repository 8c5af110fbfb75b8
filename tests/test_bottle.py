"""The bottle patch: struck (shell modes), rubbed (a squeal on a shell mode), filled (the
cavity's Helmholtz resonance rises as sqrt(V0 / V)) and struck again (the shell lower)."""

import math

import numpy as np
import pytest
from scipy.signal import welch

from jassy import Graph, render
from jassy.patchfile import load_patch
from patches.models_bottle import bottle_cavity_model, bottle_shell_model

FS = 48000


@pytest.fixture(scope="module")
def bottle():
    patch = load_patch("bottle")
    return patch, render(patch.graph, patch.score, patch.duration, FS, 64).audio[0]


def ramped(f0, scale, fraction):
    """ModalBank ramps its coefficients linearly, so cos(2 pi f / fs) ~ 1 - (2 pi f / fs)^2 / 2
    moves linearly: f^2, not f, is linear in time along a freq_scale ramp."""
    return f0 * math.sqrt(1 + (scale**2 - 1) * fraction)


def peak(x, lo, hi, a, b):
    f, p = welch(x[int(a * FS) : int(b * FS)], FS, nperseg=16384)
    band = (f > lo) & (f < hi)
    return f[band][np.argmax(p[band])]


def test_shell_model_is_the_ring_formula_and_cavity_is_helmholtz():
    n = 2
    speed = math.sqrt(70e9 / (12 * 2500 * (1 - 0.22**2)))
    f2 = 0.003 / (2 * math.pi * 0.04**2) * speed * n * (n * n - 1) / math.sqrt(n * n + 1)
    assert bottle_shell_model().frequencies[0] == pytest.approx(0.998 * f2, rel=1e-12)
    area, length = math.pi * 0.0095**2, 0.07 + 1.7 * 0.0095
    helmholtz = 343 / (2 * math.pi) * math.sqrt(area / (7.5e-4 * length))
    assert bottle_cavity_model().frequencies[0] == pytest.approx(helmholtz, rel=1e-12)
    assert np.all(bottle_shell_model().gains >= 0)  # driving-point gains: usable by Friction


def test_struck_rubbed_filled_struck(bottle):
    _, x = bottle
    shell = bottle_shell_model().frequencies
    strike = peak(x, 1000, 2000, 0.8, 1.5)
    assert min(abs(strike - shell)) < 6  # a shell mode
    squeal = peak(x, 500, 20000, 1.8, 3.3)
    assert min(abs(squeal - shell)) < 8  # the rub locks onto a shell mode
    cavity = [peak(x, 60, 400, a, a + 0.6) for a in (4.2, 5.4, 6.4)]
    assert cavity[0] < cavity[1] < cavity[2]  # the cavity rises as the bottle fills
    f0 = bottle_cavity_model().frequencies[0]
    assert cavity[0] == pytest.approx(ramped(f0, 2.236, 0.5 / 3), rel=0.03)
    assert cavity[2] == pytest.approx(ramped(f0, 2.236, 2.7 / 3), rel=0.03)
    late = peak(x, 1000, 2000, 7.6, 8.9)
    assert late == pytest.approx(0.93 * peak(x, 1400, 1600, 0.1, 0.7), rel=0.01)  # filled: lower shell


def test_cavity_alone_tracks_the_fill(bottle):
    patch, _ = bottle
    air = patch.graph.nodes["air"]
    score = [e for e in patch.score if e.node in ("pour", "air")]
    x = render(Graph(air), score, 7.0, FS, 64, limiter=False).audio[0]
    f0 = bottle_cavity_model().frequencies[0]
    assert peak(x, 60, 400, 6.4, 7.0) == pytest.approx(ramped(f0, 2.236, 2.7 / 3), rel=0.03)
