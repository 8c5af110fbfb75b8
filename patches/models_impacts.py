"""Builders of the modal models shipped with the impact patches (``marble``).

The shipped ``*_model.toml`` files are the output of these functions (a test checks it):
``python -m patches.models_impacts`` regenerates them.
"""

from __future__ import annotations

import numpy as np

from jassy.modal_model import ModalModel
from jassy.surface import PlateSurface, plate_shapes

#: Named strike points of the plate as fractions (x / a, y / b) of its sides.
PLATE_POINTS = {
    "centre": (0.5, 0.5),
    "off_centre": (0.41, 0.37),
    "near_edge": (0.13, 0.29),
    "corner": (0.07, 0.09),
}


def plate_frequencies(a, b, h, youngs, poisson, density, orders):
    """f_mn = (pi/2) (m^2/a^2 + n^2/b^2) sqrt(D / (rho h)), D = E h^3 / (12 (1 - nu^2)) (Hz).

    Simply supported thin (Kirchhoff) rectangular plate, sides a, b, thickness h (m);
    ``orders`` = (m, n) arrays (Leissa, "Vibration of Plates", NASA SP-160, 1969, sec. 4.1).
    """
    m, n = orders
    rigidity = youngs * h**3 / (12.0 * (1.0 - poisson**2))
    return 0.5 * np.pi * (m**2 / a**2 + n**2 / b**2) * np.sqrt(rigidity / (density * h))


def plate_model(
    a: float = 0.30,
    b: float = 0.20,
    h: float = 0.005,
    youngs: float = 70e9,
    poisson: float = 0.22,
    density: float = 2500.0,
    loss: float = 1.0e-3,
    base_decay: float = 3.0,
    f_max: float = 20000.0,
    points: dict[str, tuple[float, float]] | None = None,
) -> ModalModel:
    """A simply supported rectangular plate (soda-lime glass by default: 300 x 200 x 5 mm).

    Modes (m, n) with f_mn < f_max (see :func:`plate_frequencies`); mode shapes
    phi_mn(x, y) = sin(m pi x / a) sin(n pi y / b) with modal mass M = rho h a b / 4. Gains
    are the driving-point displacement impulse response per N s at each point p,
    a_mn(p) = phi_mn(p)^2 / (M w_mn) (m per N s), as a closed-loop contact needs (and as
    ModalBank plays them: the output is the displacement under the striker), also anywhere
    on the plate through the model's surface (jassy.surface, no pickup). Decay
    d = base_decay + pi f loss (1/s): material loss factor ``loss`` (d = loss w / 2; glass
    about 1e-3) plus a constant for the supports and radiation.
    """
    points = PLATE_POINTS if points is None else points
    top = int(np.ceil(np.sqrt(f_max / plate_frequencies(a, b, h, youngs, poisson, density, (1, 0))))) + 1
    m, n = np.meshgrid(np.arange(1, top + 1), np.arange(1, top + 1), indexing="ij")
    m, n = m.ravel(), n.ravel()
    freqs = plate_frequencies(a, b, h, youngs, poisson, density, (m, n))
    keep = np.argsort(freqs)
    keep = keep[freqs[keep] < f_max]
    m, n, freqs = m[keep], n[keep], freqs[keep]
    modal_mass = density * h * a * b / 4.0
    xy = np.array(list(points.values()))
    shapes = plate_shapes(m, n, xy[:, 0], xy[:, 1])  # x/a, y/b fractions
    gains = shapes**2 / (modal_mass * 2.0 * np.pi * freqs)
    decays = base_decay + np.pi * freqs * loss
    surface = PlateSurface((a, b), m, n, None, 1.0 / (modal_mass * 2.0 * np.pi * freqs))  # gains = driving
    return ModalModel(freqs, decays, gains, tuple(points), "glass_plate", surface=surface)


SHIPPED = {"glass_plate_model.toml": plate_model}
