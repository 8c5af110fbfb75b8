"""Stochastic contact controllers (SDT control layer): crumpling, breaking, bouncing.

These emit micro-impacts, each with an energy E (J) and a fragment size s, and output the
resulting contact force in N as raised-cosine pulses (as ImpactForce: exact impulse per
pulse, sub-sample onsets), to drive a ModalBank. The sources are the control algorithms
of the Sound Design Toolkit (``SDTControl.c``; Baldan, Delle Monache & Rocchesso, "The
Sound Design Toolkit", SoftwareX 2017; Rocchesso & Fontana (eds.), "The Sounding Object",
2003, ch. 8 "Crumpling"), see references/audio.md section 3.3.

Energy to impulse: a micro-impact of kinetic energy E delivered by a fragment of mass m
(the ``mass`` parameter) has speed v = sqrt(2 E / m) and momentum J = m v = sqrt(2 m E)
(N s), the impulse of its pulse. Bounce uses the momentum exchanged in each bounce,
J = m (v_in + v_out).

Timing (Crumple, Break): micro-impacts form a Poisson process of rate ``density``
(events/s; for Break scaled by the energy left). SDT draws a Bernoulli trial per sample;
here the process is simulated exactly, per sample and with sub-sample event times: the
integrated rate is accumulated sample by sample (the rate is constant within a sample)
and an event fires when it reaches a threshold drawn from Exp(1) (the time-change
construction of an inhomogeneous Poisson process), so the inter-event times of a
constant rate are exactly exponential. Random draws come from the seeded splitmix64
stream of ugens.noise, one stream per ugen, drawn in event order: the output does not
depend on the block size.

Every ugen has the extra output ``size``: the fragment size of the most recent
micro-impact, held from the first sample of its pulse on (SDT feeds it to the resonator's
fragment size, which scales its frequencies by 1/sqrt(size)).
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numba as nb
import numpy as np

from jassy.errors import PatchError
from jassy.jit import drop_stale_cache, specialise
from jassy.params import ParamSpec, Smoothed
from jassy.registry import register
from ugens import cells, noise
from ugens.cells import (
    MIN_PULSE_SAMPLES,
    PULSE_AMPLITUDE,
    PULSE_LENGTH,
    PULSE_T0,
    append_pulse,
    pulse_amplitude,
    pulse_sum,
    raised_cosine,
    slot,
)
from ugens.impact import PulseSource
from ugens.kernels import FASTMATH
from ugens.noise import seed_spec, uniform

drop_stale_cache(__file__, [cells, noise])  # its cache holds copies of their kernels

#: Rate of the exponential energy distribution of SDT's crumpling (lambda = 1.45).
ENERGY_LAMBDA = 1.45
#: Clip range of the exponential energy draw (multiples of the crushing energy).
ENERGY_CLIP = (0.1, 10.0)

_CRUMPLE, _BREAK, _BREAK_SDT = 0, 1, 2
#: Break's energy scalings: SDT's (events shrink with the energy left) or full-size events.
BREAK_SCALINGS = ("sdt", "full")


class ImpactState(NamedTuple):
    """The controllers' float state, stored in this order in the float64 array ``st``; the
    kernels read and write its fields in place through the slots below (cells.slot)."""

    acc: float  #: integrated event rate since the last event (the Poisson clock, :func:`next_event`)
    target: float  #: the Exp(1) threshold of the next event
    left: float  #: energy left to crumple or break (J)
    budget: float  #: the run's energy (J; 0: no budget)
    running: float  #: 1.0 while events are emitted
    size: float  #: the fragment size held on the size output
    speed: float  #: Bounce: the next impact's speed (m/s)
    next_impact: float  #: Bounce: the next impact's fractional sample


class Counters(NamedTuple):
    """The controllers' counters, stored in this order in the int64 array ``cnt``."""

    events: int  #: micro-impacts since the render started
    logged: int  #: rows of the event log filled


_ACC, _TARGET, _LEFT, _BUDGET, _RUNNING, _SIZE, _SPEED, _NEXT = (
    slot(ImpactState, key) for key in ImpactState._fields
)
_EVENTS, _LOGGED = (slot(Counters, key) for key in Counters._fields)


