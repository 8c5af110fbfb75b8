"""Parametric meshes of a wine glass, a mug and a cooking pot (SI units, axis z, base at z = 0).

Both are solids of revolution of a closed (r, z) profile (``trimesh.creation.revolve``);
the mug's handle is a separate closed tube whose end caps stop 0.2 mm short of the outer
wall, so the two surfaces never overlap (voxel filling counts ray crossings) while the
voxels of the handle and the wall touch face to face.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class WineGlass(NamedTuple):
    """Dimensions (m) of a stemmed wine glass: an elliptic bowl tapering to the rim."""

    foot_radius: float = 0.032
    foot_thickness: float = 0.003
    stem_radius: float = 0.0035
    stem_height: float = 0.07  # bottom of the bowl above the table
    bowl_radius: float = 0.038  # widest outer radius
    bowl_depth: float = 0.035  # from the bottom of the bowl to its widest point
    rim_radius: float = 0.031
    height: float = 0.155  # rim above the table
    wall: float = 0.0022


class Mug(NamedTuple):
    """Dimensions (m) of a straight ceramic mug with a D-shaped handle of round section."""

    radius: float = 0.041  # outer
    height: float = 0.095
    wall: float = 0.004
    base: float = 0.006
    handle_low: float = 0.03  # heights of the handle's two roots
    handle_high: float = 0.078
    handle_reach: float = 0.004  # straight run out from the wall before the bend
    handle_radius: float = 0.005  # of the tube


class Pot(NamedTuple):
    """Dimensions (m) of an open cooking pot: straight wall, flat base, no lid or handles.

    The default is a cast-iron Dutch oven of the common stove-top size, about 10 in
    (254 mm) wide and 5 in (127 mm) tall (MetroKitchen, "Dutch ovens", metrokitchen.com;
    Wikipedia, "Dutch oven": a thick-walled pot, usually of cast iron)."""

    radius: float = 0.127  # outer
    height: float = 0.127
    wall: float = 0.005
    base: float = 0.006


#: The shipped objects' dimensions.
GLASS = WineGlass()
MUG = Mug()
POT = Pot()


def wine_glass_profile(g: WineGlass = GLASS, segments: int = 24) -> np.ndarray:
    """Closed (r, z) cross-section: foot, stem, then the bowl's outer wall up to the rim and
    its inner wall (the outer one offset by ``wall``) back down to the axis."""
    z0 = g.stem_height
    s = np.linspace(0.0, np.pi / 2, segments + 1)
    taper = np.linspace(0.0, 1.0, segments + 1)[1:]
    widest = z0 + g.bowl_depth

    def wall(inset: float) -> np.ndarray:
        # lower part: quarter ellipse from the bottom (r = 0) to the widest point
        lower = np.column_stack(
            [(g.bowl_radius - inset) * np.sin(s), widest - (g.bowl_depth - inset) * np.cos(s)]
        )
        # upper part: radius narrows quadratically (vertical at the widest point) to the rim
        upper = np.column_stack(
            [
                g.bowl_radius - inset - (g.bowl_radius - g.rim_radius) * taper**2,
                widest + (g.height - widest) * taper,
            ]
        )
        return np.vstack([lower, upper])

    outer = wall(0.0)
    outer = outer[outer[:, 0] > g.stem_radius]
    inner = wall(g.wall)[::-1]
    inner = inner[inner[:, 0] > 0.0]
    return np.vstack(
        [
            [[0.0, 0.0], [g.foot_radius, 0.0], [g.foot_radius, g.foot_thickness]],
            [[3 * g.stem_radius, g.foot_thickness + 0.002], [g.stem_radius, g.foot_thickness + 0.008]],
            [[g.stem_radius, z0 - 0.002]],
            outer,
            inner,
            [[0.0, z0 + g.wall], [0.0, 0.0]],
        ]
    )


def wine_glass(g: WineGlass = GLASS, sections: int = 72, turn: float = 0.3):
    """The glass as a watertight Trimesh, turned by ``turn`` rad about z (so the voxel grid is
    not aligned with its axes)."""
    import trimesh

    mesh = trimesh.creation.revolve(wine_glass_profile(g), sections=sections)
    mesh.apply_transform(trimesh.transformations.rotation_matrix(turn, [0, 0, 1]))
    return mesh


def mug_profile(m: Mug | Pot = MUG) -> np.ndarray:
    """Closed (r, z) cross-section of the cup (or of a pot): flat base, straight wall, flat rim."""
    return np.array(
        [
            [0.0, 0.0],
            [m.radius, 0.0],
            [m.radius, m.height],
            [m.radius - m.wall, m.height],
            [m.radius - m.wall, m.base],
            [0.0, m.base],
            [0.0, 0.0],
        ]
    )


def handle_centreline(m: Mug = MUG, segments: int = 32) -> np.ndarray:
    """(x, z) of the handle's centre line in the plane y = 0: out from the wall, a half
    circle, back to the wall."""
    gap = 0.0002
    x0, x1 = m.radius + gap, m.radius + m.handle_reach
    mid, bend = (m.handle_low + m.handle_high) / 2, (m.handle_high - m.handle_low) / 2
    angle = np.linspace(-np.pi / 2, np.pi / 2, segments + 1)
    lower = np.column_stack([np.linspace(x0, x1, 4)[:-1], np.full(3, m.handle_low)])
    arc = np.column_stack([x1 + bend * np.cos(angle), mid + bend * np.sin(angle)])
    upper = np.column_stack([np.linspace(x1, x0, 4)[1:], np.full(3, m.handle_high)])
    return np.vstack([lower, arc, upper])


def tube(centre: np.ndarray, radius: float, sides: int = 16):
    """A closed tube of round section along a planar (x, z) centre line (y = 0), capped flat
    at both ends, as a Trimesh with outward normals."""
    import trimesh

    tangent = np.gradient(centre, axis=0)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    normal = np.column_stack([-tangent[:, 1], tangent[:, 0]])  # in the x-z plane
    a = 2 * np.pi * np.arange(sides) / sides
    rings = (
        np.column_stack([centre[:, 0], np.zeros(len(centre)), centre[:, 1]])[:, None, :]
        + radius * np.cos(a)[None, :, None] * np.column_stack(
            [normal[:, 0], np.zeros(len(centre)), normal[:, 1]]
        )[:, None, :]
        + radius * np.sin(a)[None, :, None] * np.array([0.0, 1.0, 0.0])[None, None, :]
    )  # fmt: skip
    n = len(centre)
    vertices = np.vstack([rings.reshape(-1, 3), centre[[0, -1]][:, [0, 0, 1]] * [1, 0, 1]])
    idx = np.arange(n * sides).reshape(n, sides)
    faces = []
    for i in range(n - 1):
        for j in range(sides):
            a0, a1, b0, b1 = idx[i, j], idx[i, (j + 1) % sides], idx[i + 1, j], idx[i + 1, (j + 1) % sides]
            faces += [[a0, b0, a1], [a1, b0, b1]]
    first, last = n * sides, n * sides + 1
    for j in range(sides):
        faces.append([first, idx[0, j], idx[0, (j + 1) % sides]])
        faces.append([last, idx[-1, (j + 1) % sides], idx[-1, j]])
    mesh = trimesh.Trimesh(vertices, np.array(faces), process=True)
    trimesh.repair.fix_normals(mesh)
    return mesh


def mug(m: Mug = MUG, sections: int = 72, turn: float = 0.3):
    """The mug (cup and handle, handle along +x before the turn) as one watertight Trimesh
    of two closed bodies that do not intersect."""
    import trimesh

    cup = trimesh.creation.revolve(mug_profile(m), sections=sections)
    handle = tube(handle_centreline(m), m.handle_radius)
    mesh = trimesh.util.concatenate([cup, handle])
    mesh.apply_transform(trimesh.transformations.rotation_matrix(turn, [0, 0, 1]))
    return mesh


def pot(p: Pot = POT, sections: int = 96, turn: float = 0.3):
    """The pot as a watertight Trimesh, turned by ``turn`` rad about z."""
    import trimesh

    mesh = trimesh.creation.revolve(mug_profile(p), sections=sections)
    mesh.apply_transform(trimesh.transformations.rotation_matrix(turn, [0, 0, 1]))
    return mesh
