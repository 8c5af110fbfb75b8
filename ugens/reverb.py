"""Reverb: a Jot feedback delay network with a reverberation time per octave band.

Feedback delay network (Jot & Chaigne, "Digital delay networks for designing artificial
reverberators", AES 90th Convention, 1991). N = 8 delay lines of lengths m_j (mutually
prime, spread around the mean free path ``room_size`` / c) are fed back through the
orthogonal (lossless) Hadamard matrix H / sqrt(N). Jot's rule gives line j the gain

    g_j = 10^(-3 m_j / (T60 fs)),

which multiplies every pole of the lossless network by the same radius, so that every
mode decays 60 dB in exactly T60 s, whatever the delays.

Frequency-dependent T60. The input, after ``pre_delay``, is split into seven octave
bands centred on 125 Hz ... 8 kHz by a tree of 8th-order Butterworth crossovers at the
band edges 125 sqrt(2) 2^k Hz (a Butterworth low-pass and high-pass of one cut-off are
power complementary, |LP|^2 + |HP|^2 = 1, so the bands' energies add up to the input's).
Each band drives its own set of N lines with the gains of its ``t60`` value; the sets
share delay lengths (as one network whose absorption depends on frequency, Jot's
design) and are computed side by side. Outputs: ``dry`` x + ``wet`` (sum of the lines
with weights 1/sqrt(N)), and on the extra output ``right`` the same with alternating
signs (a decorrelated second channel for stereo). JASS counterpart: ``CombReverb``;
SDT: ``reverb~``.
"""

from __future__ import annotations

import math
from typing import Any

import numba as nb
import numpy as np

from jassy.errors import PatchError
from jassy.jit import specialise
from jassy.params import ParamSpec
from jassy.registry import register
from jassy.ugen import UGen
from ugens.filters import design_biquad
from ugens.kernels import FASTMATH

