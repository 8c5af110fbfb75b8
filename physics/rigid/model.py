"""The rigid world's compiled records, after MuJoCo's mjModel / mjOption split: a :class:`Model`
of flat arrays that never change during a run (its :class:`Geometry`, masses, materials) and the
:class:`Options` of the step (integrator, contact model, solver settings). Both are
``typing.NamedTuple``s, which numba passes as plain tuples (also from its cache); the stepper's
state and scratch are its ``Data`` (physics.rigid.stepper). world.World builds both records.

Geometry tables are concatenated over bodies (or geometry slots) with a start index per
body: body i's rows of table ``x`` are ``x[x_start[i]:x_start[i + 1]]``. A geometry slot is a
body's polytope (slot i for body i) or one convex piece of a compound (slots after the bodies).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class Geometry(NamedTuple):
    """The bodies' shapes as flat arrays (N bodies, S geometry slots, M meshes): all the
    narrow phase reads (kept apart from the rest of the Model so that a call of the narrow
    phase, made per pair, passes only these)."""

    shape_type: np.ndarray  # (N,) shapes.SPHERE ... COMPOUND
    param: np.ndarray  # (N, 4) sphere (radius); capsule (radius, half length); plane (unit
    #   normal, offset, m); mesh (thickness, depth behind the surface, m)
    bound: np.ndarray  # (N,) bounding radius about the centre of mass, m (inf for a plane)
    vert_start: np.ndarray  # (S + 1,) rows of each slot's polytope vertices in verts
    verts: np.ndarray  # (V, 3) vertices, body (principal) frame, m
    plane_start: np.ndarray  # (S + 1,) rows of each slot's face planes
    planes: np.ndarray  # (F, 4) outward unit normal and offset (m) of each face plane
    hull_start: np.ndarray  # (S + 1,) rows of each slot's hull triangles
    hull_tris: np.ndarray  # (T, 3, 3) hull triangles' corners, m
    mesh_of: np.ndarray  # (N,) the mesh number of a TriangleMesh body, else -1
    tri_start: np.ndarray  # (M + 1,) rows of each mesh's triangles
    tris: np.ndarray  # (MT, 3, 3) mesh triangles' corners, mesh frame, m
    tri_normals: np.ndarray  # (MT, 3) their unit normals
    grid_origin_cell: np.ndarray  # (M, 4) each mesh grid's origin (m) and cell size (m)
    grid_dims: np.ndarray  # (M, 3) each mesh grid's cell counts
    cell_start: np.ndarray  # (M + 1,) rows of each mesh's cells in cell_items_start
    cell_items_start: np.ndarray  # (C,) start of each cell's triangle list in cell_items
    item_start: np.ndarray  # (M + 1,) rows of each mesh's lists in cell_items
    cell_items: np.ndarray  # (I,) triangle numbers of the cells' lists
    tri_spheres: np.ndarray  # (MT, 4) each triangle's bounding sphere (centre, radius), m
    point_start: np.ndarray  # (N + 1,) rows of each body's points in points
    points: np.ndarray  # (P, 4) body points (frame position, radius; m) met by planes, meshes
    edge_start: np.ndarray  # (S + 1,) rows of each slot's hull edges
    edges: np.ndarray  # (E, 18) hull edges: ends p, q, face normals n1, n2, n2 x n1, q - p
    piece_start: np.ndarray  # (N + 1,) rows of each body's geometry slots in piece_slots
    piece_slots: np.ndarray  # (Q,) geometry slots (a polytope: its own; a compound: its pieces)


class Model(NamedTuple):
    """Static arrays of a world's N bodies: their Geometry, kinds, masses and materials."""

    geometry: Geometry
    kind: np.ndarray  # (N,) codes.DYNAMIC, STATIC or KINEMATIC
    mass: np.ndarray  # (N,) kg (1 for a static or kinematic body)
    inertia: np.ndarray  # (N, 3) principal moments, kg m^2 (1 for a static or kinematic body)
    inv_mass: np.ndarray  # (N,) 1/kg, 0 for a static or kinematic body
    inv_inertia: np.ndarray  # (N, 3) 1/(kg m^2), 0 for a static or kinematic body
    restitution: np.ndarray  # (N,) Newton restitution of each body's material
    friction: np.ndarray  # (N,) Coulomb friction coefficient of each body's material
    rolling: np.ndarray  # (N,) rolling resistance length, m
    kinematic: np.ndarray  # (K,) the kinematic bodies, in the order of their path samples


class Options(NamedTuple):
    """Step settings (world.StepParams in SI units and codes)."""

    h: float  # outer step, s
    gx: float  # gravity, m/s^2
    gy: float
    gz: float
    slop: float  # gap (m) below which two bodies touch
    bounce_threshold: float  # approach speed (m/s) above which a contact is an impact
    beta: float  # penetration recovered per step (fraction)
    iterations: int  # most PGS sweeps per solve
    tolerance: float  # sweeps stop when no body's momentum changes more than this (relative)
    integrator: int  # integrate.SEMI_IMPLICIT, RK4 or ADAPTIVE
    adaptive_tolerance: float  # error per step of the adaptive integrator
    contact: int  # codes.IMPULSE, LINEAR or HUNT_CROSSLEY
    stiffness: float  # penalty k, N/m^p
    damping: float  # penalty c, N s/m (linear) or N s/m^(p+1) (Hunt-Crossley)
    exponent: float  # Hunt-Crossley p
    max_events: int  # impact sub-steps per step
    friction_speed: float  # penalty friction's regularisation speed, m/s


def empty_model_tables() -> dict[str, np.ndarray]:
    """Zero-row tables for a world without meshes (the mesh fields of :class:`Geometry`)."""
    return {
        "tri_start": np.zeros(1, np.int64),
        "tris": np.zeros((0, 3, 3)),
        "tri_normals": np.zeros((0, 3)),
        "grid_origin_cell": np.zeros((0, 4)),
        "grid_dims": np.zeros((0, 3), np.int64),
        "cell_start": np.zeros(1, np.int64),
        "cell_items_start": np.zeros(1, np.int64),
        "item_start": np.zeros(1, np.int64),
        "cell_items": np.zeros(0, np.int64),
        "tri_spheres": np.zeros((0, 4)),
    }
