"""Output safety: non-finite sample removal and the final brick-wall limiter."""

from __future__ import annotations

import math

import numba as nb
import numpy as np
from llvmlite import ir as llvmir
from numba.core import types
from numba.extending import intrinsic

#: Default ceiling of the final limiter: -0.1 dBFS.
CEILING = 10 ** (-0.1 / 20)

#: float64 bit masks: every bit but the sign, and the smallest magnitude of Inf and NaN.
MAGNITUDE_BITS = 0x7FFFFFFFFFFFFFFF
NONFINITE_BITS = 0x7FF0000000000000


@intrinsic
def float_from_bits(typingctx, bits):
    """The float64 whose IEEE 754 bit pattern is the int64 ``bits``."""
    sig = types.float64(types.int64)

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], llvmir.DoubleType())

    return sig, codegen


# Inlined into its callers (numba IR; the output stage of jassy.engines.callback): no
# kernel of its own to compile on a first render. Same code, no fastmath either side.
@nb.njit(cache=True, nogil=True, inline="always")
def copy_finite(src, dst, n):
    """dst[:n] = src[:n] with NaN/Inf replaced by 0, on int64 views of float64 samples;
    returns (NaN/Inf count, magnitude bits of the largest finite |sample|). Magnitude bits
    of finite doubles order as their values, so the loop needs no float compares and runs
    in SIMD vectors (the peak is ``float_from_bits`` of the result)."""
    bad = 0
    top = 0
    for i in range(n):
        b = src[i]
        a = b & MAGNITUDE_BITS
        finite = a < NONFINITE_BITS
        bad += 0 if finite else 1
        top = max(top, a if finite else 0)
        dst[i] = b if finite else 0
    return bad, top


@nb.njit(cache=True)
def scan_chunk(audio, haptic):
    """One read pass over an output chunk: (number of NaN/Inf samples in both 2-D buffers,
    largest |finite audio sample|)."""
    bad = 0
    peak = 0.0
    for c in range(audio.shape[0]):
        for i in range(audio.shape[1]):
            x = audio[c, i]
            if not math.isfinite(x):
                bad += 1
            elif abs(x) > peak:
                peak = abs(x)
    for c in range(haptic.shape[0]):
        for i in range(haptic.shape[1]):
            if not math.isfinite(haptic[c, i]):
                bad += 1
    return bad, peak


@nb.njit(cache=True)
def peak_abs(buf):
    """Largest |sample| of a finite 2-D buffer, without a temporary array."""
    peak = 0.0
    for c in range(buf.shape[0]):
        for i in range(buf.shape[1]):
            a = abs(buf[c, i])
            if a > peak:
                peak = a
    return peak


@nb.njit(cache=True)
def zero_nonfinite(buf):
    """Replace NaN/Inf samples of a 2-D buffer by 0 in place."""
    for c in range(buf.shape[0]):
        for i in range(buf.shape[1]):
            if not math.isfinite(buf[c, i]):
                buf[c, i] = 0.0


@nb.njit(cache=True)
def limit(buf, n, state, ceiling, release_coeff):
    """Linked brick-wall limiter over buf[:, :n] in place.

    Gain drops at once to ceiling/|x| when a sample would exceed the ceiling (no lookahead,
    so no delay) and recovers towards 1 with a one-pole of coefficient ``release_coeff``.
    Non-finite samples become 0. state = [gain]. |output| <= ceiling always holds.
    While the gain is exactly 1 (fully released: 1 - 0 * release stays 1) and samples are
    finite and within the ceiling, they pass unchanged, so those are only read.
    """
    g = state[0]
    channels = buf.shape[0]
    start = 0
    if g == 1.0:
        while start < n:
            inside = True
            for c in range(channels):
                x = buf[c, start]
                if not (abs(x) <= ceiling):  # also NaN
                    inside = False
            if not inside:
                break
            start += 1
    for i in range(start, n):
        peak = 0.0
        for c in range(channels):
            x = buf[c, i]
            if not math.isfinite(x):
                buf[c, i] = 0.0
                x = 0.0
            a = abs(x)
            if a > peak:
                peak = a
        g = 1.0 - (1.0 - g) * release_coeff
        if peak * g > ceiling:
            g = ceiling / peak
        for c in range(channels):
            y = buf[c, i] * g
            # guard against rounding of x * (ceiling / x) just above the ceiling
            if y > ceiling:
                y = ceiling
            elif y < -ceiling:
                y = -ceiling
            buf[c, i] = y
    state[0] = g


