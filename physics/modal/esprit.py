"""Subspace estimation of damped exponentials: band signals, pooled ESPRIT with a noise-based
model order, and least-squares amplitudes with fixed poles.

ESPRIT (Roy & Kailath 1989, "ESPRIT - estimation of signal parameters via rotational
invariance techniques"): the rows of the Hankel matrix of a sum of K damped exponentials
z_k^n span the K vectors (1, z_k, z_k^2, ...); the signal subspace, shifted by one sample,
is the same subspace rotated by diag(z_k). Several signals with the same poles (strikes,
channels) stack their Hankel rows, so one eigendecomposition of the summed Gram matrix
pools them all (Badeau, David & Richard 2006 use the same structure in subbands).

Model order: a noise eigenvalue of the Gram matrix of R rows of stationary noise is at most
about R S (1 + sqrt(M/R))^2 (Marchenko-Pastur edge, M = window width, S = the largest noise
power density in the band, per sample); eigenvalues above ``margin`` times that are signal.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from physics.modal import varpro
from physics.modal._fit_kernels import hankel_gram, project, synthesise


class Band(NamedTuple):
    """A decimated complex band signal: y[m] ~ x band-passed around ``centre`` Hz and shifted
    to 0 Hz, at ``rate`` samples/s; ``noise`` = the noise power density per sample of y in the
    flat part of the band (the Gram noise eigenvalue scale)."""

    y: np.ndarray
    rate: float
    centre: float
    noise: float


def band_signal(spectrum, n_fft, n_valid, rate, centre, flat, edge, noise_bins) -> Band:
    """Band of the zero-padded spectrum ``spectrum`` (length ``n_fft`` complex FFT of a real
    signal of ``n_valid`` samples at ``rate``): flat gain 1 within ``flat`` Hz of ``centre``,
    cosine taper to 0 at ``edge`` Hz, decimated to about 2.5 x edge samples/s. ``noise_bins``
    = the noise |X_k|^2 level for every bin (its median over the flat part is the band's)."""
    bin_hz = rate / n_fft
    kc = int(round(centre / bin_hz))
    half = int(math.ceil(edge / bin_hz))
    flat_bins = flat / bin_hz
    size = 1 << int(math.ceil(math.log2(max(2.5 * 2 * half, 16))))
    ks = np.arange(kc - half, kc + half + 1)
    dist = np.abs(ks - kc)
    win = np.where(
        dist <= flat_bins,
        1.0,
        0.5 + 0.5 * np.cos(np.pi * np.clip((dist - flat_bins) / (half - flat_bins), 0, 1)),
    )
    inside = (ks > 0) & (ks < n_fft // 2)
    sub = np.zeros(size, dtype=complex)
    sub[(ks[inside] - kc) % size] = spectrum[ks[inside]] * win[inside]
    y = np.fft.ifft(sub) * (size / n_fft)
    n_sub = int(n_valid * size / n_fft)
    flat_k = ks[inside & (dist <= flat_bins)]
    level = float(np.median(noise_bins[flat_k])) if flat_k.size else 0.0
    return Band(y[:n_sub], size * bin_hz, kc * bin_hz, level * size / n_fft**2)


def pooled_gram(signals, width: int) -> tuple[np.ndarray, int]:
    """(sum of Hankel Gram matrices of the signals, total number of rows)."""
    g = np.zeros((width, width), dtype=np.complex128)
    rows = 0
    for y in signals:
        if y.size > width:
            hankel_gram(np.ascontiguousarray(y, dtype=np.complex128), width, g)
            rows += y.size - width + 1
    return g, rows


def esprit_poles(gram: np.ndarray, rows: int, noise: float, margin: float, max_order: int) -> np.ndarray:
    """Poles z (complex, per sample) of the signal subspace of a pooled Gram matrix: the
    eigenvectors whose eigenvalues exceed ``margin`` x the noise edge (at most ``max_order``),
    rotated by one sample (total least squares ESPRIT)."""
    width = gram.shape[0]
    vals, vecs = np.linalg.eigh(gram)
    vals, vecs = vals[::-1], vecs[:, ::-1]
    edge = rows * noise * (1 + math.sqrt(width / max(rows, 1))) ** 2
    order = int(np.sum(vals > margin * edge))
    order = min(order, max_order, width // 2)
    if order == 0:
        return np.zeros(0, dtype=complex)
    # rows of H are combinations of conj(eigenvectors)^T of H^H H: the subspace is conj(V)
    v = np.conj(vecs[:, :order])
    top, bottom = v[:-1], v[1:]
    # total least squares: the right singular vectors of [top bottom]
    _, _, wh = np.linalg.svd(np.hstack([top, bottom]), full_matrices=False)
    w = np.conj(wh.T)
    w12, w22 = w[:order, order:], w[order:, order:]
    try:
        psi = -w12 @ np.linalg.inv(w22)
    except np.linalg.LinAlgError:
        psi = np.linalg.lstsq(top, bottom, rcond=None)[0]
    z = np.linalg.eigvals(psi)
    return z[np.isfinite(z) & (np.abs(z) > 1e-12)]


def amplitudes(x: np.ndarray, z: np.ndarray, excluded: np.ndarray | None = None) -> np.ndarray:
    """Complex c_k with x[n] ~ Re(sum_k c_k z_k^n) (real x, poles of positive frequency) by
    least squares over all n < len(x) except ``excluded`` indices. The Gram matrix of the
    basis {z_k^n, conj(z_k)^n} is a closed-form geometric sum, the right-hand side one pass
    per pole (numba), so the cost is O(len(x) K + K^3), not O(len(x) K^2)."""
    k = z.size
    if k == 0:
        return np.zeros(0, dtype=complex)
    basis = np.concatenate([z, np.conj(z)])
    n = x.size
    q = np.conj(basis)[:, None] * basis[None, :]
    with np.errstate(all="ignore"):
        near = np.abs(1 - q) < 1e-12
        gram = np.where(near, n, (1 - q**n) / np.where(near, 1, 1 - q))
    weight = np.ones(n)
    if excluded is not None and excluded.size:
        weight[excluded] = 0.0
        powers = np.exp(np.outer(excluded.astype(np.float64), np.log(basis)))
        gram = gram - np.conj(powers).T @ powers
    rhs = np.zeros(k, dtype=complex)
    project(np.ascontiguousarray(x, dtype=np.float64).astype(np.complex128), weight, z, rhs)
    b = np.concatenate([rhs, np.conj(rhs)])
    ridge = 1e-12 * float(np.max(np.abs(np.diag(gram)).real))
    try:
        a = np.linalg.solve(gram + ridge * np.eye(2 * k), b)
    except np.linalg.LinAlgError:
        a = np.linalg.lstsq(gram, b, rcond=None)[0]
    return 2 * a[:k]


def resynthesis(n: int, z: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Re(sum_k c_k z_k^t), t < n."""
    out = np.zeros(n)
    if z.size:
        synthesise(
            n, np.ascontiguousarray(z, dtype=np.complex128), np.ascontiguousarray(c, dtype=np.complex128), out
        )
    return out


def refine(
    signals, rate: float, z0: np.ndarray, real: bool = False, max_nfev: int = 12, max_samples: int = 1500
):
    """Maximum-likelihood poles in white noise: poles shared by the ``signals`` (y[n] ~ sum_k
    c_k z_k^n, one set of c per signal; with ``real``, real signals y ~ Re(sum_k c_k z_k^n))
    refined from ``z0`` by variable projection (:func:`varpro.separable_fit`: amplitudes
    eliminated per signal, Levenberg-Marquardt on each pole's decay and frequency, with
    d/ds z^n = n z^n / rate for s = -decay + i omega). ESPRIT alone is biased towards
    undamped poles when much of the record is noise. Returns (poles, amplitudes per signal)."""
    signals = [np.asarray(y[:max_samples]) for y in signals]
    if z0.size == 0 or not any(y.size for y in signals):
        return z0, [np.zeros(z0.size, dtype=complex) for _ in signals]
    ts = [np.arange(y.size)[:, None] / rate for y in signals]
    # a step to a growing pole is held at e^50 over the longest signal (no overflow)
    min_decay = -50.0 / max(max(t[-1, 0] for t in ts if t.size), 1.0 / rate)
    rows = (lambda a: a.real) if real else (lambda a: np.vstack([a.real, a.imag]))

    def design(i, d, w):
        # columns c_k z^n = a_k e + b_k (i e), e = e^{s t}; d/d decay = -t, d/d omega = i t
        e = np.exp(ts[i] * (-d + 1j * w))
        pair = np.empty((e.shape[0], 2 * e.shape[1]), dtype=complex)
        pair[:, 0::2], pair[:, 1::2] = e, 1j * e
        return varpro.Design(rows(pair), rows(-ts[i] * pair), rows(1j * ts[i] * pair))

    ys = [y.real.astype(float) if real else np.concatenate([y.real, y.imag]) for y in signals]
    # a degenerate start (a pole at 0, a non-finite sample) is kept by separable_fit: its
    # inf/NaN arithmetic on the way is expected, not a warning for the user
    with np.errstate(divide="ignore", invalid="ignore"):
        logz = np.log(z0)
        fit = varpro.separable_fit(design, ys, -logz.real * rate, logz.imag * rate, min_decay, max_nfev,
                                   xtol=1e-10, ftol=1e-12)  # fmt: skip
        # the poles the cost and the amplitudes were computed with
        return np.exp((-fit.decays + 1j * fit.omegas) / rate), fit.amplitudes
