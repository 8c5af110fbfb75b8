"""Builders of the modal models of the bowed-string patch (``bowed-string.toml``).

The shipped ``*_model.toml`` files are the output of these functions
(tests/test_friction_engine.py checks it); regenerate them with
``python -m patches.models_machines``.
"""

from __future__ import annotations

import numpy as np

from jassy.modal_model import ModalModel

#: Bowing points as fractions of the string length from the bridge.
BOW_POINTS = {"ponticello": 0.06, "normale": 0.12, "tasto": 0.2}


def bowed_string_model(
    f1: float = 196.0,
    n_modes: int = 48,
    inharmonicity: float = 3e-5,
    length: float = 0.325,
    tension: float = 45.0,
    t60: float = 3.0,
    loss: float = 2e-6,
) -> ModalModel:
    """Transverse modes of a stiff string (a violin G string by default) seen at bowing points.

    Frequencies f_n = n f1 sqrt(1 + B n^2) (B = ``inharmonicity``; stiffness makes partials
    slightly sharp), below 0.45 * 48 kHz. Decay d_n = ln(1000) / t60 + loss f_n^2 (1/s):
    the fundamental rings for ``t60`` s, upper partials lose energy faster (internal and
    air damping grow with frequency).

    Gains: the mode shape of mode n at the bowing point x_b (fraction of the length) is
    sin(n pi x_b), and the modal mass is mu L / 2 with mu = tension / (2 L f1)^2. A force
    impulse J at x_b excites mode n with velocity J sin(n pi x_b) / (mu L / 2), and the
    motion observed at x_b carries the shape factor sin(n pi x_b) once more, so the
    driving-point response is x(t) = J sum_n a_n e^{-d_n t} sin(w_n t) with

        a_n = 2 sin(n pi x_b)^2 / (mu L w_n)   (m per N s),

    which is >= 0 as a closed friction loop needs (modes with a node at the bow vanish).
    """
    mu = tension / (2.0 * length * f1) ** 2
    n = np.arange(1, n_modes + 1)
    freqs = n * f1 * np.sqrt(1.0 + inharmonicity * n**2)
    keep = freqs < 0.45 * 48000.0
    n, freqs = n[keep], freqs[keep]
    decays = np.log(1000.0) / t60 + loss * freqs**2
    omega = 2.0 * np.pi * freqs
    beta = np.array(list(BOW_POINTS.values()))[:, None]
    gains = 2.0 * np.sin(n * np.pi * beta) ** 2 / (mu * length * omega)
    return ModalModel(freqs, decays, gains, tuple(BOW_POINTS), "bowed_string")


SHIPPED = {"bowed_string_model.toml": bowed_string_model}
