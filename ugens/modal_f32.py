"""Float32 modal resonators in the "delta" form, and the bound that says which modes may use it.

The two-pole recursion y[n] = c1 y[n-1] - c2 y[n-2] + g F[n-1] fails in float32 for low,
lightly damped modes: c1 = 2 R cos(theta) is close to 2 and rounding it to 24 bits loses
most of theta^2, i.e. the frequency. Written for the increment Delta[n] = y[n] - y[n-1],

    Delta[n] = Delta[n-1] - b2 Delta[n-1] - c0 y[n-1] + g F[n-1],   y[n] = y[n-1] + Delta[n],

with c0 = 1 - c1 + c2 = (1 - R)^2 + 4 R sin^2(theta / 2) and b2 = 1 - c2 = 1 - R^2, the
same recursion keeps the full relative precision of the small coefficients (the
delta-operator form: Middleton and Goodwin, "Improved finite word
length characteristics in digital control using delta operators", IEEE Trans. Automat.
Contr. 31(11), 1986). Both are computed in float64 and rounded once to float32; what
remains is that rounding: a frequency error of about 2^-25 omega and a decay error of
about 2^-24 d, whose effect on the response a e^{-d t} sin(omega t) peaks at
(|d omega| + |d d|) / (d e) of a (at t = 1/d). :func:`float32_error` evaluates this for
the coefficients actually rounded, relative to the mode's own peak, plus the state's
rounding noise; modes above the tolerance stay in float64 ("mixed precision"): very
high Q only, omega / d above about 3e4-1e5 depending on how the coefficients happen to
round (of 20 Hz-20 kHz x 0.5-500 /s: 6.3 kHz and 20 kHz at d = 0.5 /s).

The state is kept divided by the mode's input gain g, so the force enters with an add:
per mode and sample 3 FMA + 2 adds (with the output sum) in float32 lanes, twice as many
as float64's, against 2 FMA + 1 multiply + 1 add of the float32 two-pole form. Modes
with g = 0 (or below MIN_GAIN) stay in float64.
"""

from __future__ import annotations

from typing import NamedTuple

import numba as nb
import numpy as np

from jassy.jit import drop_stale_cache
from ugens import cells, kernels, stack_rows, vector_ir, vector_pass
from ugens.cells import two_pole
from ugens.kernels import FASTMATH

drop_stale_cache(__file__, [cells, kernels, stack_rows, vector_ir, vector_pass])  # its cache holds their code

#: A float32 mode's worst error, relative to its own peak, that is accepted: -70 dB,
#: 10 dB inside the -60 dB bound, so that errors of many modes summed stay within it.
TOLERANCE = 10 ** (-70 / 20)

_EPS32 = 2.0**-24  # float32 unit roundoff


