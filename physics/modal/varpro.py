"""Joint maximum-likelihood refinement of damped sinusoids in the frequency domain, by
variable projection.

A real segment x[n] = Re(sum_k c_k z_k^n) + noise, n < N, has the length-N DFT

    X[m] = sum_k (c_k / 2) B(z_k)[m] + (conj(c_k) / 2) B(conj(z_k))[m],
    B(z)[m] = (1 - z^N) / (1 - z e^{-2 pi i m / N})

in closed form (a geometric sum; e^{-2 pi i m} = 1). The DFT is unitary up to a scale, so
white noise stays white and independent across bins, and a least-squares fit over the bins
near a group of poles is their maximum-likelihood fit given the other poles (subtracted):
it uses every sample of the segment at the cost of a few bins per hertz, with no band
filter and no filter transient to cut away (a band filter's transient takes the first
0.04-0.16 s, where a fast mode has most of its energy). Poles are shared by all segments
(strikes, channels), amplitudes are each segment's own.

Variable projection (Golub & Pereyra 1973, "The differentiation of pseudo-inverses and
nonlinear least squares problems whose variables separate"): the amplitudes are eliminated
by linear least squares, Levenberg-Marquardt moves only (decay, frequency) of each pole,
with Kaufman's (1975) Jacobian -P_perp (dPhi/dtheta) a.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

#: Least decay (1/s) a refined pole takes: a step to d <= 0 would make z^N overflow.
MIN_DECAY = 1e-3


class Spectrum(NamedTuple):
    """Bins ``bins`` (indices m of a length-``n`` DFT) of one segment and its values ``y``."""

    bins: np.ndarray
    y: np.ndarray
    n: int


def basis(z: np.ndarray, bins: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(B, dB): B(z)[m] (columns = poles) and its derivative with respect to log z."""
    u = np.exp(-2j * np.pi * bins / n)[:, None]
    q = z[None, :] * u
    zn = (z**n)[None, :]
    one_q = 1.0 - q
    b = (1.0 - zn) / one_q
    db = (-n * zn * one_q + (1.0 - zn) * q) / one_q**2
    return b, db


def model_columns(z: np.ndarray, bins: np.ndarray, n: int):
    """(Phi, dPhi/dd, dPhi/domega) for real amplitudes (a_k, b_k) of Re((a + i b) z^n) =
    a Re z^n - b Im z^n; columns [a_0, b_0, a_1, b_1, ...], rows = bins (complex).
    d = decay (1/s), omega (rad/s) with log z = (-d + i omega) / fs, derivatives per fs."""
    b, db = basis(z, bins, n)
    bc, dbc = basis(np.conj(z), bins, n)
    k = z.size
    phi = np.empty((bins.size, 2 * k), dtype=complex)
    phi[:, 0::2] = (b + bc) / 2
    phi[:, 1::2] = 1j * (b - bc) / 2
    # d/dd: dlogz = -1 (both); d/domega: dlogz = +i for z, -i for conj(z)
    dd = np.empty_like(phi)
    dd[:, 0::2] = -(db + dbc) / 2
    dd[:, 1::2] = -1j * (db - dbc) / 2
    dw = np.empty_like(phi)
    dw[:, 0::2] = 1j * (db - dbc) / 2
    dw[:, 1::2] = -(db + dbc) / 2
    return phi, dd, dw


def _real(a: np.ndarray) -> np.ndarray:
    return np.concatenate([a.real, a.imag])


class Design(NamedTuple):
    """Real least-squares columns of K poles for one signal: ``phi`` (rows x 2K, columns
    [a_0, b_0, a_1, b_1, ...] for the real amplitudes of c_k = a_k + i b_k) and the
    derivatives of each column with respect to its own pole's decay (1/s) and angular
    frequency (rad/s)."""

    phi: np.ndarray
    by_decay: np.ndarray
    by_omega: np.ndarray


class Separated(NamedTuple):
    """Result of :func:`separable_fit`."""

    decays: np.ndarray  # 1/s (at least the clamp the cost was computed with)
    omegas: np.ndarray  # rad/s
    amplitudes: list  # per signal: complex c_k = a_k + i b_k
    cost: float  # residual energy summed over the signals
    cost0: float  # the same at the start


