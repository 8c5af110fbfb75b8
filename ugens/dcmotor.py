"""DCMotor: a permanent-magnet DC motor's speed dynamics and its mechanical sounds.

Dynamics (e.g. Hughes & Drury, *Electric Motors and Drives*, 4th ed., ch. 3). With the
armature inductance neglected (its time constant L/R is far below the mechanical one),
the current is i = (V - k w) / R, and the rotor speed w (rad/s) obeys

    J dw/dt = k i - b w - T_load = k V / R - T_load - (k^2 / R + b) w,

a first-order lag towards w_ss = (k V / R - T_load) / (k^2 / R + b) with time constant
J / (k^2 / R + b): start-up, and the speed drop under a load step. Switched off, the
circuit is open (i = 0): the rotor coasts down with time constant J / b, braked by the
load. Voltage and load are held over each sample, so the exact exponential step is used
(w_{n+1} = w_ss + (w_n - w_ss) a, a = e^{-g / (J fs)}, g = k^2 / R + b), and the rotor
angle advances by the exact integral of w over the sample. The rotor never turns
backwards (a load above the stall torque holds it at rest).

Sound, from the rotor angle phi (revolutions) and the rotation rate f_r = w / 2 pi:

* rotor: the unbalance force, ~ w^2, at f_r and (misalignment) 2 f_r;
* commutation: the torque ripple at ``segments`` f_r, ~ |i|, and brush noise: white
  noise in bursts at each commutation ((1 + cos 2 pi segments phi)^4 / 16), ~ |i| sqrt(w);
* gears: the mesh at ``teeth`` f_r and its 2nd and 3rd harmonics (amplitudes 1, 1/2,
  1/3), ~ w (the tooth-passing impacts).

Levels are full-scale amplitudes at 3000 rpm and 1 A; their defaults put the default motor
(12 V: 5460 rpm) near -10 dBFS peak, within the -30..-6 dBFS of the level convention of
jassy.levels. Extra output ``rpm``: the rotor speed.
SDT's counterpart: ``dcmotor~`` (Baldan et al. 2017, rotor, brushes and gears).
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numba as nb
import numpy as np

from jassy.jit import drop_stale_cache, specialise
from jassy.params import Control, ParamSpec
from jassy.registry import register
from jassy.ugen import UGen
from ugens import cells, noise
from ugens.cells import slot, store
from ugens.kernels import FASTMATH
from ugens.noise import seed_spec, uniform

drop_stale_cache(__file__, [cells, noise])  # its cache holds copies of their kernels

#: Reference speed (rad/s) and current (A) of the component levels.
REFERENCE_SPEED = 2.0 * math.pi * 50.0
REFERENCE_CURRENT = 1.0
#: Relative amplitude of the rotor's second harmonic (misalignment).
SECOND_HARMONIC = 0.3


class MotorParams(NamedTuple):
    """Settings of :func:`motor_run`, stored in this order in the float64 array ``par``."""

    fs: float  #: sample rate (Hz)
    resistance: float  #: armature resistance R (ohm)
    motor_constant: float  #: k (V s/rad = N m/A)
    inertia: float  #: J (kg m^2)
    friction: float  #: viscous friction b (N m s/rad)
    on: float  #: 1.0 while switched on
    segments: float  #: commutator segments
    teeth: float  #: gear teeth
    rotor_level: float  #: rotor harmonics at the reference speed
    ripple_level: float  #: torque-ripple tone at 1 A
    brush_level: float  #: brush noise at 1 A and the reference speed
    gear_level: float  #: gear-mesh whine at the reference speed


@nb.njit(inline="always", cache=True)
def motor_params(par):
    """The MotorParams record held in ``par``."""
    return MotorParams(
        par[0], par[1], par[2], par[3], par[4], par[5], par[6], par[7], par[8], par[9], par[10], par[11]
    )


class MotorState(NamedTuple):
    """State of :func:`motor_run`, stored in this order in the float64 array ``st``."""

    w: float  #: rotor speed (rad/s)
    phi: float  #: rotor angle (turns, in [0, 1))


@nb.njit(inline="always", cache=True)
def motor_state(st):
    """The MotorState record held in ``st``."""
    return MotorState(st[0], st[1])


@nb.njit(fastmath=FASTMATH, cache=True)
def motor_run(out, rpm_out, n, volts, loads, st, rng, par):
    """n samples: speed step, sound from the rotor angle at the start of the sample; par
    holds a MotorParams, st a MotorState."""
    prm = motor_params(par)
    fs = prm.fs
    res = prm.resistance
    k = prm.motor_constant
    inertia = prm.inertia
    friction = prm.friction
    on = prm.on != 0.0
    segments = prm.segments
    teeth = prm.teeth
    rotor_level = prm.rotor_level
    ripple_level = prm.ripple_level
    brush_level = prm.brush_level
    gear_level = prm.gear_level
    two_pi = 2.0 * math.pi
    held = motor_state(st)
    w = held.w
    phi = held.phi
    s = rng[0]
    g = k * k / res + friction if on else friction
    a = math.exp(-g / (inertia * fs))
    lag = (1.0 - a) * inertia / g  # integral of a^(t fs) over one sample, in s
    for i in range(n):
        v = volts[i] if on else 0.0
        current = (v - k * w) / res if on else 0.0
        speed = w / REFERENCE_SPEED
        rotor = (
            rotor_level
            * speed
            * speed
            * (math.sin(two_pi * phi) + SECOND_HARMONIC * math.sin(2.0 * two_pi * phi))
        )
        c = math.cos(two_pi * segments * phi)
        ripple = ripple_level * abs(current) / REFERENCE_CURRENT * c
        burst = 0.5 + 0.5 * c
        burst *= burst
        s, u = uniform(s)
        brush = brush_level * abs(current) / REFERENCE_CURRENT * math.sqrt(speed) * burst * burst * u
        x = two_pi * teeth * phi
        gear = gear_level * speed * (math.sin(x) + math.sin(2.0 * x) / 2.0 + math.sin(3.0 * x) / 3.0)
        out[i] = rotor + ripple + brush + gear
        rpm_out[i] = w * 60.0 / two_pi
        drive = (k * v / res if on else 0.0) - loads[i]
        w_ss = drive / g
        w_next = w_ss + (w - w_ss) * a
        if w_next >= 0.0:
            phi += (w_ss / fs + (w - w_ss) * lag) / two_pi
        else:  # stops within the sample, at t0 where w(t0) = 0: advance by int_0^t0 w dt
            t0 = inertia / g * math.log((w - w_ss) / -w_ss)
            phi += (w_ss * t0 + inertia * w / g) / two_pi
            w_next = 0.0
        w = w_next
        phi -= math.floor(phi)
    store(st, MotorState(w, phi))
    rng[0] = s


@register
class DCMotor(UGen):
    """DC motor: first-order speed dynamics (start-up, load, coast-down) and its sounds:
    rotor harmonics, commutator ripple and brush noise, gear mesh at teeth x f_r.

    Model and sources in the module docstring; SDT ``dcmotor~``. Extra output ``rpm``."""

    type_name = "DCMotor"
    outputs = ("rpm",)
    param_specs = {
        "voltage": ParamSpec(
            "float", 12.0, low=0.0, high=1000.0, unit="V", smooth=True, doc="supply voltage"
        ),
        "load": ParamSpec(
            "float", 0.0, low=0.0, high=1000.0, unit="N m", smooth=True, doc="load torque on the shaft"
        ),
        "switched_on": ParamSpec("bool", True, doc="circuit closed (false: open, the rotor coasts)"),
        "resistance": ParamSpec(
            "float", 2.0, low=1e-3, high=1e4, unit="ohm", fixed=True, doc="armature resistance R"
        ),
        "motor_constant": ParamSpec(
            "float",
            0.02,
            low=1e-5,
            high=100.0,
            unit="N m/A",
            fixed=True,
            doc="torque constant = back-EMF constant k (V s/rad)",
        ),
        "inertia": ParamSpec(
            "float", 2e-5, low=1e-9, high=1e3, unit="kg m^2", fixed=True, doc="rotor + load inertia J"
        ),
        "friction": ParamSpec(
            "float",
            1e-5,
            low=1e-9,
            high=1e3,
            unit="N m s",
            fixed=True,
            doc="viscous friction b (sets the coast-down time J / b)",
        ),
        "segments": ParamSpec("int", 12, low=1, high=256, fixed=True, doc="commutator segments per turn"),
        "teeth": ParamSpec("int", 14, low=1, high=1000, fixed=True, doc="teeth of the pinion on the shaft"),
        "rotor_level": ParamSpec("float", 0.06, low=0.0, high=100.0, doc="unbalance tone at 3000 rpm"),
        "ripple_level": ParamSpec("float", 0.01, low=0.0, high=100.0, doc="torque-ripple tone at 1 A"),
        "brush_level": ParamSpec("float", 0.04, low=0.0, high=100.0, doc="brush noise at 1 A, 3000 rpm"),
        "gear_level": ParamSpec("float", 0.03, low=0.0, high=100.0, doc="gear-mesh whine at 3000 rpm"),
        "seed": seed_spec(),
    }
    _LEVELS = {
        key: slot(MotorParams, key) for key in ("rotor_level", "ripple_level", "brush_level", "gear_level")
    }

    def _prepare(self) -> None:
        v = self.values
        self.st = np.zeros(len(MotorState._fields))
        self.rng = np.zeros(1, dtype=np.uint64)
        self.par = np.zeros(len(MotorParams._fields))
        fixed = ("resistance", "motor_constant", "inertia", "friction", "segments", "teeth")
        self.par[slot(MotorParams, "fs")] = self.sample_rate
        for key in fixed:
            self.par[slot(MotorParams, key)] = v[key]
        for key in (*self._LEVELS, "switched_on"):
            self._param_changed(key, v[key], True)
        self.voltage = self.smoothed("voltage")
        self.load = self.smoothed("load")
        self._volts = Control(self.voltage, self.max_block)
        self._loads = Control(self.load, self.max_block)
        self._run = specialise(
            motor_run,
            self.out,
            self.out,
            0,
            self._volts.buffer,
            self._loads.buffer,
            self.st,
            self.rng,
            self.par,
        )

    def _reset(self) -> None:
        self.st[:] = 0.0
        self.rng[0] = self.values["seed"]
        for ramp in (self.voltage, self.load):
            ramp.set(ramp.target, 0, jump=True)

    def _param_changed(self, key: str, value: Any, jump: bool) -> None:
        if key in ("voltage", "load"):
            getattr(self, key).set(value, self.ramp_samples(), jump)
        elif key == "switched_on":
            self.par[slot(MotorParams, "on")] = 1.0 if value else 0.0
        else:
            self.par[self._LEVELS[key]] = value

    def process(self, start: int, n: int) -> None:
        self._run(
            self.out,
            self.extra["rpm"],
            n,
            self._volts.values(n),
            self._loads.values(n),
            self.st,
            self.rng,
            self.par,
        )

    def state_arrays(self) -> dict[str, np.ndarray]:
        return {
            "st": self.st,
            "rng": self.rng,
            "par": self.par,
            "voltage": self.voltage.ramp,
            "load": self.load.ramp,
        }
