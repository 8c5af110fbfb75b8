"""The marble patch's mallet sounds of its own: its handle's bending modes, driven by
the reaction of the Hunt-Crossley contact force, are heard after the tap."""

import math

import numpy as np
from scipy.signal import welch

from jassy import render
from jassy.patchfile import load_patch

FS = 48000


def handle_frequencies(E=12e9, rho=700.0, radius=0.004, length=0.25):
    """Free-free Euler-Bernoulli beam: f_n = (beta_n L)^2 / (2 pi L^2) sqrt(E I / (rho A))."""
    area, inertia = math.pi * radius**2, math.pi * radius**4 / 4
    return [
        b**2 / (2 * math.pi * length**2) * math.sqrt(E * inertia / (rho * area)) for b in (4.7300, 7.8532)
    ]


def tap_spectrum(handle_gain):
    patch = load_patch("marble")
    patch.graph.nodes["sound"].configure("gains", [1.0, handle_gain])
    y = render(patch.graph, patch.score, 4.5, FS, 64, limiter=False).audio[0]
    return welch(y[int(4.0 * FS) :], FS, nperseg=8192)


def test_the_mallet_handle_rings_at_its_bending_modes():
    patch = load_patch("marble")
    gain = patch.graph.nodes["sound"].values["gains"][1]
    f, with_handle = tap_spectrum(gain)
    _, without = tap_spectrum(0.0)
    for fn in handle_frequencies():
        band = np.abs(f - fn) < 2 * FS / 8192
        assert np.max(with_handle[band]) > 100 * np.max(without[band])  # +20 dB: the handle is heard
        k = int(np.argmin(np.abs(f - fn)))
        assert with_handle[k] == np.max(with_handle[max(k - 8, 0) : k + 9])  # a peak at f_n
