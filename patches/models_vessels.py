"""Builders of the wine glass, the mug and the cooking pot of the object library, by finite
elements (``jassy modes``' solver) of the parametric meshes in :mod:`physics.modal.vessels`.

The models carry their reference gain (:mod:`jassy.levels`), so a ModalBank with
``level = "calibrated"`` plays them at the library's common level.
"""

from __future__ import annotations

import numpy as np

from jassy.levels import calibrated
from jassy.modal_model import ModalModel
from physics.modal.vessels import GLASS, MUG, POT, Mug, Pot, WineGlass

#: Rotation (rad) of both meshes about z, so the voxel grid is not aligned with their axes.
TURN = 0.3


def _turned(points: dict[str, tuple[float, float, float]]) -> dict[str, tuple[float, float, float]]:
    c, s = np.cos(TURN), np.sin(TURN)
    return {k: (c * x - s * y, s * x + c * y, z) for k, (x, y, z) in points.items()}


def wine_glass_points(g: WineGlass = GLASS) -> dict[str, tuple[float, float, float]]:
    """rim: 3 mm below the rim, outside; bowl: the widest point of the bowl; stem: half way
    up the stem; foot: the edge of the foot."""
    return _turned(
        {
            "rim": (g.rim_radius, 0.0, g.height - 0.003),
            "bowl": (g.bowl_radius, 0.0, g.stem_height + g.bowl_depth),
            "stem": (0.0, g.stem_radius, g.stem_height / 2),
            "foot": (-g.foot_radius, 0.0, g.foot_thickness / 2),
        }
    )


def mug_points(m: Mug = MUG) -> dict[str, tuple[float, float, float]]:
    """rim: 3 mm below the rim, a quarter turn from the handle; side: half way up, a quarter
    turn from the handle; handle: the outside of its bend; base: the centre of the bottom."""
    bend = (m.handle_high - m.handle_low) / 2
    outside = m.radius + m.handle_reach + bend + m.handle_radius
    return _turned(
        {
            "rim": (0.0, m.radius, m.height - 0.003),
            "side": (0.0, m.radius, m.height / 2),
            "handle": (outside, 0.0, (m.handle_low + m.handle_high) / 2),
            "base": (0.004, 0.003, 0.0),
        }
    )


def wine_glass_model(n_modes: int = 24, elements: int = 12000) -> ModalModel:
    """A soda-lime wine glass (WineGlass dimensions), the lowest ``n_modes`` elastic modes
    of about ``elements`` voxels, glass damping, displacement gains at the named points."""
    from physics.modal.fem import modes_from_mesh
    from physics.modal.materials import material
    from physics.modal.vessels import wine_glass

    model, _, _ = modes_from_mesh(
        wine_glass(turn=TURN), material("glass"), n_modes=n_modes, elements=elements,
        points=wine_glass_points(), name="wine_glass",
    )  # fmt: skip
    return calibrated(model)


def mug_model(n_modes: int = 24, elements: int = 10000) -> ModalModel:
    """A ceramic mug with a handle (Mug dimensions), as :func:`wine_glass_model`."""
    from physics.modal.fem import modes_from_mesh
    from physics.modal.materials import material
    from physics.modal.vessels import mug

    model, _, _ = modes_from_mesh(
        mug(turn=TURN), material("ceramic"), n_modes=n_modes, elements=elements,
        points=mug_points(), name="mug",
    )  # fmt: skip
    return calibrated(model)


def pot_points(p: Pot = POT) -> dict[str, tuple[float, float, float]]:
    """rim: 3 mm below the rim, outside; wall: half way up the outside; base: the centre of
    the bottom, outside; inside: the centre of the bottom, inside (a spoon stirring)."""
    return _turned(
        {
            "rim": (p.radius, 0.0, p.height - 0.003),
            "wall": (0.0, p.radius, p.height / 2),
            "base": (0.004, 0.003, 0.0),
            "inside": (0.004, 0.003, p.base),
        }
    )


def cast_iron():
    """Grey cast iron: E = 103 GPa, rho = 7300 kg/m^3, loss factor 1e-2 (Kumar, "Dynamic
    properties and selection of materials", NPTEL course 112104040, lecture 9, table 9.1:
    graphite flakes make it a hundred times lossier than aluminium), Poisson's ratio 0.26
    (ASTM A48 class 30 grey iron, ASM Handbook vol. 1)."""
    from physics.modal.materials import material

    return material("steel", youngs=103e9, poisson=0.26, density=7300.0, loss=1e-2, d0=1.0)


def pot_model(n_modes: int = 30, elements: int = 15000) -> ModalModel:
    """A cast-iron cooking pot (Pot dimensions: a Dutch oven without its lid), free (standing
    on a folded cloth), as :func:`wine_glass_model`."""
    from physics.modal.fem import modes_from_mesh
    from physics.modal.vessels import pot

    model, _, _ = modes_from_mesh(
        pot(turn=TURN), cast_iron(), n_modes=n_modes, elements=elements, points=pot_points(), name="pot",
    )  # fmt: skip
    return calibrated(model)


SHIPPED = {
    "wine_glass_model.toml": wine_glass_model,
    "mug_model.toml": mug_model,
    "pot_model.toml": pot_model,
}
