"""Builders of the modal models shipped with the built-in patches.

The shipped ``*_model.toml`` files are the output of these functions (a test checks it),
so the numbers in them can be traced to the formulas below.
"""

from __future__ import annotations

import numpy as np

from jassy.modal_model import ModalModel

#: Principal partials of a tuned church bell relative to the prime (Rossing, "The Science of
#: Sound"; Fletcher & Rossing, "The Physics of Musical Instruments", ch. 21): hum, prime,
#: tierce, quint, nominal, deciem, undeciem, duodeciem, upper octave.
BELL_PARTIALS = np.array([0.5, 1.0, 1.183, 1.506, 2.0, 2.514, 2.662, 3.011, 4.166])
BELL_POINTS = ("lip", "soundbow", "waist", "shoulder", "crown")


def bell_model(n_modes: int = 120, prime: float = 392.0, loss: float = 2.0e-4, seed: int = 7) -> ModalModel:
    """A bell: the principal partials, then denser upper partials up to 16 kHz.

    Every partial is a doublet split by 0.05-0.3 % (the two orientations of a slightly
    asymmetric bell), which gives the beating of real bells. Decay d = 0.1 + pi f loss
    (1/s). Gains per strike height follow |cos(pi (n + 1) h + phase)| along the profile
    (h = 0 at the lip, 1 at the crown) for a partial with n nodal circles, times a
    spectral tilt (f / prime)^-0.6.
    """
    rng = np.random.default_rng(seed)
    n_pairs = (n_modes + 1) // 2
    upper = n_pairs - len(BELL_PARTIALS)
    ratios = list(BELL_PARTIALS[:n_pairs])
    if upper > 0:
        # plate-like growth above the upper octave: f ~ m^2, jittered, up to 16 kHz
        top = 16000.0 / prime
        m = np.linspace(np.sqrt(4.3), np.sqrt(top), upper) ** 2
        ratios.extend(np.sort(m * rng.uniform(0.98, 1.02, upper)))
    base = np.asarray(ratios) * prime
    split = rng.uniform(0.0005, 0.003, base.size)
    freqs = np.stack([base * (1 - split / 2), base * (1 + split / 2)], axis=1).reshape(-1)[:n_modes]
    decays = 0.1 + np.pi * freqs * loss
    heights = np.linspace(0.0, 1.0, len(BELL_POINTS))
    circles = np.repeat(np.arange(base.size) % 4, 2)[:n_modes]
    phase = np.repeat(rng.uniform(0, np.pi, base.size), 2)[:n_modes]
    tilt = (freqs / prime) ** -0.6
    azimuth = np.tile([np.cos(0.3), np.sin(0.3)], base.size)[:n_modes]  # strike 0.3 rad off the doublet axes
    gains = np.abs(np.cos(np.pi * (circles + 1) * heights[:, None] + phase)) * tilt * np.abs(azimuth)
    return ModalModel(freqs, decays, 0.5 * gains, BELL_POINTS, "bell")


#: beta_n L of a free-free Euler-Bernoulli beam (roots of cos(x) cosh(x) = 1).
FREE_FREE_BETA_L = np.array([4.730040745, 7.853204624, 10.995607838, 14.137165491, 17.278759657])


def free_bar_model(
    length: float = 0.2173,
    thickness: float = 0.008,
    youngs: float = 69e9,
    density: float = 2700.0,
    loss: float = 1.0e-4,
    n_modes: int = 5,
    n_points: int = 9,
) -> ModalModel:
    """Bending modes of a free-free rectangular bar (aluminium by default), Euler-Bernoulli.

    f_n = (beta_n L)^2 / (2 pi L^2) sqrt(E h^2 / (12 rho)); gains are the mode shapes
    at ``n_points`` evenly spaced positions along the bar (point 0 at one end), each
    normalised to 1 at the free end (signs kept, so interpolating between points of
    opposite sign passes through the nodal line). Decay d = 0.5 + pi f loss (1/s).
    """
    beta_l = np.concatenate([FREE_FREE_BETA_L, (2 * np.arange(6, n_modes + 1) + 1) * np.pi / 2])[:n_modes]
    speed = np.sqrt(youngs * thickness**2 / (12 * density))
    freqs = beta_l**2 / (2 * np.pi * length**2) * speed
    x = np.linspace(0.0, 1.0, n_points)[:, None] * beta_l  # beta x at each point
    sigma = (np.cosh(beta_l) - np.cos(beta_l)) / (np.sinh(beta_l) - np.sin(beta_l))
    shapes = np.cosh(x) + np.cos(x) - sigma * (np.sinh(x) + np.sin(x))
    shapes = shapes / shapes[0]
    names = tuple(f"x{i}" for i in range(n_points))
    return ModalModel(freqs, 0.5 + np.pi * freqs * loss, shapes, names, "bar")


SHIPPED = {"bell_model.toml": bell_model, "bar_model.toml": free_bar_model}
