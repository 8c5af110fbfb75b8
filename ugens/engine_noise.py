"""The Engine's intake and mechanical noise, derived from its firing pulse train.

Intake. Every intake stroke draws a suction pulse through the intake valve; with the
cylinders' strokes in sequence, the intake sees a train of suction pulses at the firing
rate, which the airbox (a Helmholtz resonator: its volume and snorkel) filters. Here the
suction train is the port pulse train p (the Engine's ``pulses`` output, on the same
scale) inverted, through an RBJ band-pass (0 dB peak) at ``airbox_freq`` with quality
``airbox_q`` (the intake's own pulses and phases are not modelled: the pulses are taken
in step with the firings). Added to it, the hiss of the turbulent flow through the
throttle body: white noise ~ throttle (rpm / 3000)^(3/2) (flow speed ~ rpm, dipole
level ~ v^3 as for wind, here at the square root of the power), band-passed at
``hiss_freq`` (Q 1). Sum times ``intake_level``: extra output ``intake``.

Mechanical. Combustion impacts, piston slap and valve-train clatter excite the engine
block at every firing; their forces grow with the inertial loads ~ rpm^2. Modelled as
white noise modulated by the pulse train (bursts at each firing, shaped like the
pulse), times (rpm / 3000)^2, through a 2nd-order high-pass at ``block_freq`` (the
block radiates efficiently only above its first panel modes); times
``mechanical_level``: extra output ``mechanical``.

Both are added to the exhaust sound. With both levels 0 (the defaults) the Engine's
output is the exhaust alone, as before. References: Heywood, *Internal Combustion Engine
Fundamentals*, 1988, ch. 7 (intake flow) and Baldan et al., SIVE 2015 (SDT ``motor~``:
intake, exhaust and engine-block vibration as separate sources).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba as nb
import numpy as np

from jassy.jit import drop_stale_cache
from jassy.params import ParamSpec
from ugens import filters, noise
from ugens.filters import biquad_coefficients, biquad_step, design_biquad
from ugens.kernels import FASTMATH
from ugens.noise import uniform

drop_stale_cache(__file__, [filters, noise])  # its cache holds copies of their kernels

#: Reference speed (1/min) of the noise levels.
REFERENCE_RPM = 3000.0
_LOWPASS, _HIGHPASS, _BANDPASS = 0, 1, 2

NOISE_SPECS = {
    "intake_level": ParamSpec("float", 0.0, low=0.0, high=100.0, doc="intake sound (0: none)"),
    "airbox_freq": ParamSpec(
        "float", 180.0, low=10.0, high=5000.0, unit="Hz", fixed=True, doc="airbox (Helmholtz) resonance"
    ),
    "airbox_q": ParamSpec("float", 3.0, low=0.3, high=100.0, fixed=True, doc="airbox resonance quality"),
    "hiss_freq": ParamSpec(
        "float", 1500.0, low=50.0, high=20000.0, unit="Hz", fixed=True, doc="centre of the intake flow hiss"
    ),
    "hiss": ParamSpec("float", 0.3, low=0.0, high=100.0, doc="hiss level relative to the intake pulses"),
    "mechanical_level": ParamSpec("float", 0.0, low=0.0, high=100.0, doc="engine-block noise (0: none)"),
    "block_freq": ParamSpec(
        "float", 1200.0, low=50.0, high=20000.0, unit="Hz", fixed=True, doc="engine-block radiation high-pass"
    ),
}

# coefficient rows: airbox band-pass, hiss band-pass, block high-pass; state rows alike
_AIRBOX, _HISS, _BLOCK = range(3)


class NoiseLevels(NamedTuple):
    """Levels of the noise sources, stored in this order in the float64 array ``levels``."""

    intake: float  #: intake sound (``intake_level``)
    hiss: float  #: throttle hiss relative to the intake pulses, scaled to the sample rate
    mechanical: float  #: engine-block noise (``mechanical_level``), scaled to the sample rate


@nb.njit(inline="always", cache=True)
def noise_levels(levels):
    """The NoiseLevels record held in ``levels``."""
    return NoiseLevels(levels[0], levels[1], levels[2])


class EngineNoise(NamedTuple):
    """The noise's arrays: levels (a NoiseLevels), filters and their state, random stream."""

    levels: np.ndarray  #: a NoiseLevels
    coef: np.ndarray  #: (3, 5) biquads [b0, b1, b2, a1, a2]: airbox, hiss, block
    state: np.ndarray  #: (3, 2) the biquads' states
    rng: np.ndarray  #: splitmix64 state, one uint64


def design(values: dict, fs: float) -> np.ndarray:
    """The three biquads (rows [b0, b1, b2, a1, a2]) for the parameter values."""
    coef = np.zeros((3, 5))
    nyquist = 0.45 * fs
    design_biquad(_BANDPASS, min(values["airbox_freq"], nyquist), values["airbox_q"], 1.0 / fs, coef[_AIRBOX])
    design_biquad(_BANDPASS, min(values["hiss_freq"], nyquist), 1.0, 1.0 / fs, coef[_HISS])
    design_biquad(_HIGHPASS, min(values["block_freq"], nyquist), 1.0 / math.sqrt(2.0), 1.0 / fs, coef[_BLOCK])
    return coef


@nb.njit(fastmath=FASTMATH, cache=True)
def _biquad(x, c, s):
    """One sample of the filter row ``c`` ([b0, b1, b2, a1, a2]) with its state row ``s``
    (ugens.filters.biquad_step), the state updated in place."""
    y, s1, s2 = biquad_step(biquad_coefficients(c), x, s[0], s[1])
    s[0] = s1
    s[1] = s2
    return y


@nb.njit(fastmath=FASTMATH, cache=True)
def engine_noise(pulses, out, intake_out, mech_out, n, rpms, throttles, noise):
    """Add intake and mechanical noise (noise: the EngineNoise) for n samples to out; write
    the extra outputs."""
    levels = noise_levels(noise.levels)
    coef, state, rng = noise.coef, noise.state, noise.rng
    s = rng[0]
    for i in range(n):
        speed = rpms[i] / REFERENCE_RPM
        p = pulses[i]
        s, u = uniform(s)
        hiss = levels.hiss * throttles[i] * speed * math.sqrt(speed) * u
        intake = levels.intake * (
            _biquad(-p, coef[_AIRBOX], state[_AIRBOX]) + _biquad(hiss, coef[_HISS], state[_HISS])
        )
        s, u = uniform(s)
        mech = levels.mechanical * _biquad(speed * speed * abs(p) * u, coef[_BLOCK], state[_BLOCK])
        intake_out[i] = intake
        mech_out[i] = mech
        out[i] += intake + mech
    rng[0] = s