class LoggedImpact(NamedTuple):
    """A row of the event log ``log``, in this order."""

    at: float  #: start (samples; seconds in :meth:`_MicroImpacts.event_log`)
    energy: float  #: energy (J)
    size: float  #: fragment size
    impulse: float  #: impulse (N s)


_LOG_AT, _LOG_ENERGY, _LOG_SIZE, _LOG_IMPULSE = (slot(LoggedImpact, key) for key in LoggedImpact._fields)


class GrainSettings(NamedTuple):
    """Step settings of :func:`micro_impacts`."""

    fs: float  #: sample rate (Hz)
    spread: float  #: SDT's fragmentation f: each size times 1 - f + f U (drawn only for f > 0)
    mass: float  #: impacting mass (kg)
    T: float  #: pulse length (samples)
    mode: int  #: _CRUMPLE, _BREAK or _BREAK_SDT


class GrainInputs(NamedTuple):
    """Per-sample inputs of :func:`micro_impacts` (arrays of the block's length)."""

    density: np.ndarray  #: micro-impact rate (1/s)
    crush: np.ndarray  #: crushing energy (J)
    frag: np.ndarray  #: fragment size scale


class BounceSettings(NamedTuple):
    """Step settings of :func:`bounces`."""

    fs: float  #: sample rate (Hz)
    g: float  #: gravitational acceleration (m/s^2)
    e: float  #: coefficient of restitution
    irregularity: float  #: random loss per bounce: e (1 - irregularity U)
    mass: float  #: mass of the bouncing object (kg)
    T: float  #: pulse length (samples)
    min_speed: float  #: bouncing stops below this rebound speed (m/s)
    fragment: float  #: size reported on the size output


class ImpactData(NamedTuple):
    """What the controllers' kernels update besides the pulse table."""

    st: np.ndarray  #: float state, an ImpactState
    cnt: np.ndarray  #: int64 counters, a Counters
    rng: np.ndarray  #: splitmix64 state, one uint64
    count: np.ndarray  #: pulses in the table, one int64
    log: np.ndarray  #: (rows, 4) event log: t0 (samples), energy (J), size, impulse (N s)


@nb.njit(fastmath=FASTMATH, cache=True)
def u01(rng):
    """A uniform draw in [0, 1) from the splitmix64 state rng[0] (advanced)."""
    s, u = uniform(rng[0])
    rng[0] = s
    return 0.5 * (u + 1.0)


@nb.njit(fastmath=FASTMATH, cache=True)
def next_event(st, rng, rate, pos):
    """Exact Poisson event times at ``rate`` events per sample.

    st holds an ImpactState (of which ``acc``, the integrated rate, and ``target``, the
    Exp(1) threshold of the next event, are read and written here). From position pos in
    [0, 1) of the current sample, returns the position of the next event in this sample,
    or -1 if there is none (the rate is accumulated)."""
    if st[_TARGET] <= 0.0:
        st[_TARGET] = -math.log(1.0 - u01(rng))
    need = st[_TARGET] - st[_ACC]
    avail = rate * (1.0 - pos)
    if need > avail:
        st[_ACC] += avail
        return -1.0
    st[_ACC] = 0.0
    st[_TARGET] = -math.log(1.0 - u01(rng))
    return min(pos + need / rate, 1.0)


@nb.njit(fastmath=FASTMATH, cache=True)
def pulse_frame(pulses, count, idx):
    """Sum of the active 1 - cos pulses at frame idx; finished ones are dropped.

    pulses[p]: a cells.Pulse (t0, T, A): A (1 - cos(2 pi (idx - t0) / T)) for t0 < idx < t0 + T.
    Returns (sum, pulses still active after idx).
    """
    s = 0.0
    kept = 0
    for p in range(count):
        t0 = pulses[p, PULSE_T0]
        T = pulses[p, PULSE_LENGTH]
        x = idx - t0
        if 0.0 < x < T:
            s += pulses[p, PULSE_AMPLITUDE] * raised_cosine(x, T)
        if t0 + T > idx + 1:
            if kept != p:
                pulses[kept, PULSE_T0] = t0
                pulses[kept, PULSE_LENGTH] = T
                pulses[kept, PULSE_AMPLITUDE] = pulses[p, PULSE_AMPLITUDE]
            kept += 1
    return s, kept


