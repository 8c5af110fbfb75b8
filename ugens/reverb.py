"""Reverb: a Jot feedback delay network with a reverberation time per octave band.

Feedback delay network (Jot & Chaigne, "Digital delay networks for designing artificial
reverberators", AES 90th Convention, 1991). N = 8 delay lines of lengths m_j (mutually
prime, spread around the mean free path ``room_size`` / c) are fed back through the
orthogonal (lossless) Hadamard matrix H / sqrt(N). Jot's rule: a line whose delay is m_j
samples attenuates by

    A_j(f) = -60 m_j / (T60(f) fs)  dB,

which multiplies every pole of the lossless network near f by the same radius, so every
mode at f decays 60 dB in T60(f) s, whatever the delays.

Frequency-dependent T60 (Jot's absorption filters). Each line carries a cascade of
second-order sections (RBJ cookbook: a low shelf at the 125/250 Hz band edge, peaking
filters at 250 Hz ... 4 kHz, one octave wide, a high shelf at the 4k/8k edge, and a flat
gain) whose dB response is fitted by least squares to A_j(f) at three frequencies per
octave band, the sections' responses superposing in dB (the graphic equaliser design of
Valimaki & Liski, "Accurate reverberation time control in feedback delay networks",
DAFx 2017, one fit repeated with the fitted gains). Outputs: ``dry`` x + ``wet`` (sum
of the lines with weights 1/sqrt(N)), and on the extra output ``right`` the same with
alternating signs (a decorrelated second channel for stereo). JASS counterpart:
``CombReverb``; SDT: ``reverb~``.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numba as nb
import numpy as np

from jassy.errors import PatchError
from jassy.jit import drop_stale_cache, specialise
from jassy.params import ParamSpec
from jassy.registry import register
from jassy.ugen import UGen
from ugens import filters
from ugens.cells import slot
from ugens.filters import BiquadCoefficients, biquad_step
from ugens.kernels import FASTMATH

drop_stale_cache(__file__, [filters])  # its cache holds copies of their kernels

#: Octave-band centres (Hz) of the ``t60`` values.
BANDS = (125.0, 250.0, 500.0, 1000.0, 2000.0, 4000.0, 8000.0)
#: Delay lines.
LINES = 8
#: Absorption filter sections per line: low shelf, five peaks, high shelf.
SECTIONS = len(BANDS)
#: Quality factor of the peaking sections (one octave between the -3 dB points of the
#: gain in dB) and of the shelves (slope S = 1).
PEAK_Q = math.sqrt(2.0)
SHELF_Q = 1.0 / math.sqrt(2.0)
#: Line lengths relative to the mean free path (spread 0.6 .. 1.5, irregular).
SPREAD = (0.61, 0.73, 0.82, 0.95, 1.04, 1.17, 1.31, 1.49)
#: Signs with which the input enters the lines (irregular, so no line pair cancels).
INPUT_SIGNS = np.array([1.0, -1.0, -1.0, 1.0, -1.0, 1.0, 1.0, -1.0])
_LOW_SHELF, _PEAK, _HIGH_SHELF = 0, 1, 2
#: Coefficient slots of one section (axis 1 of Network.sections, the last axis of
#: :func:`rbj_section`): y = (b0 + b1 z^-1 + b2 z^-2) / (1 + a1 z^-1 + a2 z^-2) x.
B0, B1, B2, A1, A2 = 0, 1, 2, 3, 4
#: State slots of one section (axis 1 of ReverbData.filter_state): the two delays of
#: direct form II transposed.
S1, S2 = 0, 1


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


def rbj_section(kind: int, freq: float, gain_db: float, fs: float) -> np.ndarray:
    """RBJ audio-EQ cookbook low shelf, peaking or high shelf: [b0, b1, b2, a1, a2]."""
    a = 10.0 ** (gain_db / 40.0)
    w0 = 2.0 * math.pi * freq / fs
    cw, sw = math.cos(w0), math.sin(w0)
    if kind == _PEAK:
        alpha = sw / (2.0 * PEAK_Q)
        b = [1.0 + alpha * a, -2.0 * cw, 1.0 - alpha * a]
        den = [1.0 + alpha / a, -2.0 * cw, 1.0 - alpha / a]
    else:
        alpha = sw / (2.0 * SHELF_Q)
        k = 2.0 * math.sqrt(a) * alpha
        s = 1.0 if kind == _LOW_SHELF else -1.0
        b = [
            a * ((a + 1) - s * (a - 1) * cw + k),
            s * 2 * a * ((a - 1) - s * (a + 1) * cw),
            a * ((a + 1) - s * (a - 1) * cw - k),
        ]
        den = [
            (a + 1) + s * (a - 1) * cw + k,
            -s * 2 * ((a - 1) + s * (a + 1) * cw),
            (a + 1) + s * (a - 1) * cw - k,
        ]
    coef = np.empty(5)
    coef[[B0, B1, B2]] = b
    coef[[A1, A2]] = den[1:]
    return coef / den[0]


def _response_db(coef: np.ndarray, freqs: np.ndarray, fs: float) -> np.ndarray:
    z = np.exp(-2j * np.pi * freqs / fs)
    h = (coef[B0] + coef[B1] * z + coef[B2] * z * z) / (1.0 + coef[A1] * z + coef[A2] * z * z)
    return 20.0 * np.log10(np.abs(h))


def _section_layout(fs: float) -> list[tuple[int, float]]:
    """(kind, frequency) of the sections, frequencies kept below 0.45 fs."""
    edges = crossover_frequencies()
    layout = [(_LOW_SHELF, edges[0])] + [(_PEAK, f) for f in BANDS[1:-1]] + [(_HIGH_SHELF, edges[-1])]
    return [(kind, min(f, 0.45 * fs)) for kind, f in layout]


def absorption_filter(attenuation_db: np.ndarray, fs: float) -> np.ndarray:
    """Sections (SECTIONS, 5) whose cascade attenuates by ``attenuation_db`` (one value
    per octave band, dB, negative) at three points per band; the flat gain is folded into
    the first section's numerator."""
    grid = np.array([c * 2.0**k for c in BANDS for k in (-1 / 3, 0.0, 1 / 3)])
    keep = grid < 0.45 * fs
    grid, target = grid[keep], np.repeat(attenuation_db, 3)[keep]
    layout = _section_layout(fs)
    gains = np.full(len(layout), float(np.mean(attenuation_db)) or -1.0)
    for _ in range(2):  # design at the fitted gains, refit
        per_db = [
            _response_db(rbj_section(kind, f, g if abs(g) > 1e-6 else -1e-3, fs), grid, fs)
            / (g if abs(g) > 1e-6 else -1e-3)
            for (kind, f), g in zip(layout, gains, strict=True)
        ]
        basis = np.column_stack([np.ones_like(grid), *per_db])
        solution = np.linalg.lstsq(basis, target, rcond=None)[0]
        flat, gains = solution[0], solution[1:]
    sections = np.array([rbj_section(kind, f, g, fs) for (kind, f), g in zip(layout, gains, strict=True)])
    sections[0, [B0, B1, B2]] *= 10.0 ** (flat / 20.0)
    return sections


