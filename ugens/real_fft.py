"""A compiled real FFT of a power-of-two length, for numba code (numba has no FFT).

The n real samples are packed into n/2 complex ones, z_j = x_2j + i x_2j+1, transformed by
an iterative decimation-in-time FFT (Cooley & Tukey 1965), and unpacked:

    X_k = E_k + e^{-2 pi i k / n} O_k,  E_k = (Z_k + conj Z_{n/2-k}) / 2,
    O_k = (Z_k - conj Z_{n/2-k}) / (2 i),  k = 0 .. n/2

(Press et al., Numerical Recipes, 3rd ed., section 12.3), the first n/2 + 1 bins of the
DFT X_k = sum_t x_t e^{-2 pi i k t / n}, as numpy.fft.rfft gives them. Arrays are the
caller's (no allocation per call): a period's periodogram costs one pass of n/2 log2(n/2)
butterflies inside the compiled decision, with no Python call around it.

The radix-2 stages go two at a time (radix 2^2: one pass over the data per two stages, the
second's odd twiddles the first's times -i), four butterflies at once in explicit vectors
(LANES; the compiler leaves the scalar loop scalar: it cannot tell the rows apart), the
first two stages (twiddles 1 and -i) fused with the bit-reversed gather of the samples.
2048 points: 8.9 -> 3.0 us in a hot loop.
"""

from __future__ import annotations

import numba as nb
import numpy as np
from llvmlite import ir
from numba.core import types
from numba.extending import intrinsic

from jassy.jit import drop_stale_cache
from ugens import vector_ir
from ugens.vector_ir import DOUBLE, contiguous, row_pointer

drop_stale_cache(__file__, [vector_ir])  # its cache holds code built by its helpers

#: Butterflies per explicit vector (float64 lanes).
LANES = 4