@nb.njit(fastmath=FASTMATH, cache=True)
def log_event(log, cnt, t0, energy, size, impulse):
    """Record (t0 in samples, energy J, size, impulse N s) while the log has room."""
    k = cnt[_LOGGED]
    if k < log.shape[0]:
        log[k, _LOG_AT] = t0
        log[k, _LOG_ENERGY] = energy
        log[k, _LOG_SIZE] = size
        log[k, _LOG_IMPULSE] = impulse
        cnt[_LOGGED] = k + 1


@nb.njit(fastmath=FASTMATH, cache=True)
def micro_impacts(out, size_out, start, n, inputs, opt, d, pulses):
    """Crumple / Break kernel for frames start .. start + n - 1; returns the pulse table.

    Per frame idx: output the pulses and the held size, then fire the Poisson events of
    the interval [idx, idx + 1): their pulses start at the next frame. inputs: a
    GrainInputs, opt: GrainSettings, d: ImpactData. mode 0: rate = density; mode 1
    (break): rate = density * energy left / budget; mode 2 (break as SDT): that rate, each
    event's energy and size also times energy left / budget, and the run ends once the
    energy left is below one crushing energy.
    """
    density, crush, frag = inputs
    fs, spread, mass, T, mode = opt
    st, cnt, rng = d.st, d.cnt, d.rng
    count = d.count[0]
    for i in range(n):
        idx = start + i
        s, count = pulse_frame(pulses, count, idx)
        out[i] = s
        size_out[i] = st[_SIZE]
        pos = 0.0  # position inside [idx, idx + 1) already accounted for
        while st[_RUNNING] != 0.0:
            if mode == _BREAK_SDT and st[_LEFT] <= crush[i]:
                st[_RUNNING] = 0.0
                break
            rate = density[i] / fs
            if mode != _CRUMPLE:
                rate *= st[_LEFT] / st[_BUDGET]
            if rate <= 0.0:
                break
            pos = next_event(st, rng, rate, pos)
            if pos < 0.0:
                break
            x = -math.log(1.0 - u01(rng)) / ENERGY_LAMBDA
            energy = crush[i] * min(max(x, ENERGY_CLIP[0]), ENERGY_CLIP[1])
            size = frag[i]
            if spread > 0.0:
                size *= 1.0 - spread + spread * u01(rng)
            size *= 0.5 + 0.5 * u01(rng)
            if mode == _BREAK_SDT:
                energy *= st[_LEFT] / st[_BUDGET]
                size *= st[_LEFT] / st[_BUDGET]
            if st[_BUDGET] > 0.0:
                if energy >= st[_LEFT]:
                    energy = st[_LEFT]
                    st[_RUNNING] = 0.0
                st[_LEFT] -= energy
            t0 = idx + pos
            impulse = math.sqrt(2.0 * mass * energy)
            pulses = append_pulse(pulses, count, t0, T, pulse_amplitude(impulse, fs, t0, T))
            count += 1
            st[_SIZE] = size
            cnt[_EVENTS] += 1
            log_event(d.log, cnt, t0, energy, size, impulse)
    d.count[0] = count
    return pulses


@nb.njit(fastmath=FASTMATH, cache=True)
def bounces(out, size_out, start, n, opt, d, pulses):
    """Bounce kernel: ballistic flights between impacts; returns the pulse table.

    opt: a BounceSettings, d: ImpactData (its ImpactState's ``next_impact``: the fractional
    sample of the next impact, ``speed``: its impact speed, m/s). An impact at speed v leaves
    at v' = v e (1 - irregularity U),
    pushes J = m (v + v'), and the next impact follows after the flight time 2 v' / g;
    bouncing stops once v' < min_speed.
    """
    fs, g, e, irregularity, mass, T, min_speed, fragment = opt
    st, cnt, rng = d.st, d.cnt, d.rng
    count = d.count[0]
    for i in range(n):
        idx = start + i
        s, count = pulse_frame(pulses, count, idx)
        out[i] = s
        size_out[i] = st[_SIZE]
        while st[_RUNNING] != 0.0 and st[_NEXT] < idx + 1:
            t0 = st[_NEXT]
            v = st[_SPEED]
            u = u01(rng)
            v_out = v * e * (1.0 - irregularity * u)
            impulse = mass * (v + v_out)
            # pulse_amplitude in this kernel's fastmath: the shipped bounce renders' last bits
            amplitude = impulse * fs / pulse_sum(t0, T)
            pulses = append_pulse(pulses, count, t0, T, amplitude)
            count += 1
            cnt[_EVENTS] += 1
            st[_SIZE] = fragment
            log_event(d.log, cnt, t0, 0.5 * mass * v * v, fragment, impulse)
            if v_out < min_speed or v_out <= 0.0:
                st[_RUNNING] = 0.0
            else:
                st[_SPEED] = v_out
                st[_NEXT] = t0 + 2.0 * v_out / g * fs
    d.count[0] = count
    return pulses


