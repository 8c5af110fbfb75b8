"""Spatial-vector rigid-body kinematics and Newton-Euler dynamics (body frame, angular first).

A body's frame sits at its centre of mass with axes along its principal axes, so its spatial
inertia is M = diag(I1, I2, I3, m, m, m). Its twist phi = (omega; v) is expressed in that
frame. Newton-Euler in the body frame (Pai, Ascher & Kry, ICRA 2000):

    f = M dphi/dt - [phi]^T M phi,   [phi] = [[w^, 0], [v^, w^]],

i.e. tau = I dw/dt + w x I w and F = m (dv/dt + w x v). Orientation is a unit quaternion
(w, x, y, z) with dq/dt = q (0, omega)/2; positions are world coordinates of the centre of
mass, dp/dt = R v.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np


@nb.njit(cache=True)
def quat_mul(a, b):
    """Hamilton product a b of quaternions (w, x, y, z)."""
    return np.array(
        [
            a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
            a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
            a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1],
            a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0],
        ]
    )


@nb.njit(cache=True)
def quat_exp(rotvec):
    """Unit quaternion of the rotation by the vector ``rotvec`` (rad; the exponential map)."""
    angle = math.sqrt(rotvec[0] ** 2 + rotvec[1] ** 2 + rotvec[2] ** 2)
    half = 0.5 * angle
    # sin(half)/angle, with its series below 1e-4 rad (error < 1e-17)
    s = math.sin(half) / angle if angle > 1e-4 else 0.5 - angle * angle / 48.0
    return np.array([math.cos(half), s * rotvec[0], s * rotvec[1], s * rotvec[2]])


@nb.njit(cache=True)
def quat_log(q):
    """Rotation vector (rad) of the unit quaternion ``q`` (shortest rotation)."""
    w = q[0]
    v = q[1:4]
    if w < 0.0:
        w = -w
        v = -v
    n = math.sqrt(v[0] ** 2 + v[1] ** 2 + v[2] ** 2)
    if n < 1e-12:
        return 2.0 * v / max(w, 1e-300)
    return 2.0 * math.atan2(n, w) / n * v


@nb.njit(cache=True)
def quat_to_mat(q):
    """Rotation matrix of the unit quaternion ``q``."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


@nb.njit(cache=True)
def cross(a, b):
    """a x b of 3-vectors."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


@nb.njit(cache=True)
def dot3(a, b):
    """a . b of 3-vectors (no BLAS call)."""
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@nb.njit(cache=True)
def mv(m, x):
    """m x for a 3 x 3 matrix (no BLAS call)."""
    return np.array(
        [
            m[0, 0] * x[0] + m[0, 1] * x[1] + m[0, 2] * x[2],
            m[1, 0] * x[0] + m[1, 1] * x[1] + m[1, 2] * x[2],
            m[2, 0] * x[0] + m[2, 1] * x[1] + m[2, 2] * x[2],
        ]
    )


@nb.njit(cache=True)
def mtv(m, x):
    """m^T x for a 3 x 3 matrix (no BLAS call)."""
    return np.array(
        [
            m[0, 0] * x[0] + m[1, 0] * x[1] + m[2, 0] * x[2],
            m[0, 1] * x[0] + m[1, 1] * x[1] + m[2, 1] * x[2],
            m[0, 2] * x[0] + m[1, 2] * x[1] + m[2, 2] * x[2],
        ]
    )


@nb.njit(cache=True)
def newton_euler(inertia, mass, phi, wrench):
    """dphi/dt of a body with principal moments ``inertia`` (kg m^2) and ``mass`` (kg) under the
    body-frame ``wrench`` (torque N m; force N): M^-1 (f + [phi]^T M phi)."""
    w = phi[:3]
    v = phi[3:]
    iw = inertia * w
    out = np.empty(6)
    out[:3] = (wrench[:3] - cross(w, iw)) / inertia
    out[3:] = wrench[3:] / mass - cross(w, v)
    return out


def hat(a: np.ndarray) -> np.ndarray:
    """The cross-product matrix [a] with [a] b = a x b."""
    return np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])


def spatial_cross(phi: np.ndarray) -> np.ndarray:
    """[phi] = [[w^, 0], [v^, w^]] (6 x 6), the spatial cross-product matrix of a twist."""
    out = np.zeros((6, 6))
    out[:3, :3] = out[3:, 3:] = hat(phi[:3])
    out[3:, :3] = hat(phi[3:])
    return out


def spatial_inertia(inertia: np.ndarray, mass: float, com: np.ndarray | None = None) -> np.ndarray:
    """6 x 6 spatial inertia of a body with 3 x 3 (or principal) inertia about its centre of
    mass, seen from a frame whose origin is at -com from the centre of mass (com = centre of
    mass in that frame): [[I - m c^ c^, m c^], [-m c^, m 1]]."""
    i_c = np.diag(inertia) if np.ndim(inertia) == 1 else np.asarray(inertia, dtype=float)
    c = hat(np.zeros(3) if com is None else np.asarray(com, dtype=float))
    out = np.zeros((6, 6))
    out[:3, :3] = i_c - mass * c @ c
    out[:3, 3:] = mass * c
    out[3:, :3] = -mass * c
    out[3:, 3:] = mass * np.eye(3)
    return out


def kinetic_energy(inertia: np.ndarray, mass: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """1/2 phi^T M phi per body (J); phi (N, 6), inertia (N, 3), mass (N,)."""
    return 0.5 * (np.sum(inertia * phi[:, :3] ** 2, axis=1) + mass * np.sum(phi[:, 3:] ** 2, axis=1))


def rotation_matrices(quat: np.ndarray) -> np.ndarray:
    """(N, 3, 3) rotation matrices of (N, 4) unit quaternions."""
    w, x, y, z = quat.T
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        axis=1,
    )
