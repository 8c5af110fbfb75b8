"""numba kernels of the modal fit: Hankel Gram matrices, projections on damped exponentials,
and their synthesis. All loops are over samples inside numba; nothing allocates per sample."""

from __future__ import annotations

import numba as nb
import numpy as np


@nb.njit(cache=True)
def hankel_gram(x, width, out):
    """out += H^H H for the Hankel matrix H[r, j] = x[r + j] (rows r = 0 .. len(x) - width).

    The first row is a correlation (O(len(x) width)); every further entry follows from the
    one up and to the left by removing one product and adding one (O(width^2)), instead of
    the O(len(x) width^2) of forming H.
    """
    rows = x.size - width + 1
    g = np.zeros((width, width), dtype=np.complex128)
    for j in range(width):
        acc = 0j
        for r in range(rows):
            acc += np.conj(x[r]) * x[r + j]
        g[0, j] = acc
    for i in range(1, width):
        for j in range(i, width):
            g[i, j] = (
                g[i - 1, j - 1] - np.conj(x[i - 1]) * x[j - 1] + np.conj(x[rows + i - 1]) * x[rows + j - 1]
            )
    for i in range(width):
        for j in range(i, width):
            out[i, j] += g[i, j]
            if j != i:
                out[j, i] += np.conj(g[i, j])


@nb.njit(cache=True)
def project(x, weight, z, out):
    """out[k] = sum_n weight[n] x[n] conj(z[k])^n (the right-hand side of the least squares
    for amplitudes of z[k]^n; weight is 0 at excluded samples, else 1)."""
    for k in range(z.size):
        zc = np.conj(z[k])
        p = 1.0 + 0j
        acc = 0j
        for n in range(x.size):
            if weight[n] != 0.0:
                acc += x[n] * p
            p *= zc
            if abs(p) < 1e-300:
                break
        out[k] = acc


@nb.njit(cache=True)
def synthesise(n, z, c, out):
    """out[t] += Re(sum_k c[k] z[k]^t) for t < n (recursive powers, stopped once negligible)."""
    for k in range(z.size):
        p = c[k]
        zk = z[k]
        for t in range(n):
            out[t] += p.real
            p *= zk
            if abs(p) < 1e-30:
                break
