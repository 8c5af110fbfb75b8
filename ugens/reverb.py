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
#: Bands padded to a power of two (the last slot stays silent), so that the per-band
#: loops of the kernel vectorise.
SLOTS = 8
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
def reverb_run(x, out, right, n, pre, split, split_state, ring, ist, lengths, gains, signs, par, band_in, y):
    """n samples. pre: pre-delay ring; split (crossovers, 2 h, 5): h low-pass then
    h high-pass biquads per crossover; ring: the lines' samples, flat (line, slot in the
    line, band); ist = [pre-delay write, ring write]; gains: flat (line, band); signs: the
    input weights of the lines; par = [pre-delay samples, dry, wet]; band_in (bands) and
    y (lines * bands): scratch."""
    pre_len = int(par[0])
    dry = par[1]
    wet = par[2]
    pre_size = pre.size
    size = ring.size // (LINES * SLOTS)
    mask = size - 1
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
        # LINES and SLOTS are compile-time constants: the loops over slots unroll and vectorise
        for j in range(LINES):
            base = (j * size + ((w - lengths[j]) & mask)) * SLOTS
            sign = 1.0 if j % 2 == 0 else -1.0
            for b in range(SLOTS):
                yj = ring[base + b]
                left_sum += yj
                right_sum += sign * yj
                y[j * SLOTS + b] = gains[j * SLOTS + b] * yj
        # fast Walsh-Hadamard transform across the lines (in place, every band at once)
        h = 1
        while h < LINES:
            for j0 in range(0, LINES, 2 * h):
                for j in range(j0, j0 + h):
                    for b in range(SLOTS):
                        a = y[j * SLOTS + b]
                        c2 = y[(j + h) * SLOTS + b]
                        y[j * SLOTS + b] = a + c2
                        y[(j + h) * SLOTS + b] = a - c2
            h *= 2
        for j in range(LINES):
            base = (j * size + w) * SLOTS
            for b in range(SLOTS):
                ring[base + b] = norm * (y[j * SLOTS + b] + signs[j] * band_in[b])
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
        gains = np.zeros((LINES, SLOTS))
        gains[:, : len(BANDS)] = 10.0 ** (-3.0 * self.lengths[:, None] / (t60[None, :] * fs))
        self.gains = gains.ravel()
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
        self.scratch = np.zeros(LINES * SLOTS)
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
            self.scratch,
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