@nb.njit(inline="always", cache=True)
def _section(sections, k, j):
    """Section k of line j's absorption cascade as a BiquadCoefficients record."""
    return BiquadCoefficients(
        sections[k, B0, j], sections[k, B1, j], sections[k, B2, j], sections[k, A1, j], sections[k, A2, j]
    )


@nb.njit(fastmath=FASTMATH, cache=True)
def _absorb(y, m, sections, filter_state, j):
    """y[:m] through line j's SECTIONS = 7 biquads (direct form II transposed,
    :func:`ugens.filters.biquad_step`), sample by sample through the whole cascade with every
    section's coefficients and state in scalars, so the sections' recurrences overlap."""
    c0, c1, c2, c3 = (
        _section(sections, 0, j),
        _section(sections, 1, j),
        _section(sections, 2, j),
        _section(sections, 3, j),
    )
    c4, c5, c6 = _section(sections, 4, j), _section(sections, 5, j), _section(sections, 6, j)
    s10, s20 = filter_state[0, S1, j], filter_state[0, S2, j]
    s11, s21 = filter_state[1, S1, j], filter_state[1, S2, j]
    s12, s22 = filter_state[2, S1, j], filter_state[2, S2, j]
    s13, s23 = filter_state[3, S1, j], filter_state[3, S2, j]
    s14, s24 = filter_state[4, S1, j], filter_state[4, S2, j]
    s15, s25 = filter_state[5, S1, j], filter_state[5, S2, j]
    s16, s26 = filter_state[6, S1, j], filter_state[6, S2, j]
    for t in range(m):
        u, s10, s20 = biquad_step(c0, y[t], s10, s20)
        u, s11, s21 = biquad_step(c1, u, s11, s21)
        u, s12, s22 = biquad_step(c2, u, s12, s22)
        u, s13, s23 = biquad_step(c3, u, s13, s23)
        u, s14, s24 = biquad_step(c4, u, s14, s24)
        u, s15, s25 = biquad_step(c5, u, s15, s25)
        y[t], s16, s26 = biquad_step(c6, u, s16, s26)
    filter_state[0, S1, j], filter_state[0, S2, j] = s10, s20
    filter_state[1, S1, j], filter_state[1, S2, j] = s11, s21
    filter_state[2, S1, j], filter_state[2, S2, j] = s12, s22
    filter_state[3, S1, j], filter_state[3, S2, j] = s13, s23
    filter_state[4, S1, j], filter_state[4, S2, j] = s14, s24
    filter_state[5, S1, j], filter_state[5, S2, j] = s15, s25
    filter_state[6, S1, j], filter_state[6, S2, j] = s16, s26


