"""Seeded noise sources: WhiteNoise and FractalNoise (1/f^beta).

Random numbers come from splitmix64 (Steele, Lea & Flood 2014): the state is a uint64
counter advanced by 0x9E3779B97F4A7C15 per draw and the output is a bijective mix of it.
The state starts at ``seed`` and is carried across calls, so the stream is reproducible
and independent of block size. A draw u is mapped to [-1, 1) as (u >> 11) * 2^-52 - 1.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from jassy.params import ParamSpec
from jassy.registry import register
from jassy.ugen import UGen
from ugens.kernels import FASTMATH

_GAMMA = np.uint64(0x9E3779B97F4A7C15)
_MIX1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX2 = np.uint64(0x94D049BB133111EB)

#: Lowest pole of the 1/f^beta filter cascade (Hz): below it the spectrum is flat.
F_LOW = 5.0
#: Pole-zero sections per octave of the cascade (ripple about the slope < 0.2 dB).
PER_OCTAVE = 2


def seed_spec(doc: str = "random seed") -> ParamSpec:
    """The ``seed`` parameter of a ugen drawing from the splitmix64 stream (:func:`uniform`)."""
    return ParamSpec("int", 0, low=0, high=2**64 - 1, fixed=True, doc=doc)


@nb.njit(cache=True)
def uniform(s):
    """Advance splitmix64 state s; return (new state, a uniform draw in [-1, 1))."""
    s += _GAMMA
    z = (s ^ (s >> np.uint64(30))) * _MIX1
    z = (z ^ (z >> np.uint64(27))) * _MIX2
    z ^= z >> np.uint64(31)
    return s, float(z >> np.uint64(11)) * 2.0**-52 - 1.0


@nb.njit(fastmath=FASTMATH, cache=True)
def white(out, n, rng, amps):
    s = rng[0]
    for i in range(n):
        s, u = uniform(s)
        out[i] = amps[i] * u
    rng[0] = s


@nb.njit(fastmath=FASTMATH, cache=True)
def cascade(v, poles, zeros, xm, ym):
    """One sample through first-order sections y = x - z x[-1] + p y[-1] in series."""
    for k in range(poles.size):
        y = v - zeros[k] * xm[k] + poles[k] * ym[k]
        xm[k] = v
        ym[k] = y
        v = y
    return v


@nb.njit(fastmath=FASTMATH, cache=True)
def fractal(out, n, rng, amps, gain, poles, zeros, xm, ym):
    s = rng[0]
    for i in range(n):
        s, u = uniform(s)
        out[i] = amps[i] * gain * cascade(u, poles, zeros, xm, ym)
    rng[0] = s


@nb.njit(fastmath=FASTMATH, cache=True)
def impulse_energy(poles, zeros, length):
    """Sum of squares of the cascade's first ``length`` impulse-response samples."""
    xm = np.zeros(poles.size)
    ym = np.zeros(poles.size)
    e = 0.0
    v = 1.0
    for _ in range(length):
        h = cascade(v, poles, zeros, xm, ym)
        e += h * h
        v = 0.0
    return e


class _Noise(UGen):
    """Shared parameters and state of the seeded sources."""

    def _prepare(self) -> None:
        self.amp = self.smoothed("amp")
        self.rng = np.zeros(1, dtype=np.uint64)
        self._amps = np.zeros(self.max_block)

    def _reset(self) -> None:
        self.amp.set(self.amp.target, 0, jump=True)
        self.rng[0] = self.values["seed"]

    def _param_changed(self, key, value, jump) -> None:
        self.amp.set(value, self.ramp_samples(), jump)

    def state_arrays(self):
        return {"rng": self.rng, "amp": self.amp.ramp}


@register
class WhiteNoise(_Noise):
    """Uniform white noise in [-amp, amp): variance amp^2 / 3, flat spectrum."""

    type_name = "WhiteNoise"
    param_specs = {
        "amp": ParamSpec("float", 1.0, smooth=True, doc="peak amplitude"),
        "seed": seed_spec(),
    }

    def process(self, start: int, n: int) -> None:
        white(self.out, n, self.rng, self.amp.fill(self._amps, n))


@register
class FractalNoise(_Noise):
    """1/f^beta noise: uniform white noise through a cascade of first-order pole-zero sections.

    Poles sit at F_LOW * r^k Hz (r = 2^(1/PER_OCTAVE), up to Nyquist) and each zero at
    r^(beta/2) times its pole (matched z: p = exp(-2 pi f / fs)), so each section adds a
    step of -10 beta log10(r) dB and the power spectrum follows f^-beta between F_LOW and
    Nyquist (flat below F_LOW). beta = 0 makes every zero cancel its pole: white noise.
    The output is scaled so that the stationary RMS is ``amp`` (gain from the cascade's
    impulse-response energy); the filter starts at rest, so components near F_LOW build up
    over the first ~0.1 s.
    """

    type_name = "FractalNoise"
    param_specs = {
        "beta": ParamSpec("float", 1.0, low=0.0, high=2.0, fixed=True, doc="spectral exponent"),
        "amp": ParamSpec("float", 1.0, smooth=True, doc="RMS amplitude"),
        "seed": seed_spec(),
    }

    def _prepare(self) -> None:
        super()._prepare()
        fs = self.sample_rate
        r = 2.0 ** (1.0 / PER_OCTAVE)
        fp = F_LOW * r ** np.arange(math.ceil(PER_OCTAVE * math.log2(fs / 2 / F_LOW)))
        self.poles = np.exp(-2.0 * math.pi * fp / fs)
        self.zeros = np.exp(-2.0 * math.pi * fp * r ** (self.values["beta"] / 2) / fs)
        # the slowest section decays as exp(-2 pi F_LOW t): its energy is < 4e-6 after fs / F_LOW
        energy = impulse_energy(self.poles, self.zeros, int(fs / F_LOW)) / 3.0  # uniform variance 1/3
        self.gain = 1.0 / math.sqrt(energy)
        self.xm = np.zeros(fp.size)
        self.ym = np.zeros(fp.size)

    def _reset(self) -> None:
        super()._reset()
        self.xm[:] = 0.0
        self.ym[:] = 0.0

    def process(self, start: int, n: int) -> None:
        amps = self.amp.fill(self._amps, n)
        fractal(self.out, n, self.rng, amps, self.gain, self.poles, self.zeros, self.xm, self.ym)

    def state_arrays(self):
        return {**super().state_arrays(), "xm": self.xm, "ym": self.ym}
