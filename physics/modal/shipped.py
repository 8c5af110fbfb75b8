"""Builders of the computed modal models shipped with the built-in patches.

``patches/bowl_model.toml`` is the output of :func:`bowl_model` (a test checks it):
regenerate with ``python -m physics.modal.shipped``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from jassy.modal_model import ModalModel

#: Bowl geometry (m) and the angles (rad) of the named strike points around the axis.
BOWL = dict(radius=0.07, height=0.055, thickness=0.005, base_radius=0.035, out_of_round=0.004, turn=0.3)


def bowl_points(geometry: dict | None = None) -> dict[str, tuple[float, float, float]]:
    """Named strike points on the bowl's outer surface (before projection onto the mesh).

    rim / rim45: just below the rim on the major axis and 45 degrees from it (the two
    orientations of each doublet are excited differently there); wall: half height; base:
    the centre of the bottom (outside); inside: the inner bottom.
    """
    g = dict(BOWL, **(geometry or {}))
    a, h, rb, e, turn = (
        g["radius"] - g["base_radius"],
        g["height"],
        g["base_radius"],
        g["out_of_round"],
        g["turn"],
    )

    def outer(t, azimuth):
        r = rb + a * np.sin(t)
        z = h * (1 - np.cos(t))
        x, y = r * np.cos(azimuth) * (1 + e / 2), r * np.sin(azimuth) * (1 - e / 2)
        c, s = np.cos(turn), np.sin(turn)
        return (float(c * x - s * y), float(s * x + c * y), float(z))

    return {
        "rim": outer(np.pi / 2 * 0.95, 0.0),
        "rim45": outer(np.pi / 2 * 0.95, np.pi / 4),
        "wall": outer(np.pi / 4, np.pi / 8),
        "base": (0.004, 0.003, 0.0),
        "inside": (0.004, 0.003, g["thickness"]),
    }


def bowl_model(n_modes: int = 90, elements: int = 8000, f_max: float = 16000.0) -> ModalModel:
    """A bronze singing bowl (7 cm radius, 5 mm wall, 0.4 % out of round) by finite elements.

    Voxel pitch for ~``elements`` hexahedra (about two through the wall), the lowest
    ``n_modes`` elastic modes, of which those below ``f_max`` Hz are kept (90 modes reach
    22 kHz, so the 57 below 16 kHz are all there are; the bending wavelength at 16 kHz,
    about 46 mm, spans some 18 voxels), bronze damping (loss factor 1.5e-4 plus 0.3 1/s), physical
    displacement gains (m per N s) at the named points of :func:`bowl_points`. The slight
    ellipticity splits each (n, 0) mode pair into a doublet a few Hz apart, which beats.
    """
    from physics.modal.fem import modes_from_mesh
    from physics.modal.materials import material
    from physics.modal.meshes import bowl

    mesh = bowl(**BOWL)
    model, _, _ = modes_from_mesh(
        mesh, material("bronze"), n_modes=n_modes, elements=elements, points=bowl_points(), name="bowl"
    )
    if model.frequencies.max() < f_max:
        raise ValueError(
            f"bowl_model: {n_modes} modes stop at {model.frequencies.max():.0f} Hz, below {f_max:g}"
        )
    return model.below(f_max)


SHIPPED = {"bowl_model.toml": bowl_model}


def main() -> None:
    """Write the shipped model files into the patches directory."""
    import patches

    here = Path(patches.__file__).parent
    for filename, builder in SHIPPED.items():
        builder().save(here / filename)


if __name__ == "__main__":
    main()