_SEED = seed_spec("random seed (splitmix64 stream)")
#: Default micro-impact: a 0.2 g fragment (a 25 cm^2 facet of 80 g/m^2 paper, or a glass
#: shard of 0.08 cm^3) at 1 m/s (a hand's crumpling speed), E = m v^2 / 2 = 1e-4 J: impulse
#: sqrt(2 m E) = 2e-4 N s, so through a calibrated ModalBank (ugens.modal, jassy.levels)
#: the default crumpling and breaking peak between -30 and -6 dBFS.
_MASS = ParamSpec(
    "float",
    2e-4,
    low=0.0,
    low_open=True,
    high=1e3,
    unit="kg",
    doc="impacting mass: impulse = sqrt(2 mass energy) per micro-impact",
)
_DURATION = ParamSpec(
    "float",
    2e-4,
    low=0.0,
    low_open=True,
    high=0.1,
    unit="s",
    doc="contact duration of a micro-impact pulse (at least 2 samples; shorter = harder)",
)
_FRAGMENT = ParamSpec(
    "float",
    1.0,
    low=0.0,
    low_open=True,
    high=1.0,
    smooth=True,
    doc="fragment size scale: size = fragment * U(0.5, 1) per micro-impact",
)
_DENSITY = ParamSpec("float", 100.0, low=0.0, high=1e6, unit="1/s", smooth=True, doc="mean micro-impact rate")
_CRUSH = ParamSpec(
    "float",
    1e-4,
    low=0.0,
    high=1e6,
    unit="J",
    smooth=True,
    doc="crushing energy E: micro-impact energy = E * clip(Exp(1.45), 0.1, 10)",
)


class _MicroImpacts(PulseSource):
    """RNG, state and event log shared by the controllers (the pulse table is PulseSource's)."""

    outputs = ("size",)
    #: Rows kept by the event log (see :meth:`event_log`); 0 disables it.
    log_capacity = 0

    def _prepare(self) -> None:
        super()._prepare()
        self.st = np.zeros(len(ImpactState._fields))
        self.cnt = np.zeros(len(Counters._fields), dtype=np.int64)
        self.rng = np.zeros(1, dtype=np.uint64)
        self.log = np.zeros((int(self.log_capacity), len(LoggedImpact._fields)))
        self._constant: dict[int, float] = {}
        self._impact_data = ImpactData(self.st, self.cnt, self.rng, self.count, self.log)
        self._opt = None  # the kernel's settings record, rebuilt after a parameter change

    def _reset(self) -> None:
        super()._reset()
        self.st[:] = 0.0
        self.cnt[:] = 0
        self.rng[0] = self.values["seed"]

    def _data(self) -> ImpactData:
        return self._impact_data

    def _per_sample(self, ramp: Smoothed, buffer: np.ndarray, n: int) -> np.ndarray:
        """Per-sample values of a smoothed parameter; a steady one is written once."""
        if ramp.steady:
            if self._constant.get(id(buffer)) != ramp.value:
                buffer[:] = ramp.value
                self._constant[id(buffer)] = ramp.value
            return buffer
        self._constant.pop(id(buffer), None)
        return ramp.fill(buffer, n)

    def _pulse_samples(self) -> float:
        return max(self.values["duration"] * self.sample_rate, MIN_PULSE_SAMPLES)

    @property
    def events(self) -> int:
        """Micro-impacts emitted since the render started."""
        return int(self.cnt[_EVENTS])

    def event_log(self) -> np.ndarray:
        """Logged micro-impacts as rows (time s, energy J, size, impulse N s).

        Set ``log_capacity`` (rows) on the instance before rendering; the first
        ``log_capacity`` events are kept. For analysis and tests; not part of the state.
        """
        rows = self.log[: int(self.cnt[_LOGGED])].copy()
        rows[:, _LOG_AT] /= self.sample_rate
        return rows

    def state_arrays(self) -> dict[str, np.ndarray]:
        return {**super().state_arrays(), "st": self.st, "cnt": self.cnt, "rng": self.rng}