class Network(NamedTuple):
    """The delay network's static arrays."""

    lengths: np.ndarray  #: int64 (LINES,) line lengths (samples)
    sections: np.ndarray  #: (SECTIONS, 5, LINES) each line's absorption filter [b0, b1, b2, a1, a2]
    signs: np.ndarray  #: (LINES,) the input weights of the lines


class ReverbParams(NamedTuple):
    """Settings of :func:`reverb_run`, stored in this order in the float64 array ``par``."""

    pre_delay: float  #: pre-delay (samples, a whole number)
    dry: float  #: gain of the direct sound
    wet: float  #: gain of the reverberation


@nb.njit(inline="always", cache=True)
def reverb_params(par):
    """The ReverbParams record held in ``par``."""
    return ReverbParams(par[0], par[1], par[2])


class ReverbData(NamedTuple):
    """The arrays :func:`reverb_run` updates."""

    pre: np.ndarray  #: pre-delay ring
    ring: np.ndarray  #: (LINES, size) the lines, size a power of two
    ist: np.ndarray  #: int64 [pre-delay write index, ring write index]
    filter_state: np.ndarray  #: (SECTIONS, 2, LINES) absorption filter states
    chunk: np.ndarray  #: (LINES + 2, C) scratch, C <= the shortest line
    wet_in: np.ndarray  #: (C,) scratch


