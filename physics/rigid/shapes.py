"""Collision shapes and their mass properties.

Shapes are given in the body's own frame before it is moved to the centre of mass and
principal axes; :func:`mass_properties` returns that transform and the principal moments.

- ``Sphere(radius)``, ``Capsule(radius, half_length)`` (axis z), ``Box(half_extents)``:
  primitives with closed-form mass properties.
- ``Convex(mesh)``: the convex hull of a trimesh mesh (or of points): a polytope with face
  planes and hull triangles; mass properties by trimesh.
- ``Plane(normal, offset)``: the half-space n.x <= offset is solid (static bodies only).
- ``TriangleMesh(mesh, thickness)``: a general (possibly open, concave) triangle surface, e.g.
  a wok, for static or kinematic bodies; points are kept on the side its normals face.
- ``Compound(mesh, pieces)``: a closed, possibly concave solid for any body: mass properties
  of the mesh itself, contacts with planes and meshes at its vertices, with other bodies
  piece by piece over convex pieces (given, or found by CoACD's approximate convex
  decomposition: Wei et al., "Approximate convex decomposition for 3D meshes with collision-
  aware concavity and tree search", SIGGRAPH 2022).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import trimesh

from jassy.errors import JassyError

SPHERE, CAPSULE, BOX, CONVEX, PLANE, MESH, COMPOUND = range(7)


def _positive(value: float, name: str) -> float:
    value = float(value)
    if not np.isfinite(value) or value <= 0:
        raise JassyError(f"{name}: expected a positive length in m, got {value!r}")
    return value


@dataclass(frozen=True)
class Sphere:
    radius: float
    kind = SPHERE

    def __post_init__(self):
        _positive(self.radius, "Sphere.radius")


@dataclass(frozen=True)
class Capsule:
    """A segment from (0, 0, -half_length) to (0, 0, half_length) swept by a sphere of radius."""

    radius: float
    half_length: float
    kind = CAPSULE

    def __post_init__(self):
        _positive(self.radius, "Capsule.radius")
        _positive(self.half_length, "Capsule.half_length")


@dataclass(frozen=True)
class Box:
    half_extents: tuple[float, float, float]
    kind = BOX

    def __post_init__(self):
        if len(self.half_extents) != 3:
            raise JassyError(f"Box.half_extents: expected 3 lengths in m, got {self.half_extents!r}")
        for h in self.half_extents:
            _positive(h, "Box.half_extents")


@dataclass(frozen=True)
class Convex:
    """Convex hull of ``mesh`` (a trimesh.Trimesh, or an (n, 3) array of points in m)."""

    mesh: object
    kind = CONVEX
    hull: trimesh.Trimesh = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        src = self.mesh
        try:
            points = src.vertices if isinstance(src, trimesh.Trimesh) else np.asarray(src, dtype=float)
            hull = trimesh.convex.convex_hull(points)
        except Exception as exc:  # qhull errors: flat or too few points
            raise JassyError(f"Convex.mesh: expected a 3-D point set spanning a volume ({exc})") from exc
        if not hull.is_volume:
            raise JassyError("Convex.mesh: its convex hull is not a closed volume")
        object.__setattr__(self, "hull", hull)


@dataclass(frozen=True)
class Plane:
    """Solid half-space {x : n . x <= offset} (world frame of a static body)."""

    normal: tuple[float, float, float] = (0.0, 0.0, 1.0)
    offset: float = 0.0
    kind = PLANE

    def __post_init__(self):
        n = np.asarray(self.normal, dtype=float)
        if n.shape != (3,) or not np.all(np.isfinite(n)) or np.linalg.norm(n) < 1e-12:
            raise JassyError(f"Plane.normal: expected a non-zero 3-vector, got {self.normal!r}")


@dataclass(frozen=True)
class TriangleMesh:
    """A triangle surface (trimesh.Trimesh or a path trimesh can load); ``thickness`` (m) is
    a skin on the side the face normals point to; points up to ``depth`` (m) behind the
    surface count as penetrating it (deeper ones have passed: choose depth above the
    largest motion of a step, and below the wall's true thickness for a closed solid)."""

    mesh: object
    thickness: float = 0.0
    depth: float = 0.005
    kind = MESH
    surface: trimesh.Trimesh = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        src = self.mesh
        if not isinstance(src, trimesh.Trimesh):
            try:
                src = trimesh.load(src, force="mesh")
            except Exception as exc:
                raise JassyError(
                    f"TriangleMesh.mesh: cannot load {src!r} as a triangle mesh ({exc})"
                ) from exc
        if len(src.faces) == 0:
            raise JassyError("TriangleMesh.mesh: expected at least one triangle")
        if not (self.thickness >= 0 and self.depth > 0):
            raise JassyError(
                f"TriangleMesh: expected thickness >= 0 and depth > 0 m, got {self.thickness}, {self.depth}"
            )
        object.__setattr__(self, "surface", src)


@dataclass(frozen=True)
class Compound:
    """A closed solid ``mesh`` (trimesh.Trimesh, watertight; may be concave) and its convex
    ``pieces`` (point sets or meshes whose hulls cover it, in the mesh's frame). Without
    pieces they are found by CoACD (the ``concave`` extra: pip install coacd) with its
    concavity ``threshold`` (a fraction of the mesh's size; smaller: more, tighter pieces)."""

    mesh: object
    pieces: tuple = ()
    threshold: float = 0.05
    kind = COMPOUND
    surface: trimesh.Trimesh = field(init=False, repr=False, compare=False)
    hulls: tuple = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        src = self.mesh
        if not isinstance(src, trimesh.Trimesh) or not src.is_volume:
            raise JassyError("Compound.mesh: expected a closed (watertight) trimesh.Trimesh")
        pieces = self.pieces if len(self.pieces) else convex_pieces(src, self.threshold)
        hulls = tuple(Convex(p).hull for p in pieces)
        object.__setattr__(self, "surface", src)
        object.__setattr__(self, "hulls", hulls)


def convex_pieces(mesh: trimesh.Trimesh, threshold: float = 0.05, seed: int = 0) -> list[np.ndarray]:
    """Vertex sets (m) of an approximate convex decomposition of the closed ``mesh`` by CoACD
    (concavity below ``threshold`` times the mesh's size)."""
    try:
        import coacd
    except ImportError as exc:
        raise JassyError(
            "Compound: convex decomposition needs CoACD (pip install coacd), or give pieces"
        ) from exc
    coacd.set_log_level("error")
    parts = coacd.run_coacd(coacd.Mesh(mesh.vertices, mesh.faces), threshold=threshold, seed=seed)
    return [np.asarray(vertices, float) for vertices, _ in parts]


Shape = Sphere | Capsule | Box | Convex | Plane | TriangleMesh | Compound


@dataclass(frozen=True)
class MassProperties:
    """mass (kg), principal moments (kg m^2), and the shape-frame pose of the principal frame:
    x_shape = rotation @ x_body + com."""

    mass: float
    inertia: np.ndarray
    com: np.ndarray
    rotation: np.ndarray


def mass_properties(shape: Shape, density: float) -> MassProperties:
    """Mass properties of a solid shape of uniform ``density`` (kg/m^3)."""
    rho = _positive(density, "density")
    eye = np.eye(3)
    zero = np.zeros(3)
    if isinstance(shape, Sphere):
        m = rho * 4.0 / 3.0 * np.pi * shape.radius**3
        return MassProperties(m, np.full(3, 0.4 * m * shape.radius**2), zero, eye)
    if isinstance(shape, Box):
        a, b, c = (2.0 * h for h in shape.half_extents)
        m = rho * a * b * c
        return MassProperties(
            m, m / 12.0 * np.array([b * b + c * c, a * a + c * c, a * a + b * b]), zero, eye
        )
    if isinstance(shape, Capsule):
        r, hl = shape.radius, shape.half_length
        mc = rho * np.pi * r * r * 2.0 * hl  # cylinder
        ms = rho * 4.0 / 3.0 * np.pi * r**3  # two hemispheres
        # hemisphere centroid at 3r/8 beyond the cylinder end
        i_axis = mc * r * r / 2.0 + ms * 0.4 * r * r
        i_perp = mc * (3 * r * r + (2 * hl) ** 2) / 12.0 + ms * (0.4 * r * r + hl * hl + 0.75 * hl * r)
        return MassProperties(mc + ms, np.array([i_perp, i_perp, i_axis]), zero, eye)
    if isinstance(shape, (Convex, Compound)):
        hull = shape.hull if isinstance(shape, Convex) else shape.surface
        props = hull.mass_properties
        m = rho * props["volume"]
        inertia = np.asarray(props["inertia"]) * rho  # about the centre of mass, shape axes
        moments, axes = np.linalg.eigh(inertia)
        if np.linalg.det(axes) < 0:
            axes[:, 0] = -axes[:, 0]
        return MassProperties(m, moments, np.asarray(props["center_mass"], dtype=float), axes)
    raise JassyError(f"{type(shape).__name__}: has no mass (use it for a static or kinematic body)")


def bounding_radius(shape: Shape, com: np.ndarray, rotation: np.ndarray) -> float:
    """Radius (m) of a sphere about the body origin containing the shape (inf for a plane)."""
    if isinstance(shape, Sphere):
        return shape.radius
    if isinstance(shape, Capsule):
        return shape.radius + shape.half_length
    if isinstance(shape, Box):
        return float(np.linalg.norm(shape.half_extents))
    if isinstance(shape, Plane):
        return np.inf
    points = shape.hull.vertices if isinstance(shape, Convex) else shape.surface.vertices
    return float(np.max(np.linalg.norm((points - com) @ rotation, axis=1))) + getattr(shape, "thickness", 0.0)