def delta_coefficients(c1: np.ndarray, c2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(c0, b2) = (1 - c1 + c2, 1 - c2) in float64 from the two-pole coefficients.

    c1 and c2 carry float64 rounding of about 1e-16 absolute, so c0 ~ theta^2 and b2 ~
    2 d / fs keep a relative precision of 1e-9 or better even for 20 Hz, d = 0.5 /s at
    48 kHz: far below the float32 rounding that follows."""
    return (1.0 - c1) + c2, 1.0 - c2


def _pole(c0: np.ndarray, b2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(theta, decay per sample) of the pole from (c0, b2), without cancellation."""
    log_r = 0.5 * np.log1p(-b2)
    one_minus_r = -np.expm1(log_r)
    r = 1.0 - one_minus_r
    sin2_half = np.maximum(c0 - one_minus_r * one_minus_r, 0.0) / (4.0 * r)
    theta = 2.0 * np.arcsin(np.sqrt(np.minimum(sin2_half, 1.0)))
    return theta, -log_r


def float32_error(c1: np.ndarray, c2: np.ndarray, sample_rate: float) -> np.ndarray:
    """Worst error of each mode's impulse response in the float32 delta form, relative to
    the peak of its exact response (dimensionless; 0 for silent modes, c2 = 0).

    Coefficient rounding: the pole realised by the float32 (c0, b2) against the float64
    one, dw and dd in 1/s, giving (|dw| + |dd|) max_t t e^{-d t} = (|dw| + |dd|) / (d e).
    State rounding: 2^-24 of the amplitude per sample in y and in Delta (whose rounding,
    2^-24 of theta times the amplitude, moves the amplitude by as much), as a random walk
    over the decay time's fs / d samples. The sum is divided by the response's peak e^{-d t*} sin(omega t*),
    t* = atan2(omega, d) / omega.
    """
    return _rounding_error(c1, c2, sample_rate, decay_factor=False)


def decay_factor_error(c1: np.ndarray, c2: np.ndarray, sample_rate: float) -> np.ndarray:
    """As :func:`float32_error` for the decay-factor form, whose second coefficient is
    R^2 - c0 = 1 - b2 - c0 rounded to float32 (:func:`factor_coefficient`): its absolute
    rounding, up to 2^-25, moves the realised R^2 and so the decay by up to fs 2^-26
    (7e-4 /s at 48 kHz), so light modes (d below a few 1/s) may fail where the delta form
    holds."""
    return _rounding_error(c1, c2, sample_rate, decay_factor=True)


def _rounding_error(c1, c2, sample_rate: float, decay_factor: bool) -> np.ndarray:
    """:func:`float32_error` (sample_rate in Hz) of the delta or (``decay_factor``) decay-factor form."""
    sounding = c2 > 0.0
    c0, b2 = delta_coefficients(np.where(sounding, c1, 0.0), np.where(sounding, c2, 0.25))
    theta, rho = _pole(c0, b2)
    c0_32 = c0.astype(np.float32).astype(np.float64)
    if decay_factor:
        b2_32 = 1.0 - (factor_coefficient(c0, b2).astype(np.float64) + c0_32)
    else:
        b2_32 = b2.astype(np.float32).astype(np.float64)
    theta32, rho32 = _pole(c0_32, b2_32)
    omega, decay = theta * sample_rate, np.maximum(rho * sample_rate, 1e-12)
    drift = (np.abs(theta32 - theta) + np.abs(rho32 - rho)) * sample_rate / (decay * np.e)
    noise = 2.0 * _EPS32 * np.sqrt(sample_rate / decay)
    t_peak = np.arctan2(omega, decay) / np.maximum(omega, 1e-12)
    peak = np.exp(-decay * t_peak) * np.sin(omega * t_peak)
    return np.where(sounding, (drift + noise) / np.maximum(peak, 1e-300), 0.0)


def factor_coefficient(c0: np.ndarray, b2: np.ndarray) -> np.ndarray:
    """The decay-factor form's second coefficient in float32: R^2 - c0 = 1 - b2 - c0 with
    c0 as rounded to float32, so that the realised R^2 (this plus the float32 c0, exact
    in float64) is R^2 to within this coefficient's own rounding."""
    return ((1.0 - b2) - c0.astype(np.float32).astype(np.float64)).astype(np.float32)


#: Flags of the per-mode update: contraction into FMA, no reassociation, so that the
#: update stays two independent FMAs and an add (reassociated, LLVM spends a multiply and
#: more adds on it, and the adds are the scarcer units at small banks).
_UPDATE_FLAGS = {"contract", "nsz", "arcp"}

#: Modes whose input gain is smaller than this (in magnitude) stay in float64: the float32
#: state is scaled by 1 / g (:func:`narrow_rows`).
MIN_GAIN = 1e-30


@nb.njit(fastmath=_UPDATE_FLAGS, cache=True)
def _next_delta(v, p, u, c0, b, f, by_factor):
    """The scaled Delta[n] from v = Delta[n-1] / g, p = y[n-2] / g, u = y[n-1] / g and
    F[n-1] = f (float32).

    Delta form (b = b2): Delta[n] = (F - c0 y[n-1]) + (Delta[n-1] - b2 Delta[n-1]), two FMA
    on independent operands and an add; a mode's recursion waits for y[n-1] = y[n-2] +
    Delta[n-1] (an add), an FMA and an add per sample. Decay-factor form (``by_factor``, b
    = R^2 - c0): with y[n-1] = y[n-2] + Delta[n-1], Delta[n] = R^2 Delta[n-1] - c0 y[n-1]
    + F is (R^2 - c0) Delta[n-1] + (F - c0 y[n-2]): the term in y[n-2] is ready a sample
    early, so Delta waits one FMA per sample on itself, as the two-pole form's y does (its
    path through y[n-2], an add and two FMA, spans two samples)."""
    if by_factor:
        return b * v + (f - c0 * p)
    return (f - c0 * u) + (v - b * v)


#: The float32 rows hold a multiple of this many modes and the kernel runs whole multiples:
#: LLVM's vector loop takes 32 float32 modes per step with AVX-512 (16 lanes, two
#: interleaved; 16 with AVX2), and the modes left over ran in a 4-lane loop (at 254
#: modes, 30 of them took half the time of the other 224).
LANES = 32

#: Rows of float64 modes that resonate_narrow's explicit vectors take hold a multiple of
#: this many modes (one AVX-512 vector of float64: ugens.vector_pass.add_wide_chunk).
WIDE_LANES = vector_pass.WIDE_VECTOR

#: Banks of at most this many float32 modes and no float64 modes run with their rows held
#: on the kernel's stack (:func:`resonate_held`): 4 vectors of 16 float32 lanes per row with
#: AVX-512, five rows and the four output sums fit the 32 vector registers.
HELD_MODES = 64

#: Whether the kernels written with LLVM intrinsics (ugens.stack_rows, ugens.vector_pass)
#: run: not with numba's JIT disabled (NUMBA_DISABLE_JIT=1, where kernels run as Python and
#: intrinsics cannot), which takes the general loop instead.
EXPLICIT_VECTORS = not nb.config.DISABLE_JIT

#: The rows of a float32 bank start this many bytes apart modulo 4 KiB. Rows a multiple of
#: 4 KiB apart (1024 modes) made the loads of one row wait on the stores to another with
#: the same low 12 address bits (4K aliasing): the kernel ran at half speed or full speed
#: depending on where the arrays happened to be allocated.
ROW_SPREAD = 512


def float32_rows(rows: int, width: int) -> np.ndarray:
    """Zeros (rows, stride) in float32, C-contiguous, starting on a 64-byte cache-line
    boundary, with stride >= width floats such that rows start ROW_SPREAD bytes apart
    modulo 4 KiB (``width`` a multiple of LANES: every row starts on a line, and vector
    loads never straddle lines)."""
    stride = width + ((ROW_SPREAD - 4 * width) % 4096) // 4
    raw = np.zeros(rows * stride + 16, np.float32)
    skip = (-raw.ctypes.data % 64) // 4
    return raw[skip : skip + rows * stride].reshape(rows, stride)


def narrow_rows(c0, b2, g, d, y1, y2, delta_end: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(coef, state): the float32 rows (c0, b2 for the modes [0, ``delta_end``) in the delta
    form, R^2 - c0 (:func:`factor_coefficient`) for the rest, in the decay-factor form;
    g, d) and (y[n-2] / g, Delta[n-1] / g) of modes with float64 coefficients c0, b2
    (:func:`delta_coefficients`), gains g, direct gains d and state y[n-1] = y1, y[n-2] =
    y2, padded to a multiple of LANES modes (the rows may be longer: :func:`float32_rows`).
    ``delta_end`` None: every mode in the delta form. A padding mode has c0 = 1 and b2 = 1
    (R^2 = 0, R^2 - c0 = -1), so its y[n] = F[n-1] stays bounded, and g = d = 0, so it
    adds exact zeros."""
    n = g.size
    width = -(-n // LANES) * LANES
    delta_end = width if delta_end is None else delta_end
    rows = float32_rows(6, width)
    coef, state = rows[:4], rows[4:]
    in_delta = np.arange(n) < delta_end
    coef[:, :n] = np.stack([c0, np.where(in_delta, b2, factor_coefficient(c0, b2)), g, d])
    coef[0, n:] = 1.0
    coef[1, n:] = np.where(np.arange(n, coef.shape[1]) < delta_end, 1.0, -1.0)
    state[:, :n] = np.stack([y2 / g, (y1 - y2) / g])
    return coef, state


def order_by_form(c1: np.ndarray, c2: np.ndarray, sample_rate: float, tolerance: float = TOLERANCE):
    """(order, delta_end) for float32 modes with two-pole coefficients c1, c2 (sample_rate
    in Hz): the modes whose decay-factor form misses ``tolerance``
    (:func:`decay_factor_error`) first, then the others, each group in its own order, and
    how many leading modes run in the delta form: those, rounded up to whole LANES (the
    kernels take one form per chunk of LANES modes), 0 if none."""
    misses = decay_factor_error(c1, c2, sample_rate) > tolerance
    order = np.concatenate([np.flatnonzero(misses), np.flatnonzero(~misses)])
    return order, -(-int(misses.sum()) // LANES) * LANES


def unscaled_state(state: np.ndarray, g: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(y[n-1], y[n-2]) in float64 of the ``g.size`` modes of :func:`narrow_rows`' state,
    y[n-1] summed in float32 as the kernel sums it."""
    p, dy = state[:, : g.size]
    return (p + dy).astype(np.float64) * g, p.astype(np.float64) * g


class DeltaRows(NamedTuple):
    """Float32 delta-form modes as :func:`resonate_delta` reads them, one entry per mode:
    the coefficients c0 = 1 - c1 + c2, b2 = 1 - c2 (R^2 - c0 in the decay-factor form),
    input gain g and direct gain d, and the state scaled by the input gain, y = y[n-2] / g,
    dy = Delta[n-1] / g (y[n-1] / g = y + dy)."""

    c0: np.ndarray
    b2: np.ndarray
    g: np.ndarray
    d: np.ndarray
    y: np.ndarray
    dy: np.ndarray


@nb.njit(inline="always", cache=True)
def delta_rows(coef, state):
    """The DeltaRows of coefficient rows (c0, b2, g, d) and state rows (y[n-2], Delta[n-1]) / g."""
    return DeltaRows(coef[0], coef[1], coef[2], coef[3], state[0], state[1])


@nb.njit(inline="always", cache=True)
def _four_samples(c0, b, p, v, fp, f0, f1, f2, by_factor):
    """A float32 mode with coefficients c0, b (:func:`_next_delta`) and scaled state p = y[n-2]
    / g, v = Delta[n-1] / g over four samples whose preceding forces are fp, f0, f1, f2:
    its new (p, v) and its four scaled outputs y[n] / g. Scalars in and out, so that the
    callers' mode loops stay free of array references and vectorise (inlined, it takes
    their fastmath flags)."""
    u = p + v
    v = _next_delta(v, p, u, c0, b, fp, by_factor)
    p = u
    u0 = u + v
    v = _next_delta(v, p, u0, c0, b, f0, by_factor)
    u1 = u0 + v
    v = _next_delta(v, u0, u1, c0, b, f1, by_factor)
    u2 = u1 + v
    v = _next_delta(v, u1, u2, c0, b, f2, by_factor)
    u3 = u2 + v
    return u2, v, u0, u1, u2, u3


@nb.njit(inline="always", cache=True)
def _wide_one(wide, count, fw):
    """One sample of the float64 modes [0, count) of ``wide`` whose preceding force is fw (N,
    the two-pole recursion of ugens.modal.resonate): their output sum."""
    t = 0.0
    for k in range(count):
        v = two_pole(wide.c1[k], wide.c2[k], wide.y1[k], wide.y2[k], wide.g[k] * fw)
        wide.y2[k] = wide.y1[k]
        wide.y1[k] = v
        t += v
    return t


@nb.njit(inline="always", cache=True)
def _direct_gain(d, count, direct):
    """``direct`` + d[0] + ... + d[count - 1] in float64, in that order: the direct gain of
    ``count`` modes added to ``direct``."""
    for k in range(count):
        direct += d[k]
    return direct


@nb.njit(inline="always", cache=True)
def _one_sample(rows, count, fp, delta_end):
    """One sample of the float32 modes [0, count) of ``rows`` (DeltaRows or HeldRows; modes
    [0, delta_end) in the delta form, the rest in the decay-factor form) whose preceding
    force is fp (float32, N): their state advanced, their output sum (float32)."""
    s = np.float32(0.0)
    for k in range(count):
        p = rows.y[k]
        u = p + rows.dy[k]
        v = _next_delta(rows.dy[k], p, u, rows.c0[k], rows.b2[k], fp, k >= delta_end)
        rows.y[k] = u
        rows.dy[k] = v
        s += rows.g[k] * (u + v)
    return s


@nb.njit(inline="always", cache=True)
def _tail(force, out, i, rows, count, wide, wide_active, last, delta_end, add):
    """The samples i .. len(force) - 1 after the four-sample passes (fewer than four; callers
    pass the force up to the block's end), one at a time:
    the float32 modes [0, count) of ``rows`` (:func:`_one_sample`, ``delta_end``) and the float64 modes
    [0, wide_active) of ``wide`` (None: none) over force (N), their sum added to out (the
    bank's output units) with ``add``, else written."""
    n = force.shape[0]
    while i < n:
        fw = force[i - 1] if i > 0 else last[0]
        s = _one_sample(rows, count, np.float32(fw), delta_end)
        if wide is not None:
            s = s + _wide_one(wide, wide_active, fw)
        if add:
            out[i] += s
        else:
            out[i] = s
        i += 1


@nb.njit(inline="always", cache=True)
def _finish(force, out, start, n, direct, last):
    """Add the direct term direct F[i] (force in N) to out[start:n] (after the passes: a
    scalar held across the mode loops takes a vector register) and leave last[0] at
    force[n - 1]."""
    if direct != 0.0:
        for i in range(start, n):
            out[i] += direct * force[i]
    if n > 0:
        last[0] = force[n - 1]


@nb.njit(fastmath=FASTMATH, cache=True)
def _wide_pass(wide, count, force, i, last):
    """The float64 modes [0, count) of ``wide`` (ugens.cells.ModeRows) advanced over
    force[i:i + 4] (N; last[0] is the sample before force[0]) as in resonate_delta's
    passes: their four output sums (the bank's output units)."""
    fw = force[i - 1] if i > 0 else last[0]
    w0 = force[i]
    w1 = force[i + 1]
    w2 = force[i + 2]
    t0 = t1 = t2 = t3 = 0.0
    for k in range(count):
        q1 = wide.c1[k]
        q2 = wide.c2[k]
        gk = wide.g[k]
        u1 = wide.y1[k]
        u2 = wide.y2[k]
        v0 = two_pole(q1, q2, u1, u2, gk * fw)
        v1 = two_pole(q1, q2, v0, u1, gk * w0)
        v2 = two_pole(q1, q2, v1, v0, gk * w1)
        v3 = two_pole(q1, q2, v2, v1, gk * w2)
        wide.y2[k] = v2
        wide.y1[k] = v3
        t0 += v0
        t1 += v1
        t2 += v2
        t3 += v3
    return t0, t1, t2, t3


@nb.njit(fastmath=FASTMATH, cache=True)
def resonate_delta(force, out, n, rows, active, wide, wide_active, last, delta_end):
    """Add the float32 modes [0, active) of ``rows`` and the float64 modes [0, wide_active)
    of ``wide`` over force[:n] to out[:n]; the float32 modes [0, delta_end) in the delta
    form, the rest in the decay-factor form (b2 holds R^2 - c0 there, :func:`narrow_rows`).

    ``rows``: a DeltaRows of float32 arrays (the state scaled by the input gain: the force
    enters with an add instead of a multiply and g weighs the output sum with an FMA).
    ``wide``: None (no float64 modes), or the float64 modes' ugens.cells.ModeRows,
    updated by the two-pole recursion of ugens.modal.resonate in the same passes (a mixed
    bank's few very-high-Q modes: in a pass of their own, 2 modes cost 10 % of 256; here
    their scalar updates fill the float32 loop's waits). With None (a type of its own)
    numba compiles a kernel without that loop: at 64 modes its presence cost 5 %.
    force (N) and out (the bank's output units) float64, C-contiguous. last[0]: the force
    sample before force[0] (N), left at force[n-1]. The direct term sum(d) F[n] is added as
    in ugens.modal.resonate, after the passes. Four samples per pass over the modes, as
    there. The float32 modes run up to the next multiple of LANES within the rows
    (:func:`narrow_rows`' padding, or modes silenced by the flush: exact zeros that stay
    zero without force, and with force every mode is active)."""
    c0, b2, g, d, y, dy = rows
    active = min(-(-active // LANES) * LANES, c0.size)
    split = min(delta_end, active)
    direct = _direct_gain(d, active, 0.0)
    if wide is not None:
        direct = _direct_gain(wide.d, wide_active, direct)
    i = 0
    while i + 4 <= n:
        # Only the loop's own values stay in registers across the float32 loop (scalars
        # share the vector registers; a direct term and the float64 force samples held
        # there cost 4 % at 64 modes): the force is read again where it is needed.
        fp = np.float32(force[i - 1] if i > 0 else last[0])
        f0 = np.float32(force[i])
        f1 = np.float32(force[i + 1])
        f2 = np.float32(force[i + 2])
        s0 = np.float32(0.0)
        s1 = np.float32(0.0)
        s2 = np.float32(0.0)
        s3 = np.float32(0.0)
        for by_factor in (False, True):  # the modes [0, delta_end), then the rest
            for k in range(split if by_factor else 0, active if by_factor else split):
                gk = g[k]
                y[k], dy[k], u0, u1, u2, u3 = _four_samples(
                    c0[k], b2[k], y[k], dy[k], fp, f0, f1, f2, by_factor
                )
                s0 += gk * u0
                s1 += gk * u1
                s2 += gk * u2
                s3 += gk * u3
        t0 = t1 = t2 = t3 = 0.0
        if wide is not None:
            t0, t1, t2, t3 = _wide_pass(wide, wide_active, force, i, last)
        out[i] += s0 + t0
        out[i + 1] += s1 + t1
        out[i + 2] += s2 + t2
        out[i + 3] += s3 + t3
        i += 4
    _tail(force[:n], out, i, rows, active, wide, wide_active, last, delta_end, True)
    _finish(force, out, 0, n, direct, last)


class HeldRows(NamedTuple):
    """A :class:`DeltaRows` without the direct gains, as ugens.vector_pass takes the modes:
    in :func:`_held_passes` copies on the kernel's stack (ugens.stack_rows) of one
    constant width, in :func:`resonate_chunks` the bank's own rows."""

    c0: np.ndarray
    b2: np.ndarray
    g: np.ndarray
    y: np.ndarray
    dy: np.ndarray


@nb.njit(inline="always", cache=True)
def _hold(rows, held):
    """Copy the float32 modes [0, width) of ``rows`` (DeltaRows) to ``held`` (HeldRows of
    constant width, on the stack); return their direct gain sum(d) in float64."""
    c0, b2, g, y, dy = held
    direct = 0.0
    for k in range(c0.size):
        c0[k] = rows.c0[k]
        b2[k] = rows.b2[k]
        g[k] = rows.g[k]
        y[k] = rows.y[k]
        dy[k] = rows.dy[k]
        direct += rows.d[k]
    return direct


@nb.njit(inline="always", cache=True)
def _release(force, out, start, n, rows, held, direct, last):
    """Copy the held state back to ``rows``, add the direct term to out[start:n] and leave
    last[0] at force[n - 1] (:func:`_finish`). The direct term is added after the passes:
    added as each sample is written (in float64, or in float32 from the force samples of
    the pass), it made the kernel 4-13 % slower at 16 and 64 modes."""
    for k in range(held.y.size):
        rows.y[k] = held.y[k]
        rows.dy[k] = held.dy[k]
    _finish(force, out, start, n, direct, last)


@nb.njit(inline="always", cache=True)
def _held_passes(force, out, n, rows, held, last, width):
    """Write the float32 modes [0, width) of ``rows`` over force[:n] (with their direct term)
    to out[:n] (as :func:`resonate_delta` adds them), in the decay-factor form, on their
    copies in ``held`` (HeldRows of the literal ``width``, on the stack), where LLVM keeps
    them in vector registers across the passes. Each pass in explicit vectors
    (ugens.vector_pass.write_four: the four output sums reduced together, the direct term
    added and the four samples converted and stored as one vector)."""
    direct = _hold(rows, held)
    i = 0
    while i + 4 <= n:
        fp = np.float32(force[i - 1] if i > 0 else last[0])
        vector_pass.write_four(width, held, fp, force, out, i, direct)
        i += 4
    _tail(force[:n], out, i, held, held.c0.size, None, 0, last, 0, False)
    _release(force, out, i, n, rows, held, direct, last)


@nb.njit(fastmath=FASTMATH, cache=True)
def _held_16(force, out, n, rows, last):
    """:func:`_held_passes` for 16 modes (one AVX-512 vector per row)."""
    row = stack_rows.stack_row
    _held_passes(force, out, n, rows, HeldRows(row(16), row(16), row(16), row(16), row(16)), last, 16)


@nb.njit(fastmath=FASTMATH, cache=True)
def _held_32(force, out, n, rows, last):
    """:func:`_held_passes` for 32 modes."""
    row = stack_rows.stack_row
    _held_passes(force, out, n, rows, HeldRows(row(32), row(32), row(32), row(32), row(32)), last, 32)


@nb.njit(fastmath=FASTMATH, cache=True)
def _held_64(force, out, n, rows, last):
    """:func:`_held_passes` for 64 modes."""
    row = stack_rows.stack_row
    _held_passes(force, out, n, rows, HeldRows(row(64), row(64), row(64), row(64), row(64)), last, 64)


@nb.njit(cache=True)
def held_width(active):
    """The mode count :func:`resonate_held` runs for ``active`` float32 modes (1 ..
    HELD_MODES): the next of 16, 32, 64."""
    return 16 if active <= 16 else (32 if active <= 32 else 64)


@nb.njit(cache=True)
def resonate_held(force, out, n, rows, active, last):
    """Write (not add) 1 .. HELD_MODES float32 modes in the decay-factor form over force[:n]
    (float64, N) to out[:n] (float64, the bank's output units), as :func:`resonate_delta`
    computes them with no float64 modes: the modes [0, :func:`held_width`) held on the
    stack (:func:`_held_passes`; the padding and silenced modes beyond ``active`` hold
    exact zeros, as in the general loop). The general loop, like the C two-pole loop,
    loads and stores every mode's state on every pass."""
    width = held_width(active)
    if width == 16:
        _held_16(force, out, n, rows, last)
    elif width == 32:
        _held_32(force, out, n, rows, last)
    else:
        _held_64(force, out, n, rows, last)


@nb.njit(fastmath=FASTMATH, cache=True)
def resonate_chunks(force, out, n, rows, active, wide, wide_active, last, delta_end):
    """Write (not add) what :func:`resonate_delta` computes (same arguments) to out[:n], each
    pass's float32 modes in explicit vectors (ugens.vector_pass.add_chunk, 32 modes at a
    time, their per-lane sums kept in four stack rows; write_sums reduces the four together
    and stores the four samples as one vector): LLVM's code reduced and stored the four
    samples one by one. Up to 2 WIDE_LANES float64 modes (rows of whole WIDE_LANES) run as
    one or two float64 vectors whose outputs join the float32 sums' lanes
    (ugens.vector_pass.add_wide_chunk; ModalBank b1024/C at 1000 modes, 8 of them: 0.96-0.99
    -> 1.00-1.08; at 5000, 12 of them: 0.95 -> 1.00), called once or twice: as a loop over
    the vectors, two of them made the bank at 5000 modes 10 % slower (though not the kernel
    alone). More run in the scalar pass :func:`_wide_pass`, a function of its own: written
    out here, its loop's mere presence made the bank of 256 modes 2-4 % slower."""
    c0, b2, g, d, y, dy = rows
    active = min(-(-active // LANES) * LANES, c0.size)
    split = min(delta_end, active)  # the delta form's chunks, then the decay-factor form's
    direct = _direct_gain(d, active, 0.0)
    if wide is not None:
        direct = _direct_gain(wide.d, wide_active, direct)
    modes = HeldRows(c0, b2, g, y, dy)
    row = stack_rows.stack_row
    s0, s1, s2, s3 = row(LANES), row(LANES), row(LANES), row(LANES)
    sums = (s0, s1, s2, s3)
    i = 0
    while i + 4 <= n:
        forces = (
            np.float32(force[i - 1] if i > 0 else last[0]),
            np.float32(force[i]),
            np.float32(force[i + 1]),
            np.float32(force[i + 2]),
        )
        for lane in range(LANES):
            s0[lane] = 0.0
            s1[lane] = 0.0
            s2[lane] = 0.0
            s3[lane] = 0.0
        t0 = 0.0
        t1 = 0.0
        t2 = 0.0
        t3 = 0.0
        if wide is not None:
            if 0 < wide_active <= 2 * WIDE_LANES:
                wide_forces = (force[i - 1] if i > 0 else last[0], force[i], force[i + 1], force[i + 2])
                vector_pass.add_wide_chunk(wide, 0, wide_forces, sums)
                if wide_active > WIDE_LANES:
                    vector_pass.add_wide_chunk(wide, WIDE_LANES, wide_forces, sums)
            elif wide_active > 0:
                t0, t1, t2, t3 = _wide_pass(wide, wide_active, force, i, last)
        for k in range(0, split, LANES):
            vector_pass.add_chunk(LANES, modes, k, forces, sums, False)
        for k in range(split, active, LANES):
            vector_pass.add_chunk(LANES, modes, k, forces, sums, True)
        vector_pass.write_sums(LANES, sums, out, i, (t0, t1, t2, t3))
        i += 4
    _tail(force[:n], out, i, modes, active, wide, wide_active, last, delta_end, False)
    _finish(force, out, 0, n, direct, last)


@nb.njit(cache=True)
def resonate_narrow(force, out, n, rows, active, wide, wide_active, last, delta_end):
    """Write the modes of :func:`resonate_delta` (same arguments) over force[:n] to out[:n]:
    all in the decay-factor form (``delta_end`` 0), 1 .. HELD_MODES float32 modes and no
    float64 modes, :func:`resonate_held` (on rows at least :func:`held_width` long, as :func:`narrow_rows`
    pads them); else, on float32 rows of whole LANES, ``delta_end`` a whole number of LANES
    and float64 rows of whole WIDE_LANES (as ugens.modal.split_by_precision makes them),
    :func:`resonate_chunks`; otherwise (or without EXPLICIT_VECTORS) out cleared and
    resonate_delta. The float64 rows, where given, are C-contiguous (as the bank's are)."""
    if EXPLICIT_VECTORS:
        held = delta_end == 0 and wide is None and 0 < active <= HELD_MODES
        if held and held_width(active) <= rows.c0.size:
            resonate_held(force, out, n, rows, active, last)
            return
        whole = rows.c0.size % LANES == 0 and delta_end % LANES == 0  # chunks of one form each
        if whole and (wide is None or wide.c1.size % WIDE_LANES == 0):
            resonate_chunks(force, out, n, rows, active, wide, wide_active, last, delta_end)
            return
    for i in range(n):
        out[i] = 0.0
    resonate_delta(force, out, n, rows, active, wide, wide_active, last, delta_end)


@nb.njit(cache=True)
def flush_silent_delta(y, dy, g, active, floor):
    """Zero float32 modes whose y[n-2] and Delta[n-1] (the scaled state times g) are below ``floor``;
    return the new active count (last audible mode + 1)."""
    last = 0
    for k in range(active):  # without branches: 86 -> 43 ns at 254 modes
        silent = (abs(g[k] * y[k]) < floor) & (abs(g[k] * dy[k]) < floor)
        y[k] = 0.0 if silent else y[k]
        dy[k] = 0.0 if silent else dy[k]
        last = max(last, 0 if silent else k + 1)
    return last