class _Granular(_MicroImpacts):
    """Crumple and Break: Poisson micro-impacts with smoothed density, energy, fragment."""

    _mode = _CRUMPLE
    _SMOOTHED = ("density", "crushing_energy", "fragment")

    def _prepare(self) -> None:
        super()._prepare()
        self.ramps = {key: self.smoothed(key) for key in self._SMOOTHED}
        self.buffers = {key: np.zeros(self.max_block) for key in self._SMOOTHED}
        self._inputs = GrainInputs(*(self.buffers[key] for key in self._SMOOTHED))
        x = self.out
        self._kernel = specialise(
            micro_impacts,
            x,
            x,
            0,
            0,
            GrainInputs(x, x, x),
            GrainSettings(1.0, 1.0, 1.0, 1.0, 0),
            self._data(),
            self.pulses,
        )

    def _reset(self) -> None:
        super()._reset()
        for ramp in self.ramps.values():
            ramp.set(ramp.target, 0, jump=True)

    def _param_changed(self, key: str, value: Any, jump: bool) -> None:
        if key in self.ramps:
            self.ramps[key].set(value, self.ramp_samples(), jump)
        self._opt = None

    def _arm(self, budget: float | None) -> None:
        """Start emitting; a budget (J) makes the run stop once that energy is spent."""
        self.st[_RUNNING] = 1.0
        self.st[_BUDGET] = 0.0 if budget is None else budget
        self.st[_LEFT] = self.st[_BUDGET]
        if budget is not None and budget <= 0.0:
            self.st[_RUNNING] = 0.0

    def process(self, start: int, n: int) -> None:
        for key in self._SMOOTHED:  # the per-sample values of the block into self._inputs
            self._per_sample(self.ramps[key], self.buffers[key], n)
        if self._opt is None:
            v = self.values
            fragmentation = v.get("fragmentation", 0.0)
            self._opt = GrainSettings(
                self.sample_rate, fragmentation, v["mass"], self._pulse_samples(), self._mode
            )
        self.pulses = self._kernel(
            self.out, self.extra["size"], start, n, self._inputs, self._opt, self._impact_data, self.pulses
        )

    def state_arrays(self) -> dict[str, np.ndarray]:
        return {**super().state_arrays(), **{k: r.ramp for k, r in self.ramps.items()}}


@register
class Crumple(_Granular):
    """Crumpling (SDT crumpling~): Poisson micro-impacts, force in N, extra output ``size``.

    Between ``start`` and ``stop`` micro-impacts occur at ``density`` per second, each of
    energy E * clip(Exp(1.45), 0.1, 10) (E = ``crushing_energy``), fragment size
    ``fragment`` * (1 - f + f U) * U(0.5, 1) (f = ``fragmentation``, SDT's
    ``SDTCrumpling_dsp``), impulse sqrt(2 ``mass`` energy) N s, as a 1 - cos pulse of
    ``duration``. Connect ``size`` to a ModalBank's ``size`` input for SDT's crumpling
    model: each event retunes the resonator to its fragment size (frequencies and decay
    rates times 1/sqrt(size), displacement per unit impulse times 1/sqrt(size)).
    ``start`` with ``energy`` (J) crumples a finite budget: the last micro-impact takes
    what is left and the crumpling stops. Source: SDT (Baldan et al.
    2017), Rocchesso & Fontana, "The Sounding Object" (2003) ch. 8.
    """

    type_name = "Crumple"
    param_specs = {
        "density": _DENSITY,
        "crushing_energy": _CRUSH,
        "fragment": _FRAGMENT,
        "fragmentation": ParamSpec(
            "float",
            0.0,
            low=0.0,
            high=1.0,
            fixed=True,
            doc="fragmentation spread f: size times 1 - f + f U (SDT crumpling; 0: none)",
        ),
        "mass": _MASS,
        "duration": _DURATION,
        "seed": _SEED,
    }
    actions = {
        "start": {
            "energy": ParamSpec(
                "float",
                None,
                low=0.0,
                low_open=True,
                high=1e9,
                unit="J",
                doc="total energy to crumple, then stop (omitted: until stop)",
            )
        },
        "stop": {},
    }

    def act(self, action: str, args: dict[str, Any], sample_time: float) -> None:
        """``start`` {energy}: begin (again) at this frame; ``stop``: no new micro-impacts."""
        if action == "start":
            self._arm(args.get("energy"))
        elif action == "stop":
            self.st[_RUNNING] = 0.0
        else:
            super().act(action, args, sample_time)