#: Octave-band centres (Hz) of the ``t60`` values.
BANDS = (125.0, 250.0, 500.0, 1000.0, 2000.0, 4000.0, 8000.0)
#: Delay lines per band.
LINES = 8
#: Bands stored per line and delay slot (the kernel keeps a band's 8 lines in registers).
SLOTS = len(BANDS)
#: Order of the Butterworth crossovers and the quality factors of their biquads.
CROSSOVER_ORDER = 8
BUTTERWORTH_Q = tuple(
    1.0 / (2.0 * math.cos((2 * k + 1) * math.pi / (2 * CROSSOVER_ORDER))) for k in range(CROSSOVER_ORDER // 2)
)
#: Line lengths relative to the mean free path (spread 0.6 .. 1.5, irregular).
SPREAD = (0.61, 0.73, 0.82, 0.95, 1.04, 1.17, 1.31, 1.49)
#: Signs with which the input enters the lines (irregular, so no line pair cancels).
INPUT_SIGNS = np.array([1.0, -1.0, -1.0, 1.0, -1.0, 1.0, 1.0, -1.0])
_LOWPASS, _HIGHPASS = 0, 1


def crossover_frequencies() -> np.ndarray:
    """Band edges (Hz): geometric means of adjacent band centres."""
    centres = np.array(BANDS)
    return np.sqrt(centres[:-1] * centres[1:])


def _next_prime(k: int) -> int:
    def prime(m: int) -> bool:
        return m > 1 and all(m % d for d in range(2, int(math.isqrt(m)) + 1))

    while not prime(k):
        k += 1
    return k


def line_lengths(room_size: float, c: float, fs: float) -> np.ndarray:
    """Delay lengths (samples): distinct primes near SPREAD * room_size / c * fs."""
    lengths: list[int] = []
    for s in SPREAD:
        k = _next_prime(max(2, int(s * room_size / c * fs)))
        while k in lengths:
            k = _next_prime(k + 1)
        lengths.append(k)
    return np.array(lengths, dtype=np.int64)


@nb.njit(fastmath=FASTMATH, cache=True)
def _section(x, coef, state):
    """One DF2T biquad sample; coef [b0, b1, b2, a1, a2], state [s1, s2]."""
    y = coef[0] * x + state[0]
    state[0] = coef[1] * x - coef[3] * y + state[1]
    state[1] = coef[2] * x - coef[4] * y
    return y


@nb.njit(fastmath=FASTMATH, cache=True)
def reverb_run(x, out, right, n, pre, split, split_state, ring, ist, lengths, gains, signs, par, band_in):
    """n samples. pre: pre-delay ring; split (crossovers, 2 h, 5): h low-pass then
    h high-pass biquads per crossover; ring: the lines' samples, flat (line, slot in the
    line, band); ist = [pre-delay write, ring write]; gains: flat (band, line); signs: the
    input weights of the lines; par = [pre-delay samples, dry, wet]; band_in (bands):
    scratch. The network is written out for LINES = 8."""
    pre_len = int(par[0])
    dry = par[1]
    wet = par[2]
    pre_size = pre.size
    size = ring.size // (LINES * SLOTS)
    mask = size - 1
    n_bands = band_in.size
    n_cross = split.shape[0]
    half = split.shape[1] // 2
    norm = 1.0 / math.sqrt(LINES)
    pw = ist[0]
    w = ist[1]
    for i in range(n):
        pre[pw] = x[i]
        r = pw - pre_len
        if r < 0:
            r += pre_size
        v = pre[r]
        pw += 1
        if pw == pre_size:
            pw = 0
        # octave bands: low-pass off the bottom band, pass the rest up the tree
        for c in range(n_cross):
            low = v
            for k in range(half):
                low = _section(low, split[c, k], split_state[c, k])
                v = _section(v, split[c, half + k], split_state[c, half + k])
            band_in[c] = low
        band_in[n_cross] = v
        left_sum = 0.0
        right_sum = 0.0
        r0 = ((w - lengths[0]) & mask) * SLOTS
        r1 = (size + ((w - lengths[1]) & mask)) * SLOTS
        r2 = (2 * size + ((w - lengths[2]) & mask)) * SLOTS
        r3 = (3 * size + ((w - lengths[3]) & mask)) * SLOTS
        r4 = (4 * size + ((w - lengths[4]) & mask)) * SLOTS
        r5 = (5 * size + ((w - lengths[5]) & mask)) * SLOTS
        r6 = (6 * size + ((w - lengths[6]) & mask)) * SLOTS
        r7 = (7 * size + ((w - lengths[7]) & mask)) * SLOTS
        wb = w * SLOTS
        for b in range(n_bands):
            # the 8 lines of band b in registers: read, sum to the outputs, attenuate
            y0 = ring[r0 + b]
            y1 = ring[r1 + b]
            y2 = ring[r2 + b]
            y3 = ring[r3 + b]
            y4 = ring[r4 + b]
            y5 = ring[r5 + b]
            y6 = ring[r6 + b]
            y7 = ring[r7 + b]
            left_sum += ((y0 + y1) + (y2 + y3)) + ((y4 + y5) + (y6 + y7))
            right_sum += ((y0 - y1) + (y2 - y3)) + ((y4 - y5) + (y6 - y7))
            g = b * LINES
            y0 *= gains[g]
            y1 *= gains[g + 1]
            y2 *= gains[g + 2]
            y3 *= gains[g + 3]
            y4 *= gains[g + 4]
            y5 *= gains[g + 5]
            y6 *= gains[g + 6]
            y7 *= gains[g + 7]
            # 8-point fast Walsh-Hadamard transform
            a0, a1, a2, a3 = y0 + y1, y0 - y1, y2 + y3, y2 - y3
            a4, a5, a6, a7 = y4 + y5, y4 - y5, y6 + y7, y6 - y7
            c0, c1, c2, c3 = a0 + a2, a1 + a3, a0 - a2, a1 - a3
            c4, c5, c6, c7 = a4 + a6, a5 + a7, a4 - a6, a5 - a7
            x_b = band_in[b]
            ring[wb + b] = norm * (c0 + c4 + signs[0] * x_b)
            ring[size * SLOTS + wb + b] = norm * (c1 + c5 + signs[1] * x_b)
            ring[2 * size * SLOTS + wb + b] = norm * (c2 + c6 + signs[2] * x_b)
            ring[3 * size * SLOTS + wb + b] = norm * (c3 + c7 + signs[3] * x_b)
            ring[4 * size * SLOTS + wb + b] = norm * (c0 - c4 + signs[4] * x_b)
            ring[5 * size * SLOTS + wb + b] = norm * (c1 - c5 + signs[5] * x_b)
            ring[6 * size * SLOTS + wb + b] = norm * (c2 - c6 + signs[6] * x_b)
            ring[7 * size * SLOTS + wb + b] = norm * (c3 - c7 + signs[7] * x_b)
        w = (w + 1) & mask
        out[i] = dry * x[i] + wet * norm * left_sum
        right[i] = dry * x[i] + wet * norm * right_sum
    ist[0] = pw
    ist[1] = w


@register
class Reverb(UGen):
    """Room reverb: Jot feedback delay network (8 lines, Hadamard feedback) with a T60 per
    octave band (125 Hz - 8 kHz) and a pre-delay; extra output ``right`` for stereo.

    Model and sources in the module docstring; JASS ``CombReverb``, SDT ``reverb~``."""

    type_name = "Reverb"
    inputs = ("input",)
    outputs = ("right",)
    param_specs = {
        "t60": ParamSpec(
            "floats",
            [2.0, 1.9, 1.7, 1.5, 1.3, 1.0, 0.7],
            unit="s",
            fixed=True,
            doc="reverberation time per octave band 125, 250, 500, 1k, 2k, 4k, 8k Hz (7 values)",
        ),
        "pre_delay": ParamSpec(
            "float", 0.02, low=0.0, high=1.0, unit="s", fixed=True, doc="delay before the reverberation"
        ),
        "room_size": ParamSpec(
            "float",
            8.0,
            low=0.5,
            high=100.0,
            unit="m",
            fixed=True,
            doc="mean free path (4 V / S): the mean delay-line length is room_size / c",
        ),
        "c": ParamSpec("float", 343.0, low=100.0, high=2000.0, unit="m/s", fixed=True, doc="speed of sound"),
        "dry": ParamSpec("float", 1.0, low=0.0, high=10.0, doc="gain of the direct sound"),
        "wet": ParamSpec("float", 0.3, low=0.0, high=10.0, doc="gain of the reverberation"),
    }

    def check_param(self, key: str, value: Any, where: str) -> Any:
        value = super().check_param(key, value, where)
        if key == "t60" and (value.size != len(BANDS) or np.any(value <= 0.0) or np.any(value > 100.0)):
            raise PatchError(
                f"{where}: expected {len(BANDS)} reverberation times in (0, 100] s "
                f"(octaves {', '.join(f'{b:g}' for b in BANDS)} Hz), got {list(value)}"
            )
        return value

    def _prepare(self) -> None:
        v, fs = self.values, self.sample_rate
        self.lengths = line_lengths(v["room_size"], v["c"], fs)
        size = 1 << int(math.ceil(math.log2(int(self.lengths.max()) + 1)))
        self.ring = np.zeros(LINES * size * SLOTS)
        t60 = np.asarray(v["t60"], dtype=np.float64)
        # Jot's gains, flat (band, line)
        self.gains = (10.0 ** (-3.0 * self.lengths[None, :] / (t60[:, None] * fs))).ravel()
        pre_len = int(round(v["pre_delay"] * fs))
        self.pre = np.zeros(pre_len + 1)
        self.par = np.array([pre_len, v["dry"], v["wet"]], dtype=np.float64)
        edges = crossover_frequencies()
        half = len(BUTTERWORTH_Q)
        self.split = np.zeros((edges.size, 2 * half, 5))
        for c, f in enumerate(edges):
            f = min(f, 0.45 * fs)
            for k, q in enumerate(BUTTERWORTH_Q):
                design_biquad(_LOWPASS, f, q, 1.0 / fs, self.split[c, k])
                design_biquad(_HIGHPASS, f, q, 1.0 / fs, self.split[c, half + k])
        self.split_state = np.zeros((edges.size, 2 * half, 2))
        self.ist = np.zeros(2, dtype=np.int64)
        self.band_in = np.zeros(SLOTS)
        self._run = specialise(reverb_run, *self._arguments(0))

    def _arguments(self, n: int) -> tuple:
        return (
            self.input_buffer("input"),
            self.out,
            self.extra["right"],
            n,
            self.pre,
            self.split,
            self.split_state,
            self.ring,
            self.ist,
            self.lengths,
            self.gains,
            INPUT_SIGNS,
            self.par,
            self.band_in,
        )

    def _reset(self) -> None:
        self.ring[:] = 0.0
        self.pre[:] = 0.0
        self.split_state[:] = 0.0
        self.ist[:] = 0

    def _param_changed(self, key: str, value: Any, jump: bool) -> None:
        if key == "dry":
            self.par[1] = value
        elif key == "wet":
            self.par[2] = value

    def process(self, start: int, n: int) -> None:
        self._run(*self._arguments(n))

    def state_arrays(self) -> dict[str, np.ndarray]:
        return {
            "ring": self.ring,
            "pre": self.pre,
            "split_state": self.split_state,
            "ist": self.ist,
            "par": self.par,
        }
