"""A compiled real FFT of a power-of-two length, for numba code (numba has no FFT).

The n real samples are packed into n/2 complex ones, z_j = x_2j + i x_2j+1, transformed by
an iterative radix-2 decimation-in-time FFT (Cooley & Tukey 1965), and unpacked:

    X_k = E_k + e^{-2 pi i k / n} O_k,  E_k = (Z_k + conj Z_{n/2-k}) / 2,
    O_k = (Z_k - conj Z_{n/2-k}) / (2 i),  k = 0 .. n/2

(Press et al., Numerical Recipes, 3rd ed., section 12.3), the first n/2 + 1 bins of the
DFT X_k = sum_t x_t e^{-2 pi i k t / n}, as numpy.fft.rfft gives them. Arrays are the
caller's (no allocation per call): a period's periodogram costs one pass of n/2 log2(n/2)
butterflies inside the compiled decision, with no Python call around it.
"""

from __future__ import annotations

import numba as nb
import numpy as np


def twiddles(n: int) -> np.ndarray:
    """(2, n/2 + 1): cos and sin of 2 pi k / n, k = 0 .. n/2, for :func:`real_spectrum`."""
    angle = 2.0 * np.pi * np.arange(n // 2 + 1) / n
    return np.stack([np.cos(angle), np.sin(angle)])


@nb.njit(cache=True)
def real_spectrum(x, cos, sin, zr, zi, xr, xi):
    """The DFT of the real x (length n, a power of two >= 4) at bins 0 .. n/2: real parts
    into xr, imaginary into xi (n/2 + 1 each); zr, zi (n/2 each) are scratch; cos, sin:
    :func:`twiddles` (n)."""
    n = x.size
    m = n // 2
    for j in range(m):
        zr[j] = x[2 * j]
        zi[j] = x[2 * j + 1]
    j = 0
    for i in range(1, m):  # bit-reversed order
        bit = m >> 1
        while j & bit:
            j ^= bit
            bit >>= 1
        j ^= bit
        if i < j:
            zr[i], zr[j] = zr[j], zr[i]
            zi[i], zi[j] = zi[j], zi[i]
    stage_cos, stage_sin = xr, xi  # the stage's twiddles, contiguous (xr, xi are written only at the end)
    size = 2
    while size <= m:
        half = size // 2
        stride = n // size  # e^{-2 pi i k / size} is entry k * stride of the n-point table
        for k in range(half):
            stage_cos[k] = cos[k * stride]
            stage_sin[k] = -sin[k * stride]
        for s in range(0, m, size):  # each block's butterflies in a row (contiguous a and b)
            for k in range(half):
                a = s + k
                b = a + half
                tr = zr[b] * stage_cos[k] - zi[b] * stage_sin[k]
                ti = zr[b] * stage_sin[k] + zi[b] * stage_cos[k]
                zr[b] = zr[a] - tr
                zi[b] = zi[a] - ti
                zr[a] += tr
                zi[a] += ti
        size *= 2
    for k in range(m + 1):
        a = k if k < m else 0  # k and m - k modulo m, without a division
        b = m - k if k > 0 else 0
        er = 0.5 * (zr[a] + zr[b])
        ei = 0.5 * (zi[a] - zi[b])
        orr = 0.5 * (zi[a] + zi[b])
        oi = -0.5 * (zr[a] - zr[b])
        wr = cos[k]
        wi = -sin[k]
        xr[k] = er + wr * orr - wi * oi
        xi[k] = ei + wr * oi + wi * orr