@register
class Break(_Granular):
    """Breaking (SDT breaking~): micro-impacts that draw down a stored energy budget.

    ``break`` {energy} stores ``energy`` J; micro-impacts then occur at the rate
    ``density`` * R, R = energy left / energy stored, so the cascade thins out as it goes.
    Impulse sqrt(2 ``mass`` energy) N s per pulse. Extra output ``size``.

    ``scaling = "sdt"`` (default, SDT's ``breaking~``): each micro-impact takes
    E R clip(Exp(1.45), 0.1, 10) (E = ``crushing_energy``) and has the size
    ``fragment`` R U(0.5, 1), so the fragments get smaller and weaker as the energy runs
    out and the cascade fades; it ends once the energy left is below E (the rest is not
    emitted). ``scaling = "full"``: full-size events E clip(Exp(1.45), 0.1, 10) and sizes
    ``fragment`` U(0.5, 1) throughout, the last one taking what is left, so the energies
    of all pulses sum to the budget. Source: SDT ``SDTBreaking_dsp`` (Baldan et al. 2017).
    """

    type_name = "Break"
    _mode = _BREAK
    param_specs = {
        "density": ParamSpec(
            "float",
            1000.0,
            low=0.0,
            high=1e6,
            unit="1/s",
            smooth=True,
            doc="micro-impact rate at a full budget",
        ),
        "crushing_energy": _CRUSH,
        "fragment": _FRAGMENT,
        "mass": _MASS,
        "duration": _DURATION,
        "seed": _SEED,
        "scaling": ParamSpec(
            "str",
            "sdt",
            choices=BREAK_SCALINGS,
            fixed=True,
            doc="sdt: events shrink with the energy left and fade out; full: full-size events",
        ),
    }
    actions = {
        "break": {
            "energy": ParamSpec(
                "float",
                5e-3,
                low=0.0,
                low_open=True,
                high=1e9,
                unit="J",
                doc="stored energy to release (default: 50 crushing energies)",
            )
        },
        "stop": {},
    }

    def _prepare(self) -> None:
        super()._prepare()
        self._mode = _BREAK_SDT if self.values["scaling"] == "sdt" else _BREAK

    def act(self, action: str, args: dict[str, Any], sample_time: float) -> None:
        """``break`` {energy}: store the budget and start; ``stop``: abandon what is left."""
        if action == "break":
            self._arm(args["energy"])
        elif action == "stop":
            self.st[_RUNNING] = 0.0
        else:
            super().act(action, args, sample_time)


