"""Kinematics of one constant-curvature element (a circular arc), in stable form.

An element starts at pose (x, y, theta) with curvature kappa; the point at arc length s is
r(s) = (x, y) + e^{i theta} F0(kappa, s) (complex notation, x = Re, y = Im) with the moments

    F_m(kappa, s) = int_0^s sigma^m e^{i kappa sigma} d sigma,   m = 0, 1, 2,

evaluated as s^{m+1} E_m(kappa s), E_m(z) = int_0^1 u^m e^{i z u} du: a power series for
|z| < 0.5 and the integration-by-parts recurrence otherwise, so kappa -> 0 is exact and
continuous (F0 = s sinc(kappa s/2) e^{i kappa s/2}, the chord). Derivatives:
dr/dtheta = i e^{i theta} F0, dr/dkappa = i e^{i theta} F1, d2r/dtheta2 = -e^{i theta} F0,
d2r/dtheta dkappa = -e^{i theta} F1, d2r/dkappa2 = -e^{i theta} F2.
Units: m, rad, 1/m.
"""

from __future__ import annotations

import numba
import numpy as np

NQ = 8
"""Gauss-Legendre points per element for arc integrals (mass, gravity)."""

_xi, _wq = np.polynomial.legendre.leggauss(NQ)
GAUSS_X = 0.5 * (_xi + 1.0)
"""Quadrature nodes on [0, 1]."""
GAUSS_W = 0.5 * _wq
"""Quadrature weights on [0, 1] (sum 1)."""


_INV = 1.0 / np.arange(1.0, 25.0)


@numba.njit(cache=True)
def unit_moments(z: float) -> tuple[complex, complex, complex]:
    """E_m(z) = int_0^1 u^m e^{i z u} du for m = 0, 1, 2: for |z| < 0.5 the series
    sum_k (i z)^k / (k! (k + m + 1)), else the recurrence E_m = (e^{iz} - m E_{m-1}) / (i z)
    (real arithmetic: numba's complex division is slow)."""
    if abs(z) < 0.5:
        r0 = r1 = r2 = i0 = i1 = i2 = 0.0
        t = 1.0  # z^k / k!; i^k cycles through 1, i, -1, -i
        for k in range(22):
            a0, a1, a2 = t * _INV[k], t * _INV[k + 1], t * _INV[k + 2]
            ph = k & 3
            if ph == 0:
                r0, r1, r2 = r0 + a0, r1 + a1, r2 + a2
            elif ph == 1:
                i0, i1, i2 = i0 + a0, i1 + a1, i2 + a2
            elif ph == 2:
                r0, r1, r2 = r0 - a0, r1 - a1, r2 - a2
            else:
                i0, i1, i2 = i0 - a0, i1 - a1, i2 - a2
            t *= z * _INV[k]
            if abs(t) < 1e-18:
                break
        return complex(r0, i0), complex(r1, i1), complex(r2, i2)
    c, s = np.cos(z), np.sin(z)
    inv = 1.0 / z  # (a + i b) / (i z) = (b - i a) / z
    e0 = complex(s * inv, (1.0 - c) * inv)
    e1 = complex((s - e0.imag) * inv, (e0.real - c) * inv)
    e2 = complex((s - 2.0 * e1.imag) * inv, (2.0 * e1.real - c) * inv)
    return e0, e1, e2


@numba.njit(cache=True)
def _moments_flat(kappa, s, out):
    for k in range(kappa.size):
        e0, e1, e2 = unit_moments(kappa[k] * s[k])
        sk = s[k]
        out[0, k] = sk * e0
        out[1, k] = sk * sk * e1
        out[2, k] = sk * sk * sk * e2


def moments(kappa, s) -> np.ndarray:
    """(F0, F1, F2) stacked on a new first axis, broadcasting kappa (1/m) and s (m)."""
    kb, sb = np.broadcast_arrays(np.asarray(kappa, dtype=np.float64), np.asarray(s, dtype=np.float64))
    out = np.empty((3, kb.size), dtype=np.complex128)
    _moments_flat(np.ascontiguousarray(kb).reshape(-1), np.ascontiguousarray(sb).reshape(-1), out)
    return out.reshape((3,) + kb.shape)


def point(x, y, theta, kappa, s) -> np.ndarray:
    """Point at arc length s of the element(s) as complex x + i y."""
    return np.asarray(x) + 1j * np.asarray(y) + np.exp(1j * np.asarray(theta)) * moments(kappa, s)[0]


def end_pose(x, y, theta, kappa, seg) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """End pose Phi = (x+, y+, theta+) of elements of length seg (stable chord form)."""
    r = point(x, y, theta, kappa, seg)
    return r.real, r.imag, np.asarray(theta) + np.asarray(kappa) * np.asarray(seg)


def end_pose_jacobian(theta, kappa, seg) -> np.ndarray:
    """dPhi/d(x, y, theta, kappa), shape (..., 3, 4)."""
    theta, kappa, seg = np.broadcast_arrays(*(np.asarray(a, dtype=np.float64) for a in (theta, kappa, seg)))
    f = moments(kappa, seg)
    rot = np.exp(1j * theta)
    d_theta = 1j * rot * f[0]
    d_kappa = 1j * rot * f[1]
    jac = np.zeros(theta.shape + (3, 4))
    jac[..., 0, 0] = 1.0
    jac[..., 1, 1] = 1.0
    jac[..., 0, 2], jac[..., 1, 2] = d_theta.real, d_theta.imag
    jac[..., 0, 3], jac[..., 1, 3] = d_kappa.real, d_kappa.imag
    jac[..., 2, 2] = 1.0
    jac[..., 2, 3] = seg
    return jac


def position_hessian(theta, kappa, s) -> np.ndarray:
    """Complex second derivatives of r(s) w.r.t. (theta, kappa), shape (..., 2, 2)
    (x part = real, y part = imaginary); all other second derivatives vanish."""
    f = moments(kappa, s)
    rot = -np.exp(1j * np.asarray(theta))
    h = np.empty(f.shape[1:] + (2, 2), dtype=np.complex128)
    h[..., 0, 0] = rot * f[0]
    h[..., 0, 1] = h[..., 1, 0] = rot * f[1]
    h[..., 1, 1] = rot * f[2]
    return h


def forward_kinematics(x0: float, y0: float, theta0: float, kappa: np.ndarray, seg: np.ndarray):
    """Node poses of a chain: (r complex (n+1,), theta (n+1,)); node i = start of element i."""
    theta = theta0 + np.concatenate(([0.0], np.cumsum(kappa * seg)))
    chords = np.exp(1j * theta[:-1]) * moments(kappa, seg)[0]
    r = complex(x0, y0) + np.concatenate(([0j], np.cumsum(chords)))
    return r, theta