def twiddles(n: int) -> np.ndarray:
    """(2, n/2 + 1): cos and sin of 2 pi k / n, k = 0 .. n/2, for :func:`real_spectrum`."""
    angle = 2.0 * np.pi * np.arange(n // 2 + 1) / n
    return np.stack([np.cos(angle), np.sin(angle)])


def _times(builder, ar, ai, wr, wi):
    """(ar + i ai)(wr + i wi), lane by lane: (real, imaginary)."""
    real = builder.fsub(builder.fmul(ar, wr), builder.fmul(ai, wi))
    return real, builder.fadd(builder.fmul(ar, wi), builder.fmul(ai, wr))


def _lanes(context, builder, signature, args, count):
    """Pointers to LANES floats of zr and zi at p + k + j h (j < count) and of the twiddle
    rows wr, wi at k and h + k (the :func:`butterflies` arguments ``args``)."""
    zr, zi, wr, wi, p, h, k = args
    vector = ir.VectorType(DOUBLE, LANES)
    at = [builder.add(p, k)]
    for _ in range(count - 1):
        at.append(builder.add(at[-1], h))
    rows = [row_pointer(context, builder, signature.args[0], zr, i, vector) for i in at]
    rows += [row_pointer(context, builder, signature.args[1], zi, i, vector) for i in at]
    twiddle = [k, builder.add(h, k)]
    tw = [row_pointer(context, builder, signature.args[2], wr, i, vector) for i in twiddle]
    tw += [row_pointer(context, builder, signature.args[3], wi, i, vector) for i in twiddle]
    return rows, tw


def _typed(zr, zi, wr, wi, p, h, k):
    """The signature of a butterfly intrinsic, or None for other arguments."""
    if all(contiguous(a) for a in (zr, zi, wr, wi)) and all(isinstance(i, types.Integer) for i in (p, h, k)):
        return types.void(zr, zi, wr, wi, types.intp, types.intp, types.intp)
    return None


@intrinsic
def radix4_lanes(typingctx, zr, zi, wr, wi, p, h, k):
    """Two radix-2 stages (sub-transforms of h points -> 2h -> 4h) at butterflies k .. k +
    LANES - 1 of the block at p (z = zr + i zi in place; quarters at p, p + h, p + 2h,
    p + 3h): twiddles e^{-2 pi i k / 4h} at wr[k], wi[k] and e^{-2 pi i k / 2h} at wr[h + k],
    wi[h + k]."""
    signature = _typed(zr, zi, wr, wi, p, h, k)
    if signature is None:
        return None

    def codegen(context, builder, signature, args):
        rows, tw = _lanes(context, builder, signature, args, 4)
        zr0, zr1, zr2, zr3, zi0, zi1, zi2, zi3 = (builder.load(r, align=8) for r in rows)
        w4r, w2r, w4i, w2i = (builder.load(t, align=8) for t in tw)
        t1r, t1i = _times(builder, zr1, zi1, w2r, w2i)
        t3r, t3i = _times(builder, zr3, zi3, w2r, w2i)
        a0r, a0i, a1r, a1i = (
            builder.fadd(zr0, t1r),
            builder.fadd(zi0, t1i),
            builder.fsub(zr0, t1r),
            builder.fsub(zi0, t1i),
        )
        a2r, a2i, a3r, a3i = (
            builder.fadd(zr2, t3r),
            builder.fadd(zi2, t3i),
            builder.fsub(zr2, t3r),
            builder.fsub(zi2, t3i),
        )
        ur, ui = _times(builder, a2r, a2i, w4r, w4i)
        qr, qi = _times(builder, a3r, a3i, w4r, w4i)  # then times -i: (qi, -qr)
        results = (
            builder.fadd(a0r, ur), builder.fadd(a1r, qi), builder.fsub(a0r, ur), builder.fsub(a1r, qi),
            builder.fadd(a0i, ui), builder.fsub(a1i, qr), builder.fsub(a0i, ui), builder.fadd(a1i, qr),
        )  # fmt: skip
        for row, value in zip(rows, results, strict=True):
            builder.store(value, row, align=8)
        return context.get_dummy_value()

    return signature, codegen


@intrinsic
def radix2_lanes(typingctx, zr, zi, wr, wi, p, h, k):
    """One radix-2 stage (h points -> 2h) at butterflies k .. k + LANES - 1 of the block at
    p (halves at p, p + h): twiddles e^{-2 pi i k / 2h} at wr[h + k], wi[h + k]."""
    signature = _typed(zr, zi, wr, wi, p, h, k)
    if signature is None:
        return None

    def codegen(context, builder, signature, args):
        rows, tw = _lanes(context, builder, signature, args, 2)
        zr0, zr1, zi0, zi1 = (builder.load(r, align=8) for r in rows)
        tr, ti = _times(builder, zr1, zi1, builder.load(tw[1], align=8), builder.load(tw[3], align=8))
        results = builder.fadd(zr0, tr), builder.fsub(zr0, tr), builder.fadd(zi0, ti), builder.fsub(zi0, ti)
        for row, value in zip(rows, results, strict=True):
            builder.store(value, row, align=8)
        return context.get_dummy_value()

    return signature, codegen


@nb.njit(cache=True)
def first_stages(x, zr, zi):
    """z_j = x_2j + i x_2j+1 (j < m = x.size / 2) into zr, zi in bit-reversed order, its
    first two radix-2 stages taken on the way (twiddles 1 and -i; one for m = 2). Returns
    the size of the sub-transforms done."""
    m = x.size // 2
    if m == 2:
        zr[0], zi[0] = x[0] + x[2], x[1] + x[3]
        zr[1], zi[1] = x[0] - x[2], x[1] - x[3]
        return 2
    quarter = m // 4
    r = 0  # q bit-reversed over log2(quarter) bits: z_r, z_r+m/2, z_r+m/4, z_r+3m/4 go to 4q .. 4q + 3
    for q in range(quarter):
        a, b, c, d = 2 * r, 2 * r + m, 2 * r + m // 2, 2 * r + m + m // 2
        s0r, s0i, d0r, d0i = x[a] + x[b], x[a + 1] + x[b + 1], x[a] - x[b], x[a + 1] - x[b + 1]
        s1r, s1i, d1r, d1i = x[c] + x[d], x[c + 1] + x[d + 1], x[c] - x[d], x[c + 1] - x[d + 1]
        i = 4 * q
        zr[i], zi[i], zr[i + 2], zi[i + 2] = s0r + s1r, s0i + s1i, s0r - s1r, s0i - s1i
        zr[i + 1], zi[i + 1], zr[i + 3], zi[i + 3] = d0r + d1i, d0i - d1r, d0r - d1i, d0i + d1r
        bit = quarter >> 1
        while r & bit:
            r ^= bit
            bit >>= 1
        r ^= bit
    return 4


@nb.njit(cache=True)
def stage_twiddles(cos, sin, n, wr, wi, h, quarter):
    """e^{-2 pi i k / 2h} into wr[h + k], wi[h + k] (k < h) from the n-point table (cos,
    sin: :func:`twiddles`); ``quarter``: also e^{-2 pi i k / 4h} into wr[k], wi[k]."""
    step = n // (2 * h)
    for k in range(h):
        wr[h + k] = cos[k * step]
        wi[h + k] = -sin[k * step]
    if quarter:
        for k in range(h):  # (4h <= n / 2: step is even)
            wr[k] = cos[k * (step // 2)]
            wi[k] = -sin[k * (step // 2)]


@nb.njit(cache=True)
def real_spectrum(x, cos, sin, zr, zi, xr, xi):
    """The DFT of the real x (length n, a power of two >= 4) at bins 0 .. n/2: real parts
    into xr, imaginary into xi (n/2 + 1 each); zr, zi (n/2 each) are scratch; cos, sin:
    :func:`twiddles` (n). zr, zi, xr and xi are C-contiguous float64 (the passes run in
    explicit vectors over them); other lengths or shorter arrays raise ValueError."""
    n = x.size
    m = n // 2
    if n < 4 or n & (n - 1) or min(zr.size, zi.size) < m or min(xr.size, xi.size) < m + 1:
        raise ValueError("real_spectrum: expected n a power of two >= 4, scratch of n/2, outputs of n/2 + 1")
    if min(cos.size, sin.size) < m + 1:
        raise ValueError("real_spectrum: expected twiddles of n/2 + 1")
    size = first_stages(x, zr, zi)
    stages = 0
    while size << stages < m:
        stages += 1
    if stages % 2 == 1:  # one radix-2 stage, then two at a time
        stage_twiddles(cos, sin, n, xr, xi, size, False)  # (xr, xi are written only at the end)
        for p in range(0, m, 2 * size):
            for k in range(0, size, LANES):
                radix2_lanes(zr, zi, xr, xi, p, size, k)
        size *= 2
    while size < m:
        stage_twiddles(cos, sin, n, xr, xi, size, True)
        for p in range(0, m, 4 * size):
            for k in range(0, size, LANES):
                radix4_lanes(zr, zi, xr, xi, p, size, k)
        size *= 4
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
