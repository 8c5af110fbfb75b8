"""Closed-form and analytic references for validating the finite element modes.

* Free-free Euler-Bernoulli beam: roots of cos(x) cosh(x) = 1 (x = beta L = 4.7300, 7.8532,
  10.9956, ...), f_n = x_n^2 / (2 pi L^2) sqrt(E I / (rho A)).
* Free elastic sphere (Lamb 1882, "On the vibrations of an elastic sphere"; Eringen &
  Suhubi, "Elastodynamics" vol. 2, sec. 8.13). With x = omega a / c_s (c_s = sqrt(mu/rho)):

  - torsional modes of degree n: (n - 1) j_n(x) = x j_{n+1}(x);
  - spheroidal modes of degree n: det [[sigma_rr^P, sigma_rr^S], [tau^P, tau^S]] = 0 at r = a,
    built from the two regular solutions u = grad(j_n(h r) Y_n) and
    u = curl curl(r j_n(k r) Y_n) (h = omega/c_p, k = omega/c_s), whose radial and
    tangential displacement amplitudes are U_P = h j_n'(h r), V_P = j_n(h r)/r and
    U_S = n(n+1) j_n(k r)/r, V_S = (r j_n(k r))'/r; sigma_rr = lambda div u + 2 mu U',
    tau = mu (V' - V/r + U/r).
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import brentq
from scipy.special import spherical_jn


def free_free_beta_l(count: int = 3) -> np.ndarray:
    """The first ``count`` roots x of cos(x) cosh(x) = 1 with x > 0 (free-free beam)."""
    roots = []
    for m in range(1, count + 1):
        guess = (2 * m + 1) * np.pi / 2
        roots.append(brentq(lambda x: np.cos(x) * np.cosh(x) - 1.0, guess - 0.5, guess + 0.5, xtol=1e-14))
    return np.array(roots)


def free_free_beam_frequencies(
    length: float, width: float, thickness: float, youngs: float, density: float, count: int = 3
) -> np.ndarray:
    """Euler-Bernoulli bending frequencies (Hz) of a free-free rectangular bar bending across
    ``thickness``: f_n = (beta_n L)^2 / (2 pi L^2) sqrt(E t^2 / (12 rho))."""
    x = free_free_beta_l(count)
    return x**2 / (2 * np.pi * length**2) * np.sqrt(youngs * thickness**2 / (12 * density))


def _roots(func, lo: float, hi: float, count: int, step: float = 0.01) -> np.ndarray:
    """The first ``count`` sign changes of func (vectorised) on [lo, hi], refined by brentq."""
    xs = np.arange(lo, hi, step)
    with np.errstate(all="ignore"):
        vals = func(xs)
    ok = np.isfinite(vals[:-1]) & np.isfinite(vals[1:]) & (np.sign(vals[:-1]) != np.sign(vals[1:]))
    brackets = np.flatnonzero(ok)[:count]
    return np.array([brentq(func, xs[i], xs[i + 1], xtol=1e-13) for i in brackets])


def sphere_torsional_roots(n: int, count: int = 1) -> np.ndarray:
    """x = omega a / c_s of the torsional modes of degree n >= 1 (n = 1, first root: rotation
    excluded) of a free sphere: roots of (n - 1) j_n(x) - x j_{n+1}(x)."""

    def f(x):
        return (n - 1) * spherical_jn(n, x) - x * spherical_jn(n + 1, x)

    return _roots(f, 0.5, 60.0, count)


def _j(n, x, d=0):
    """Spherical Bessel j_n and its first two derivatives (d = 0, 1, 2)."""
    if d == 0:
        return spherical_jn(n, x)
    if d == 1:
        return spherical_jn(n, x, derivative=True)
    # j'' = -(2/x) j' - (1 - n(n+1)/x^2) j (the spherical Bessel equation)
    return -(2 / x) * spherical_jn(n, x, derivative=True) - (1 - n * (n + 1) / x**2) * spherical_jn(n, x)


def sphere_spheroidal_determinant(x: float, n: int, poisson: float) -> float:
    """The traction-free determinant of spheroidal modes of degree n at x = omega a / c_s
    (sphere radius a = 1, mu = 1)."""
    ratio = np.sqrt((1 - 2 * poisson) / (2 * (1 - poisson)))  # c_s / c_p
    mu = 1.0
    lam = 2 * mu * poisson / (1 - 2 * poisson)
    k, h, r = x, x * ratio, 1.0
    # P (dilatational) solution
    up, dup = h * _j(n, h * r, 1), h * h * _j(n, h * r, 2)
    vp, dvp = _j(n, h * r) / r, h * _j(n, h * r, 1) / r - _j(n, h * r) / r**2
    srr_p = lam * (-(h**2) * _j(n, h * r)) + 2 * mu * dup
    tau_p = mu * (dvp - vp / r + up / r)
    # S (equivoluminal, poloidal) solution
    nn = n * (n + 1)
    us = nn * _j(n, k * r) / r
    dus = nn * (k * _j(n, k * r, 1) / r - _j(n, k * r) / r**2)
    g = _j(n, k * r) + k * r * _j(n, k * r, 1)  # (r j)'
    dg = 2 * k * _j(n, k * r, 1) + k * k * r * _j(n, k * r, 2)
    vs, dvs = g / r, dg / r - g / r**2
    srr_s = 2 * mu * dus
    tau_s = mu * (dvs - vs / r + us / r)
    if n == 0:
        return srr_p
    return srr_p * tau_s - srr_s * tau_p  # works elementwise on arrays of x


def sphere_spheroidal_roots(n: int, poisson: float, count: int = 1) -> np.ndarray:
    """x = omega a / c_s of the spheroidal modes of degree n of a free sphere (for n = 1 the
    rigid translation x = 0 is excluded)."""
    return _roots(lambda x: sphere_spheroidal_determinant(x, n, poisson), 0.3, 60.0, count)


def sphere_frequency(x: float, radius: float, youngs: float, poisson: float, density: float) -> float:
    """f = x c_s / (2 pi a) in Hz."""
    cs = np.sqrt(youngs / (2 * (1 + poisson)) / density)
    return x * cs / (2 * np.pi * radius)