@nb.njit(cache=True, inline="always")  # inlined, as copy_finite
def pinned_samples(buf, n, ceiling, run):
    """Frames of buf[:, :n] where some channel sits at the limiter's ceiling (within 1e-9):
    (count, longest run, run still open at the end), runs carried over from ``run`` frames."""
    count = 0
    longest = run
    threshold = ceiling * (1.0 - 1e-9)
    for i in range(n):
        pinned = False
        for c in range(buf.shape[0]):
            if abs(buf[c, i]) >= threshold:
                pinned = True
        if pinned:
            count += 1
            run += 1
            longest = max(longest, run)
        else:
            run = 0
    return count, longest, run


#: Slots of a limiter meter's state (float64): the largest input peak (linear, finite
#: samples before limiting), frames held at the ceiling, the longest run of them, the run
#: still open at the end, and the frames metered.
INPUT_PEAK, PINNED, LONGEST, OPEN_RUN, METERED = range(5)


@nb.njit(cache=True, inline="always")  # inlined, as copy_finite
def limit_metered(buf, n, state, ceiling, release_coeff, peak, meter):
    """:func:`limit` over buf[:, :n] given the finite input peak ``peak`` of those frames,
    metered into ``meter`` (slots INPUT_PEAK .. METERED). A fully released limiter (gain
    exactly 1) passes frames below the pinned threshold unchanged, so they are not read
    again: the output is :func:`limit`'s bit for bit, in chunks of any size."""
    meter[INPUT_PEAK] = max(meter[INPUT_PEAK], peak)
    meter[METERED] += n
    if state[0] == 1.0 and peak < ceiling * (1.0 - 1e-9):
        meter[OPEN_RUN] = 0.0
        return
    limit(buf, n, state, ceiling, release_coeff)
    count, longest, run = pinned_samples(buf, n, ceiling, int(meter[OPEN_RUN]))
    meter[PINNED] += count
    meter[LONGEST] = max(meter[LONGEST], longest)
    meter[OPEN_RUN] = run


class LimiterMeter:
    """What the final limiter did over a render: frames held at the ceiling, the longest run
    of them (frames) and the largest input peak (linear, before limiting), kept in
    ``state`` (slots INPUT_PEAK .. METERED) where compiled renders update it too."""

    def __init__(self, ceiling: float = CEILING):
        self.ceiling = ceiling
        self.state = np.zeros(METERED + 1)

    @property
    def pinned(self) -> int:
        return int(self.state[PINNED])

    @property
    def longest(self) -> int:
        return int(self.state[LONGEST])

    @property
    def input_peak(self) -> float:
        return float(self.state[INPUT_PEAK])

    @property
    def frames(self) -> int:
        return int(self.state[METERED])

    def before(self, buf: np.ndarray) -> None:
        """Record the peak of a chunk about to be limited (finite samples)."""
        if buf.size:
            self.state[INPUT_PEAK] = max(self.state[INPUT_PEAK], peak_abs(buf))

    def after(self, buf: np.ndarray, n: int) -> None:
        """Count the frames of a limited chunk held at the ceiling."""
        count, longest, run = pinned_samples(buf, n, self.ceiling, int(self.state[OPEN_RUN]))
        self.state[LONGEST] = max(self.state[LONGEST], longest)
        self.state[PINNED] += count
        self.state[OPEN_RUN] = run
        self.state[METERED] += n

    def limit(self, buf: np.ndarray, n: int, state: np.ndarray, release_coeff: float, peak: float) -> None:
        """Limit buf[:, :n] in place and meter it, given its finite input peak (see
        :func:`limit_metered`)."""
        limit_metered(buf, n, state, self.ceiling, release_coeff, peak, self.state)

    @property
    def reduction_db(self) -> float:
        """Peak gain reduction in dB (0 when the input never exceeded the ceiling)."""
        return max(0.0, 20 * math.log10(self.input_peak / self.ceiling)) if self.input_peak > 0 else 0.0

    def report(self, sample_rate: float) -> dict:
        return {
            "pinned_frames": self.pinned,
            "longest_pinned_s": self.longest / sample_rate,
            "peak_reduction_db": self.reduction_db,
        }

    def warning(self, sample_rate: float) -> str | None:
        """A warning when the limiter cut peaks, else None."""
        if self.reduction_db <= 0.0:
            return None
        share = 100.0 * self.pinned / max(self.frames, 1)
        longest_ms = 1e3 * self.longest / sample_rate
        return (
            f"limiter: peaks reduced by {self.reduction_db:.1f} dB; {self.pinned} frames ({share:.2f} %) "
            f"held at the ceiling, the longest run {longest_ms:.1f} ms; lower a gain or use --normalise"
        )


def release_coefficient(release: float, sample_rate: float) -> float:
    """One-pole coefficient for a release time constant ``release`` (s)."""
    return float(np.exp(-1.0 / (release * sample_rate))) if release > 0 else 0.0
