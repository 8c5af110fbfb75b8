"""The rolling contact filter makes the force from the roughness's height alone.

A ball of mass m on its contact spring k rolling at v over a sinusoidal roughness of
wavelength lambda and amplitude r on a rigid surface feels F = r / (1/k - 1/(m w^2)),
w = 2 pi v / lambda (Remington, JASA 81, 1987): the speed enters through w only, and
far below the contact resonance F = m w^2 r grows as v^2. An amplitude law s(F, v) on top
(Roll's default sqrt(F v), for an open-loop force) would count the speed a second time.
"""

import math

import numpy as np
import pytest

from jassy import Graph, ModalModel, PatchError, render
from ugens.roll import Roll
from ugens.scrape import ResonantScrape, Scrape

FS = 48000
MASS, STIFFNESS = 0.11, 1.1e7  # kg, N/m: the roll patch's ball on steel
WAVELENGTH, POINTS = 1e-3, 64  # m; profile points per wavelength
RMS = 1e-7  # m


def rolled(speed, law):
    """The contact force of Roll rolling at ``speed`` over the sinusoidal roughness, on a
    surface far stiffer than the contact (one 15 kHz mode of negligible receptance)."""
    surface = ModalModel([15000.0], [50.0], [[1e-6]])
    node = Roll(
        name="roll",
        model=surface,
        location=0,
        profile=list(np.sin(2 * math.pi * np.arange(POINTS) / POINTS)),
        roughness=RMS,
        dx=WAVELENGTH / POINTS,
        fc0=20000.0,  # the speed-tracking low-pass 100 wavelengths' frequency up: flat here
        v0=0.2,
        mass=MASS,
        contact_stiffness=STIFFNESS,
        law=law,
        force=1.08,
        speed=speed,
    )
    return render(Graph(node), [], 1.0, FS, 256, limiter=False).audio[0]


def amplitude(x, f):
    t = np.arange(x.size) / FS
    tail = slice(x.size // 2, x.size)
    basis = np.stack([np.sin(2 * math.pi * f * t[tail]), np.cos(2 * math.pi * f * t[tail])], axis=1)
    return float(np.hypot(*np.linalg.lstsq(basis, x[tail], rcond=None)[0]))


def sampled_contact_filter(speed):
    """|F| / r of the same loop with the ball stepped as the kernel steps it, y[n] - 2 y[n-1]
    + y[n-2] = F[n] / (m fs^2): 1 / (m w^2) becomes e^{jW} / (m (2 fs sin(W/2))^2),
    W = w / fs (the z transform of the double sum, no delay)."""
    big_w = 2 * math.pi * speed / WAVELENGTH / FS
    ball = complex(math.cos(big_w), math.sin(big_w)) / (MASS * (2 * FS * math.sin(big_w / 2)) ** 2)
    return 1.0 / abs(1.0 / STIFFNESS - ball)


@pytest.mark.parametrize("speed", [0.1, 0.2, 1.0])
def test_rolling_force_is_the_contact_filter_of_the_height(speed):
    """At 0.1 and 0.2 m/s (m w^2 / k = 0.004, 0.016) the continuous formula holds; at 1 m/s
    (0.39, near the 1.6 kHz contact resonance) the sampled ball's own closed form does."""
    w = 2 * math.pi * speed / WAVELENGTH
    force = amplitude(rolled(speed, "height"), speed / WAVELENGTH)
    assert force == pytest.approx(math.sqrt(2) * RMS * sampled_contact_filter(speed), rel=0.002)
    if speed < 0.5:
        expected = math.sqrt(2) * RMS * MASS * w * w / (1 - MASS * w * w / STIFFNESS)
        assert force == pytest.approx(expected, rel=0.005)


@pytest.mark.parametrize("make", [Roll, Scrape, ResonantScrape])
def test_the_height_law_needs_a_contact_filter(make):
    """Without a contact model "height" would make force = stiffness x height, with no
    speed or load in it: refused in one line naming the node's ``law``."""
    with pytest.raises(PatchError, match=r"nodes\.x\.law: 'height' .* needs a contact filter"):
        render(Graph(make(name="x", law="height", speed=0.2)), [], 0.01, FS, 256, limiter=False)