def separable_fit(design, ys, decays, omegas, min_decay: float, max_nfev: int, **options) -> Separated:
    """Decays and angular frequencies of K poles shared by the real signals ``ys``, each with
    its own linear amplitudes, by variable projection (Golub & Pereyra 1973): the amplitudes
    are eliminated by least squares per signal (one QR of its 2K columns), Levenberg-Marquardt
    moves only the 2K pole parameters, with Kaufman's (1975) Jacobian -P_perp (dPhi/dtheta) a.
    ``design(i, decays, omegas)`` gives the :class:`Design` of signal i. Decays are held at
    ``min_decay`` or above (their Jacobian columns there are zero); a result whose cost is
    not below the start's keeps the start; degenerate input (a non-finite signal or design,
    a design least squares cannot solve) keeps the start with zero amplitudes and NaN
    costs. ``options`` go to scipy's ``least_squares``."""
    from scipy.optimize import least_squares

    k = np.size(decays)
    last: dict = {}

    def solve(p):
        # least_squares evaluates the residual and then the Jacobian at the same point
        if last.get("p") is not None and np.array_equal(last["p"], p):
            return last["out"]
        d = np.maximum(p[:k], min_decay)
        out = []
        for i, y in enumerate(ys):
            cols = design(i, d, p[k:])
            q, r = np.linalg.qr(cols.phi)
            coef = np.linalg.lstsq(r, q.T @ y, rcond=None)[0]
            out.append((q, coef, y - cols.phi @ coef, cols))
        last["p"], last["out"] = p.copy(), out
        return out

    def resid(p):
        return np.concatenate([o[2] for o in solve(p)])

    def jac(p):
        blocks = []
        for q, coef, _, cols in solve(p):
            ab = coef.reshape(k, 2)
            parts = []
            for deriv in (cols.by_decay, cols.by_omega):
                # column j of the model's derivative: dPhi_j/dtheta_j (a_j, b_j)
                v = deriv[:, 0::2] * ab[:, 0] + deriv[:, 1::2] * ab[:, 1]
                parts.append(-(v - q @ (q.T @ v)))
            blocks.append(np.hstack(parts))
        out = np.vstack(blocks)
        out[:, :k][:, p[:k] < min_decay] = 0.0  # a clamped decay does not move the model
        return out

    def settled(p):
        """(per-signal solutions, cost) at p, or None where the input is degenerate (a
        non-finite signal or design, a design least squares cannot solve)."""
        try:
            sols = solve(p)
        except (ValueError, np.linalg.LinAlgError):
            return None
        cost = float(sum(o[2] @ o[2] for o in sols))
        return (sols, cost) if math.isfinite(cost) else None

    p0 = np.concatenate([np.asarray(decays, float), np.asarray(omegas, float)])
    start = settled(p0)
    if start is None:  # the start kept, no amplitudes
        zero = [np.zeros(k, dtype=complex) for _ in ys]
        return Separated(np.maximum(p0[:k], min_decay), p0[k:], zero, math.nan, math.nan)
    try:
        sol = least_squares(resid, p0, jac=jac, method="lm", max_nfev=max_nfev, **options)
        p = sol.x if np.all(np.isfinite(sol.x)) else p0
    except (ValueError, np.linalg.LinAlgError):
        p = p0
    end = settled(p)
    if end is None or not end[1] <= start[1]:
        p, end = p0, start
    amps = [o[1].reshape(k, 2) @ np.array([1.0, 1j]) for o in end[0]]
    return Separated(np.maximum(p[:k], min_decay), p[k:], amps, end[1], start[1])


class Refined(NamedTuple):
    frequencies: np.ndarray  # Hz
    decays: np.ndarray  # 1/s
    amplitudes: list  # per segment: complex c_k at the segment's first sample
    cost: float  # residual energy (sum over bins and segments of |Y - model|^2)
    cost0: float  # the same at the start


def refine(spectra: list[Spectrum], rate: float, freqs, decays, max_nfev: int = 30) -> Refined:
    """Frequencies (Hz) and decays (1/s) of damped sinusoids shared by the ``spectra``, by
    variable projection (:func:`separable_fit`) from the given start; amplitudes per
    spectrum by least squares."""
    freqs = np.asarray(freqs, float)

    def design(i, d, w):
        s = spectra[i]
        phi, dd, dw = model_columns(np.exp((-d + 1j * w) / rate), s.bins, s.n)
        return Design(np.vstack([phi.real, phi.imag]), _rows(dd) / rate, _rows(dw) / rate)

    fit = separable_fit(design, [_real(s.y) for s in spectra], decays, 2 * np.pi * freqs, MIN_DECAY,
                        max_nfev, x_scale="jac")  # fmt: skip
    return Refined(fit.omegas / (2 * np.pi), fit.decays, fit.amplitudes, fit.cost, fit.cost0)


def _rows(a: np.ndarray) -> np.ndarray:
    """Complex rows -> real rows (real parts, then imaginary parts)."""
    return np.vstack([a.real, a.imag])


def fast_length(n: int) -> int:
    """The largest 2^a 3^b 5^c <= n (a DFT length numpy transforms quickly)."""
    best = 1
    p2 = 1
    while p2 <= n:
        p3 = p2
        while p3 <= n:
            p5 = p3
            while p5 <= n:
                best = max(best, p5)
                p5 *= 5
            p3 *= 3
        p2 *= 2
    return best


def half_width(decay):
    """Half-power half-width (Hz) of a mode decaying at ``decay`` 1/s (a number or an array)."""
    return decay / (2 * math.pi)
