"""One haptic update of the burr as one compiled call: moments, normal and depth, elastic
load, the surface pass (friction and erosion) and the octree's refresh.

Agus et al., IEEE VR 2002/2003: m0, m1 of the density in the burr ball; n = -m1/|m1| (out
of the bone; zero when |m1| <= 1e-9 m0 R: burr fully immersed or density symmetric about
its centre); h from m0 = pi rho0 R^3 (h/R)^2 (1 - h/(3R)); F_e = c_e R^2 (h/R)^(3/2) n; the
Hertz contact radius a = sqrt(R h); then :func:`physics.burr.contact.contact_pass`.

The arithmetic outside the voxel kernels is IEEE without fast-math, as numpy does it, so a
step gives the same bits as the same formulas evaluated in Python. Units: SI in and out
(m, N, rad/s, kg), grid units (voxels, counter units) inside.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba as nb
import numpy as np

from jassy.jit import drop_stale_cache
from physics.burr import contact, octree
from physics.burr.contact import (
    Ball,
    Bricks,
    BurrModel,
    ContactData,
    ContactOptions,
    brute_moments,
    contact_pass,
    depth_from_m0,
)
from physics.burr.octree import Pyramid, build_parents, descend

# haptic_update's cache holds copies of the contact and octree kernels it calls
drop_stale_cache(__file__, [contact, octree])

STEP_RESULT = np.dtype(
    [(name, np.float64, (3,)) for name in ("force", "elastic", "friction", "torque", "normal", "m1")]
    + [(name, np.float64) for name in ("m0", "depth", "load", "power", "removed", "expected", "area")]
)
"""What one update returns, by name, all float64: the force of the bone on the burr =
elastic + friction (3,) (N), friction torque about the centre (3,) (N m), the unit normal
(3,) (zeros if undefined), m1 about the centre (3,) (counter m^4); m0 (counter m^3), depth
h (m), load |F_e| (N), frictional power (W), removed and expected counter units, contact
area (m^2)."""


class Burr(NamedTuple):
    """The burr's constants: radius (m) and in voxels, c_e (N/m^2), rho0 (counter units),
    the volume's voxel edge (m), voxel^3 and voxel^4 (as Python computes them), its origin
    (3,) (m), and the octree's leaf (voxels; 0: brute-force moments)."""

    radius: float
    radius_grid: float
    c_e: float
    rho0: float
    voxel: float
    voxel3: float
    voxel4: float
    origin: np.ndarray
    leaf: int


class Moments(NamedTuple):
    """The octree the moments descend (a Pyramid), its stack scratch and the [m0, m1] out
    array (4,)."""

    pyramid: Pyramid
    stack: np.ndarray
    out: np.ndarray


class Pose(NamedTuple):
    """One step's input: burr centre (3,) (m), spin omega (3,) (rad/s), tool velocity (3,)
    (m/s), dt (s), erode (bool)."""

    centre: np.ndarray
    omega: np.ndarray
    velocity: np.ndarray
    dt: float
    erode: bool


@nb.njit(cache=True)
def haptic_update(burr, model, moments, pose, data, result):
    """One step on plain tuples (numba types a plain tuple's fields in C): Burr, BurrModel,
    Moments, Pose, ContactData (its Bricks a plain tuple too); fills result[0]
    (STEP_RESULT) and data.tally."""
    update(Burr(*burr), BurrModel(*model), Moments(Pyramid(*moments[0]), moments[1], moments[2]), Pose(*pose),
         ContactData(data[0], data[1], data[2], data[3], Bricks(*data[4])), result)  # fmt: skip


@nb.njit(cache=True)
def update(burr, model, moments, pose, data, result):
    """One haptic update (module docstring)."""
    centre = pose.centre
    g = np.empty(3)
    for a in range(3):
        g[a] = (centre[a] - burr.origin[a]) / burr.voxel
    mom = moments.out
    if burr.leaf > 0:
        descend(moments.pyramid, Ball(g[0], g[1], g[2], burr.radius_grid), burr.leaf, mom, moments.stack)
    else:
        brute_moments(data.density, g[0], g[1], g[2], burr.radius_grid, mom)
    R = burr.radius
    m0 = mom[0] * burr.voxel3
    m1x = mom[1] * burr.voxel4
    m1y = mom[2] * burr.voxel4
    m1z = mom[3] * burr.voxel4
    norm = math.sqrt(m1x * m1x + m1y * m1y + m1z * m1z)
    normal = np.zeros(3)
    if m0 > 0 and norm > 1e-9 * m0 * R:
        normal[0] = -m1x / norm
        normal[1] = -m1y / norm
        normal[2] = -m1z / norm
    h = depth_from_m0(m0, burr.rho0, R)
    load = burr.c_e * R * R * (h / R) ** 1.5
    a_hertz = math.sqrt(R * h) / burr.voxel
    contact_pass(
        model, ContactOptions(g, normal, a_hertz, load, pose.omega, pose.velocity, pose.dt, pose.erode), data
    )
    t = data.tally[0]
    if burr.leaf > 0 and t.removed > 0:
        p = moments.pyramid
        box = np.array([t.lo_i, t.lo_j, t.lo_k, t.hi_i, t.hi_j, t.hi_k])
        build_parents(p.base, p.top, p.mom, p.off, p.dims, box)
    r = result[0]
    friction = (t.force_x, t.force_y, t.force_z)
    torque = (t.torque_x, t.torque_y, t.torque_z)
    for a in range(3):
        r.m1[a] = mom[1 + a] * burr.voxel4
        r.normal[a] = normal[a]
        r.elastic[a] = load * normal[a]
        r.friction[a] = friction[a]
        r.force[a] = r.elastic[a] + friction[a]
        r.torque[a] = torque[a]
    r.m0 = m0
    r.depth = h
    r.load = load
    r.power = t.power
    r.removed = t.removed
    r.expected = t.expected
    r.area = t.area
