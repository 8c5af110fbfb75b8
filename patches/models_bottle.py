"""Models of the bottle patch: a glass wine bottle's shell and its air cavity.

Shell: circumferential (ring) bending modes of a thin cylindrical shell, inextensional
theory (Rayleigh; Fletcher & Rossing, "The Physics of Musical Instruments", 2.14):

    f_n = h / (2 pi R^2) sqrt(E / (12 rho (1 - nu^2))) n (n^2 - 1) / sqrt(n^2 + 1),  n = 2, 3, ...

each with a few axial variants (ratios 1, 1.18, 1.45: the shell's finite length), as
split doublets (a real bottle is not perfectly round). Gains are driving-point values
(squared mode shapes / (M w)) at three heights, so closed-loop contacts (rubbing) can use
them. Decay: d = 1 + pi f eta, glass loss factor eta = 1e-3.

Cavity: the Helmholtz resonance f = c / (2 pi) sqrt(A / (V L_eff)) of the air above the
liquid; the patch raises it with ``freq_scale`` as the bottle fills (V shrinks).
"""

from __future__ import annotations

import math

import numpy as np

from jassy.modal_model import ModalModel

GLASS = {"youngs": 70e9, "density": 2500.0, "poisson": 0.22, "loss": 1e-3}
HEIGHTS = ("shoulder", "body", "base")


def bottle_shell_model(radius: float = 0.04, thickness: float = 0.003, length: float = 0.2) -> ModalModel:
    """Ring modes n = 2..6 with three axial variants each, as doublets: 30 modes."""
    g = GLASS
    speed = math.sqrt(g["youngs"] / (12 * g["density"] * (1 - g["poisson"] ** 2)))
    n = np.arange(2, 7)
    ring = thickness / (2 * math.pi * radius**2) * speed * n * (n**2 - 1) / np.sqrt(n**2 + 1)
    axial = np.array([1.0, 1.18, 1.45])
    base = (ring[:, None] * axial[None, :]).reshape(-1)
    freqs = np.stack([base * 0.998, base * 1.002], axis=1).reshape(-1)
    mass = g["density"] * 2 * math.pi * radius * thickness * length / 2  # modal mass of a shell mode
    heights = np.linspace(0.15, 0.85, len(HEIGHTS))  # fraction of the length from the base
    m_axial = np.tile(np.repeat(np.arange(1, 4), 2), n.size)  # axial half-waves of each mode
    shapes = np.sin(np.pi * m_axial[None, :] * (1 - heights[:, None]))
    gains = shapes**2 / (mass * 2 * math.pi * freqs)
    decays = 1.0 + math.pi * freqs * g["loss"]
    return ModalModel(freqs, decays, gains, HEIGHTS[::-1], "bottle_shell")


def bottle_cavity_model(
    neck_radius: float = 0.0095, neck_length: float = 0.07, volume: float = 7.5e-4, sound_speed: float = 343.0
) -> ModalModel:
    """The empty bottle's Helmholtz resonance (about 114 Hz for a 0.75 l wine bottle)."""
    area = math.pi * neck_radius**2
    effective = neck_length + 1.7 * neck_radius  # end corrections (flanged + unflanged)
    f = sound_speed / (2 * math.pi) * math.sqrt(area / (volume * effective))
    return ModalModel([f, 2.9 * f], [6.0, 30.0], [[1.0, 0.15]], (), "bottle_cavity")


SHIPPED = {"bottle_shell_model.toml": bottle_shell_model, "bottle_cavity_model.toml": bottle_cavity_model}
