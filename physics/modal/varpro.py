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


class Refined(NamedTuple):
    frequencies: np.ndarray  # Hz
    decays: np.ndarray  # 1/s
    amplitudes: list  # per segment: complex c_k at the segment's first sample
    cost: float  # residual energy (sum over bins and segments of |Y - model|^2)
    cost0: float  # the same at the start


def refine(spectra: list[Spectrum], rate: float, freqs, decays, max_nfev: int = 30) -> Refined:
    """Frequencies (Hz) and decays (1/s) of damped sinusoids shared by the ``spectra``, by
    variable projection from the given start; amplitudes per spectrum by least squares."""
    from scipy.optimize import least_squares

    freqs, decays = np.asarray(freqs, float), np.asarray(decays, float)
    k = freqs.size
    ys = [_real(s.y) for s in spectra]

    def poles(p):
        # a step to d <= 0 would make z^N overflow: such poles are held at a tiny decay
        return np.exp((-np.maximum(p[:k], MIN_DECAY) + 1j * p[k:]) / rate)

    last: dict = {}

    def solve(p):
        # least_squares evaluates the residual and then the Jacobian at the same point
        if last.get("p") is not None and np.array_equal(last["p"], p):
            return last["out"]
        z = poles(p)
        out = []
        for s, y in zip(spectra, ys, strict=True):
            phi, dd, dw = model_columns(z, s.bins, s.n)
            a_phi = np.vstack([phi.real, phi.imag])
            q, r = np.linalg.qr(a_phi)
            coef = np.linalg.lstsq(r, q.T @ y, rcond=None)[0]
            res = y - a_phi @ coef
            out.append((q, coef, res, dd, dw))
        last["p"], last["out"] = p.copy(), out
        return out

    def resid(p):
        return np.concatenate([o[2] for o in solve(p)])

    def jac(p):
        blocks = []
        for q, coef, _, dd, dw in solve(p):
            ab = coef.reshape(k, 2)
            cols = []
            for deriv in (dd, dw):
                # column j: dPhi_j/dtheta_j (a_j, b_j), complex rows -> real
                v = deriv[:, 0::2] * ab[:, 0] + deriv[:, 1::2] * ab[:, 1]
                v = np.vstack([v.real, v.imag]) / rate
                cols.append(-(v - q @ (q.T @ v)))
            blocks.append(np.hstack(cols))
        out = np.vstack(blocks)
        out[:, :k][:, p[:k] < MIN_DECAY] = 0.0  # a clamped decay does not move the model
        return out

    p0 = np.concatenate([decays, 2 * np.pi * freqs])
    r0 = resid(p0)
    cost0 = float(r0 @ r0)
    try:
        sol = least_squares(resid, p0, jac=jac, method="lm", max_nfev=max_nfev, x_scale="jac")
        p = sol.x if np.all(np.isfinite(sol.x)) else p0
    except (ValueError, np.linalg.LinAlgError):  # pragma: no cover - degenerate input
        p = p0
    sols = solve(p)
    cost = float(sum(o[2] @ o[2] for o in sols))
    if not cost <= cost0:
        p, sols, cost = p0, solve(p0), cost0
    amps = [o[1].reshape(k, 2) @ np.array([1.0, 1j]) for o in sols]
    # the decays the cost and the amplitudes were computed with
    return Refined(p[k:] / (2 * np.pi), np.maximum(p[:k], MIN_DECAY), amps, cost, cost0)


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
