"""Explosion: a Friedlander blast wave and its scattered rumble, heard at a distance.

Blast wave. The overpressure at a fixed point after the shock front arrives (t = 0) is
the Friedlander waveform (Friedlander 1946; Kinney & Graham, *Explosive Shocks in Air*,
1985, ch. 7)

    p(t) = P (1 - t / t+) e^{-b t / t+},   t >= 0,

a jump to the peak P, a positive phase that crosses zero at t = t+ (``blast_time``), then
the negative (suction) phase returning to ambient. Its positive impulse is

    I+ = int_0^t+ p dt = P t+ (b - 1 + e^{-b}) / b^2      (= P t+ / e for b = 1).

The sum of all blasts is an exact two-state recursion, as for the Engine's pulses: with
r = e^{-b / (t+ fs)}, S1 = sum_k A_k r^(n - t_k), S2 = sum_k A_k (n - t_k) r^(n - t_k),
p = S1 - S2 / (t+ fs); each blast starts at its fractional sample time, so blasts overlap
at no extra cost.

Distance. The listener is ``distance`` r m away: the wave arrives r / c later and its
amplitude falls as 1 / r (``overpressure`` is the peak at 1 m; acoustic far field). Air
and ground absorb the high frequencies: the result goes through a two-pole (Butterworth)
low-pass at min(20 kHz / sqrt(r), 0.45 fs), as in SDT ``explosion~``.

Scattering. Reflections off ground, buildings and terrain spread the blast's energy into
a diffuse tail (the rumble). Its energy envelope E is the blast's p^2 through a one-pole
leaky integrator whose energy decays 60 dB in ``scatter_time`` s (sum of the integrator's
impulse response = 1, so the tail carries the blast's energy); the tail is unit-variance
noise times sqrt(E), low-passed at ``rumble`` Hz with its noise gain normalised (a fixed
variance in a band fixed in Hz: the same spectral density at any sample rate). The
output is (1 - dispersion) blast + dispersion tail (SDT's mix of direct and scattered
wave). Output: pressure in Pa. SDT ``explosion~`` (Baldan et al., 2017).
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numba as nb
import numpy as np

from jassy.jit import drop_stale_cache, specialise
from jassy.params import ParamSpec
from jassy.registry import register
from jassy.ugen import UGen
from ugens import cells, filters, noise
from ugens.cells import (
    ONSET_AMPLITUDE,
    ONSET_AT,
    ONSET_COLUMNS,
    Onset,
    add_onset,
    decay_sums,
    drop_row,
    slot,
    store,
    with_room,
)
from ugens.filters import biquad_coefficients, biquad_step, design_biquad
from ugens.kernels import FASTMATH
from ugens.noise import seed_spec, uniform

drop_stale_cache(__file__, [cells, filters, noise])  # its cache holds copies of their kernels

#: Capacity of the queue of blasts travelling to the listener.
QUEUE = 32
#: Air-absorption low-pass cut-off at 1 m (Hz), falling as 1 / sqrt(distance).
ABSORPTION_CUTOFF = 20000.0
_LOWPASS = 0


class ExplosionParams(NamedTuple):
    """Settings of :func:`explosion_run`, stored in this order in the float64 array ``par``."""

    r: float  #: per-sample decay of the blast pulse, e^{-b / (t+ fs)}
    inv_tp: float  #: 1 / (t+ fs), inverse positive phase in samples
    scatter: float  #: per-sample factor of the tail's energy integrator
    dispersion: float  #: share of the scattered tail in the output
    tail_gain: float  #: scale of the uniform draws to unit variance after the rumble low-pass


@nb.njit(inline="always", cache=True)
def explosion_params(par):
    """The ExplosionParams record held in ``par``."""
    return ExplosionParams(par[0], par[1], par[2], par[3], par[4])


class ExplosionState(NamedTuple):
    """State of :func:`explosion_run`, stored in this order in the float64 array ``st``."""

    s1: float  #: sum of the blasts' A r^x
    s2: float  #: sum of the blasts' x A r^x
    energy: float  #: the tail's energy envelope (Pa^2)
    a1: float  #: air-absorption low-pass, first DF2T state
    a2: float  #: air-absorption low-pass, second DF2T state
    t1: float  #: rumble low-pass, first DF2T state
    t2: float  #: rumble low-pass, second DF2T state


@nb.njit(inline="always", cache=True)
def explosion_state(st):
    """The ExplosionState record held in ``st``."""
    return ExplosionState(st[0], st[1], st[2], st[3], st[4], st[5], st[6])


_DISPERSION = slot(ExplosionParams, "dispersion")


def friedlander(t: np.ndarray, peak: float, blast_time: float, decay: float = 1.0) -> np.ndarray:
    """The Friedlander waveform P (1 - t / t+) e^{-b t / t+} for t >= 0, zero before."""
    x = np.asarray(t, dtype=np.float64) / blast_time
    return np.where(x >= 0.0, peak * (1.0 - x) * np.exp(-decay * np.maximum(x, 0.0)), 0.0)


def positive_impulse(peak: float, blast_time: float, decay: float = 1.0) -> float:
    """I+ = P t+ (b - 1 + e^{-b}) / b^2 (Pa s), the integral of the positive phase."""
    return peak * blast_time * (decay - 1.0 + math.exp(-decay)) / decay**2


@nb.njit(fastmath=FASTMATH, cache=True)
def explosion_run(out, start, n, st, queue, count, rng, par, absorb, rumble):
    """n samples from absolute frame ``start``; st holds an ExplosionState, par an
    ExplosionParams; queue: a cells.Onset per row (arrival, peak), count[0] blasts queued;
    absorb/rumble: low-pass coefficients (ugens.filters.BiquadCoefficients)."""
    c = explosion_params(par)
    r = c.r
    inv_tp = c.inv_tp
    scatter = c.scatter
    dispersion = c.dispersion
    log_r = math.log(r)
    state = explosion_state(st)
    s1 = state.s1
    s2 = state.s2
    energy = state.energy
    a1 = state.a1
    a2 = state.a2
    t1 = state.t1
    t2 = state.t2
    s = rng[0]
    k_count = count[0]
    tail_gain = c.tail_gain
    rumble_lowpass = biquad_coefficients(rumble)
    absorb_lowpass = biquad_coefficients(absorb)
    for i in range(n):
        t = float(start + i)
        s1, s2 = decay_sums(s1, s2, r)
        k = 0
        while k < k_count:
            onset = queue[k, ONSET_AT]
            if onset <= t:
                s1, s2 = add_onset(s1, s2, queue[k, ONSET_AMPLITUDE], t - onset, log_r)
                k_count = drop_row(queue, k, k_count)
            else:
                k += 1
        p = s1 - s2 * inv_tp
        energy = scatter * energy + (1.0 - scatter) * p * p
        s, u = uniform(s)
        x = tail_gain * math.sqrt(energy) * u
        tail, t1, t2 = biquad_step(rumble_lowpass, x, t1, t2)
        x = (1.0 - dispersion) * p + dispersion * tail
        out[i], a1, a2 = biquad_step(absorb_lowpass, x, a1, a2)
    store(st, ExplosionState(s1, s2, energy, a1, a2, t1, t2))
    rng[0] = s
    count[0] = k_count


@register
class Explosion(UGen):
    """Explosion heard at a distance: Friedlander blast wave (positive phase t+, then
    suction) plus its scattered rumble, 1/r level, r/c delay, air absorption; Pa.

    ``blast`` {overpressure}: a detonation now (peak Pa at 1 m). Model and sources in the
    module docstring; SDT ``explosion~``."""

    type_name = "Explosion"
    param_specs = {
        "blast_time": ParamSpec(
            "float",
            0.01,
            low=1e-4,
            high=10.0,
            unit="s",
            fixed=True,
            doc="positive-phase duration t+ (grows with the charge: ~ W^(1/3))",
        ),
        "decay": ParamSpec(
            "float", 1.0, low=0.01, high=20.0, fixed=True, doc="Friedlander decay coefficient b"
        ),
        "distance": ParamSpec(
            "float", 10.0, low=1.0, high=1e5, unit="m", fixed=True, doc="distance r to the listener"
        ),
        "c": ParamSpec("float", 343.0, low=100.0, high=2000.0, unit="m/s", fixed=True, doc="speed of sound"),
        "scatter_time": ParamSpec(
            "float", 2.0, low=1e-3, high=60.0, unit="s", fixed=True, doc="T60 of the scattered tail"
        ),
        "dispersion": ParamSpec(
            "float", 0.5, low=0.0, high=1.0, doc="share of the scattered tail (0: the bare blast wave)"
        ),
        "rumble": ParamSpec(
            "float", 300.0, low=10.0, high=20000.0, unit="Hz", fixed=True, doc="low-pass cut-off of the tail"
        ),
        "seed": seed_spec(),
    }
    actions = {
        "blast": {
            "overpressure": ParamSpec(
                "float", 1000.0, low=0.0, high=1e9, unit="Pa", doc="peak overpressure at 1 m"
            )
        }
    }

    def _prepare(self) -> None:
        v, fs = self.values, self.sample_rate
        tp = v["blast_time"] * fs
        self.delay = v["distance"] / v["c"] * fs
        self.absorb = np.zeros(5)
        cutoff = min(ABSORPTION_CUTOFF / math.sqrt(v["distance"]), 0.45 * fs)
        design_biquad(_LOWPASS, cutoff, 1.0 / math.sqrt(2.0), 1.0 / fs, self.absorb)
        self.rumble = np.zeros(5)
        design_biquad(_LOWPASS, min(v["rumble"], 0.45 * fs), 1.0 / math.sqrt(2.0), 1.0 / fs, self.rumble)
        # uniform draws (variance 1/3) through the low-pass: scale to unit output variance
        impulse = np.zeros(int(20 * fs / min(v["rumble"], 0.45 * fs)) + 64)
        impulse[0] = 1.0
        from scipy import signal  # imported here: scipy.signal adds about a second to every start

        h = signal.lfilter(self.rumble[:3], [1.0, *self.rumble[3:]], impulse)
        params = ExplosionParams(
            r=math.exp(-v["decay"] / tp),
            inv_tp=1.0 / tp,
            scatter=10.0 ** (-6.0 / (v["scatter_time"] * fs)),
            dispersion=v["dispersion"],
            tail_gain=math.sqrt(3.0 / float(np.dot(h, h))),
        )
        self.par = np.array(params, dtype=np.float64)
        self.st = np.zeros(len(ExplosionState._fields))
        self.queue = np.zeros((QUEUE, ONSET_COLUMNS))
        self.count = np.zeros(1, dtype=np.int64)
        self.rng = np.zeros(1, dtype=np.uint64)
        self._run = specialise(
            explosion_run,
            self.out,
            0,
            0,
            self.st,
            self.queue,
            self.count,
            self.rng,
            self.par,
            self.absorb,
            self.rumble,
        )

    def _reset(self) -> None:
        self.st[:] = 0.0
        self.queue[:] = 0.0
        self.count[0] = 0
        self.rng[0] = self.values["seed"]

    def _param_changed(self, key: str, value: Any, jump: bool) -> None:
        if key == "dispersion":
            self.par[_DISPERSION] = value

    def act(self, action: str, args: dict[str, Any], sample_time: float) -> None:
        """``blast`` {overpressure}: a detonation at fractional ``sample_time``; it reaches
        the listener distance / c later with peak overpressure / distance."""
        if action != "blast":
            return super().act(action, args, sample_time)
        k = int(self.count[0])
        self.queue = with_room(self.queue, k + 1)
        self.queue[k] = Onset(sample_time + self.delay, args["overpressure"] / self.values["distance"])
        self.count[0] = k + 1

    def process(self, start: int, n: int) -> None:
        self._run(
            self.out,
            start,
            n,
            self.st,
            self.queue,
            self.count,
            self.rng,
            self.par,
            self.absorb,
            self.rumble,
        )

    def state_arrays(self) -> dict[str, np.ndarray]:
        return {"st": self.st, "queue": self.queue, "count": self.count, "rng": self.rng, "par": self.par}