@register
class Bounce(_MicroImpacts):
    """Bouncing (SDT bouncing~): ballistic bounces of a dropped object, force in N.

    ``drop`` {height} releases the object at rest ``height`` m above the surface (first
    impact sqrt(2 h / g) later, at speed sqrt(2 g h)); ``drop`` {speed} makes it hit the
    surface now at ``speed`` m/s. Each impact at speed v leaves at
    v' = v * restitution * (1 - irregularity * U), U ~ U(0, 1), is a 1 - cos pulse of
    impulse mass * (v + v') N s (the momentum exchanged), and the next impact follows
    after the exact flight time 2 v' / g. With irregularity 0 the times and impulses are
    the closed form t_{i+1} - t_i = 2 e v_i / g, v_{i+1} = e v_i. Bouncing stops when
    v' < ``min_speed``. Extra output ``size``: the ``fragment`` parameter at each impact.
    The default object is light, a 0.5 g shirt button (or a 7 mm glass bead): dropped
    10 cm it first exchanges 0.5e-3 * 1.4 * 1.7 = 1.2e-3 N s, about the reference strike of
    a calibrated ModalBank (1e-3 N s at -18 dBFS, jassy.levels), so it peaks between -30
    and -6 dBFS; a 10 g ball from 20 cm would exchange 29 dB more and pin the limiter.
    Source: SDT (Baldan et al. 2017).
    """

    type_name = "Bounce"
    param_specs = {
        "restitution": ParamSpec(
            "float", 0.7, low=0.0, high=1.0, doc="coefficient of restitution e (speed ratio)"
        ),
        "irregularity": ParamSpec(
            "float", 0.0, low=0.0, high=1.0, doc="random loss per bounce: e * (1 - irregularity * U)"
        ),
        "gravity": ParamSpec(
            "float", 9.81, low=0.0, low_open=True, high=1e4, unit="m/s^2", doc="gravitational acceleration"
        ),
        "mass": ParamSpec(
            "float",
            5e-4,
            low=0.0,
            low_open=True,
            high=1e4,
            unit="kg",
            doc="mass of the bouncing object (default: a 0.5 g shirt button or 7 mm glass bead)",
        ),
        "duration": ParamSpec(
            "float",
            5e-4,
            low=0.0,
            low_open=True,
            high=0.1,
            unit="s",
            doc="contact duration of an impact pulse (at least 2 samples)",
        ),
        "min_speed": ParamSpec(
            "float",
            0.02,
            low=0.0,
            low_open=True,
            high=1e3,
            unit="m/s",
            doc="bouncing stops when the rebound speed falls below this",
        ),
        "fragment": ParamSpec(
            "float", 1.0, low=0.0, low_open=True, high=1.0, doc="size reported on the size output"
        ),
        "seed": _SEED,
    }
    actions = {
        "drop": {
            "height": ParamSpec(
                "float", None, low=0.0, low_open=True, high=1e4, unit="m", doc="release height (at rest)"
            ),
            "speed": ParamSpec(
                "float", None, low=0.0, low_open=True, high=1e4, unit="m/s", doc="impact speed, hitting now"
            ),
        },
        "stop": {},
    }

    def act(self, action: str, args: dict[str, Any], sample_time: float) -> None:
        """``drop`` {height | speed}: start a bouncing sequence; ``stop``: no more impacts."""
        if action == "stop":
            self.st[_RUNNING] = 0.0
            return
        if action != "drop":
            return super().act(action, args, sample_time)
        height, speed = args.get("height"), args.get("speed")
        if (height is None) == (speed is None):
            raise PatchError(f"{self.type_name} {self.name!r}: drop: give either height (m) or speed (m/s)")
        g = self.values["gravity"]
        if speed is None:
            speed = math.sqrt(2.0 * g * height)
            sample_time += math.sqrt(2.0 * height / g) * self.sample_rate
        self.st[_NEXT] = sample_time
        self.st[_SPEED] = speed
        self.st[_RUNNING] = 1.0

    def _param_changed(self, key: str, value: Any, jump: bool) -> None:
        self._opt = None  # read at each impact

    def _prepare(self) -> None:
        super()._prepare()
        x = self.out
        self._kernel = specialise(bounces, x, x, 0, 0, self._settings(), self._data(), self.pulses)

    def _settings(self) -> BounceSettings:
        v = self.values
        keys = ("gravity", "restitution", "irregularity", "mass")
        fs, g, e, irregularity, mass = (float(x) for x in (self.sample_rate, *(v[k] for k in keys)))
        pulse = self._pulse_samples()
        return BounceSettings(
            fs, g, e, irregularity, mass, pulse, float(v["min_speed"]), float(v["fragment"])
        )

    def process(self, start: int, n: int) -> None:
        if self._opt is None:
            self._opt = self._settings()
        self.pulses = self._kernel(
            self.out, self.extra["size"], start, n, self._opt, self._impact_data, self.pulses
        )