@nb.njit(fastmath=FASTMATH, cache=True)
def reverb_run(x, out, right, n, net, par, d):
    """n samples of input x to the outputs out (left) and right. net: the Network; par holds
    the ReverbParams; d: the ReverbData.

    The network runs in chunks of at most C samples: everything a line delivers within a
    chunk was written before it, so each line's chunk is read and filtered at once (the
    filter state in registers), then the feedback matrix writes the chunk back."""
    lengths, sections, signs = net
    pre, ring, ist, filter_state, chunk, wet_in = d
    prm = reverb_params(par)
    pre_len = int(prm.pre_delay)
    dry = prm.dry
    wet = prm.wet
    pre_size = pre.size
    mask = ring.shape[1] - 1
    norm = 1.0 / math.sqrt(LINES)
    pw = ist[0]
    w = ist[1]
    i = 0
    while i < n:
        m = min(n - i, wet_in.size)
        for t in range(m):
            pre[pw] = x[i + t]
            r = pw - pre_len
            if r < 0:
                r += pre_size
            wet_in[t] = norm * pre[r]
            pw += 1
            if pw == pre_size:
                pw = 0
        left = chunk[LINES]
        rite = chunk[LINES + 1]
        for t in range(m):
            left[t] = 0.0
            rite[t] = 0.0
        for j in range(LINES):
            y = chunk[j]
            start = w - lengths[j]
            sign = 1.0 if j % 2 == 0 else -1.0
            for t in range(m):
                v = ring[j, (start + t) & mask]
                left[t] += v
                rite[t] += sign * v
                y[t] = v
            _absorb(y, m, sections, filter_state, j)
        for t in range(m):
            # 8-point fast Walsh-Hadamard transform
            a0, a1_, a2_, a3 = (
                chunk[0, t] + chunk[1, t],
                chunk[0, t] - chunk[1, t],
                chunk[2, t] + chunk[3, t],
                chunk[2, t] - chunk[3, t],
            )
            a4, a5, a6, a7 = (
                chunk[4, t] + chunk[5, t],
                chunk[4, t] - chunk[5, t],
                chunk[6, t] + chunk[7, t],
                chunk[6, t] - chunk[7, t],
            )
            c0, c1, c2, c3 = a0 + a2_, a1_ + a3, a0 - a2_, a1_ - a3
            c4, c5, c6, c7 = a4 + a6, a5 + a7, a4 - a6, a5 - a7
            v = wet_in[t]
            wt = (w + t) & mask
            ring[0, wt] = norm * (c0 + c4) + signs[0] * v
            ring[1, wt] = norm * (c1 + c5) + signs[1] * v
            ring[2, wt] = norm * (c2 + c6) + signs[2] * v
            ring[3, wt] = norm * (c3 + c7) + signs[3] * v
            ring[4, wt] = norm * (c0 - c4) + signs[4] * v
            ring[5, wt] = norm * (c1 - c5) + signs[5] * v
            ring[6, wt] = norm * (c2 - c6) + signs[6] * v
            ring[7, wt] = norm * (c3 - c7) + signs[7] * v
            out[i + t] = dry * x[i + t] + wet * norm * left[t]
            right[i + t] = dry * x[i + t] + wet * norm * rite[t]
        w = (w + m) & mask
        i += m
    ist[0] = pw
    ist[1] = w


@register
class Reverb(UGen):
    """Room reverb: Jot feedback delay network (8 lines, Hadamard feedback, an absorption
    filter per line) with a T60 per octave band (125 Hz - 8 kHz) and a pre-delay; extra
    output ``right`` for stereo.

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
        self.ring = np.zeros((LINES, size))
        t60 = np.asarray(v["t60"], dtype=np.float64)
        # Jot's attenuation per line and band (dB), realised by each line's filter
        filters = [absorption_filter(-60.0 * m / (t60 * fs), fs) for m in self.lengths]
        self.sections = np.ascontiguousarray(np.stack(filters, axis=-1))
        self.filter_state = np.zeros((SECTIONS, 2, LINES))
        pre_len = int(round(v["pre_delay"] * fs))
        self.pre = np.zeros(pre_len + 1)
        self.par = np.array(ReverbParams(pre_len, v["dry"], v["wet"]), dtype=np.float64)
        self.ist = np.zeros(2, dtype=np.int64)
        chunk = int(self.lengths.min())
        self.chunk = np.zeros((LINES + 2, chunk))
        self.wet_in = np.zeros(chunk)
        self._net = Network(self.lengths, self.sections, INPUT_SIGNS)
        self._data = ReverbData(self.pre, self.ring, self.ist, self.filter_state, self.chunk, self.wet_in)
        self._run = specialise(reverb_run, *self._arguments(0))

    def _arguments(self, n: int) -> tuple:
        return (self.input_buffer("input"), self.out, self.extra["right"], n, self._net, self.par, self._data)

    def _reset(self) -> None:
        self.ring[:] = 0.0
        self.pre[:] = 0.0
        self.filter_state[:] = 0.0
        self.ist[:] = 0

    def _param_changed(self, key: str, value: Any, jump: bool) -> None:
        if key in ("dry", "wet"):
            self.par[slot(ReverbParams, key)] = value

    def process(self, start: int, n: int) -> None:
        self._run(*self._arguments(n))

    def state_arrays(self) -> dict[str, np.ndarray]:
        return {
            "ring": self.ring,
            "pre": self.pre,
            "filter_state": self.filter_state,
            "ist": self.ist,
            "par": self.par,
        }
