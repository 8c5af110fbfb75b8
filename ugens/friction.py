"""Friction: elasto-plastic (bristle) friction in a closed loop with a modal resonator.

An exciter (bow, finger, hinge pin) moves at velocity ``speed`` (m/s) against the contact
point of a modal resonator, pressed with normal force ``force`` (N). The relative velocity
v = v_exciter - v_contact drives the mean bristle deflection z (m) of the elasto-plastic
model (Dupont, Hayward, Armstrong & Altpeter, IEEE TAC 2002; Avanzini, Serafin &
Rocchesso, IEEE TSAP 2005; SDT ``SDTFriction_ElastoPlastic``):

    f_s = static * F_N,   f_c = dynamic * F_N,   f_ss(v) = f_c + (f_s - f_c) e^{-(v/v_s)^2}
    z_ss(v) = sgn(v) f_ss(v) / sigma0,          z_ba = sgn(v) breakaway * f_c / sigma0
    alpha(z, v) = 0 if sgn z != sgn v or |z| < |z_ba|; 1 if |z| > |z_ss|;
                  1/2 + 1/2 sin(pi (z - (z_ss + z_ba)/2) / (z_ss - z_ba)) in between
    dz/dt = v (1 - alpha(z, v) z / z_ss(v))
    f = sigma0 z + sigma1 dz/dt + sigma2 v + sigma3 w,   w = u sqrt(|v| F_N),  u ~ U[-1, 1)

and f pushes the resonator's contact point. In steady sliding z = z_ss and
f = sgn(v) f_ss(v) + sigma2 v (Coulomb + Stribeck + viscous). Below the break-away
deflection the contact is a pure spring-damper; between z_ba and z_ss it creeps only
while it moves (dz/dt is proportional to v), so a constant load below f_s is held with
no drift (true sticking, unlike the LuGre model).

Resonator (the closed-loop convention of jassy): each mode obeys
q_k'' + 2 d_k q_k' + (w_k^2 + d_k^2) q_k = a_k w_k f, the contact displacement is
x_c = sum_k q_k (the main output, in m) and its modes are stepped with ModalBank's exact
impulse-invariant recursion q_k[n] = c1 q_k[n-1] - c2 q_k[n-2] + g_k f[n] with
g_k = a_k R_k sin(theta_k) / fs, so for the same force the output equals a ModalBank's.
An external force f_e on the same point (input ``strike``) enters as g_k (f + f_e), and the
pickup hears f + f_e: with no contact (F_N = 0) the output is the resonator's linear
response to f_e alone.
The gains a[p, k] at the contact are a driving-point response (force applied and motion
observed at the same point; ModalModel.driving_at): they must be >= 0, or the loop would
create energy. The main output is what the model's pickup hears: the same modes under the
same force with the model's signed gains (:mod:`ugens.heard`, the same recursion); it is
x_c (output ``contact``) when the model has no separate driving-point gains.

Discretisation (per sample, no delay in the loop). The contact velocity is the mean
velocity over the last sample, v_c[n] = (x_c[n] - x_c[n-1]) fs; with the resonator
recursion it is affine in this sample's force, v_c = V_h + G_v f with
G_v = sum_k a_k R_k sin(theta_k) >= 0 (the instantaneous admittance). The bristle uses
backward Euler, z[n] = z[n-1] + T g(z[n], v[n]), and dz/dt = (z[n] - z[n-1]) / T in f.
Eliminating f and v leaves one scalar equation in z[n],

    R(z) = z - z[n-1] - T g(z, v(z)) = 0,   v(z) = (A - K z) / D,
    K = G_v (sigma0 + sigma1 fs),  D = 1 + G_v sigma2,

solved by Newton's method from z[n-1] with the analytic derivative (two iterations when
sticking, where R is linear; two to four when sliding); if Newton stalls (dR/dz <= 0 at a
fold of the Stribeck branch) a bracket is grown from z[n-1] until R changes sign (R -> +-inf
as z -> +-inf because K >= 0, D >= 1) and closed by safeguarded Newton-bisection. Backward
Euler is L-stable, so there is no step limit on sigma0, sigma1 or the bristle time
constant f_ss / (sigma0 |v|): bristle dynamics faster than a sample are resolved as their
quasi-static limit. (An explicit Euler step, as in the SDT, needs sigma0 |v| T / f_ss < 2;
at the defaults, F_N = 1 N and a slip velocity of 0.5 m/s at 48 kHz it is 5.2: unstable.) The noise amplitude
sqrt(|v| F_N) uses the previous sample's v (keeps R smooth). With F_N <= 1e-9 N the
exciter is off the resonator: f = 0 and z = 0.

Units: sigma0 N/m, sigma1 and sigma2 N s/m, sigma3 (``noise``) sqrt(N s/m) so that
sigma3 w is in N. The SDT defaults (sigma0 = 1000, sigma1 = 10, sigma2 = 10) are in the
SDT's own resonator units; the defaults here are scaled for a real string. A violin G
string has wave impedance Z = sqrt(T mu) ~ 0.35 N s/m, so the bow sees 2 Z ~ 0.7 N s/m:
sigma0 = 1e5 N/m (z_ss ~ 8 um at F_N = 1 N) relaxes through it in 2 Z / sigma0 ~ 7 us,
a third of a sample, so the bow holds the string firmly while sticking (in
bowed-string.toml the slip lasts 16 % of the period, Helmholtz motion's ideal being the
bowing point, 12 %); sigma1 = 0.02 and sigma2 = 0.01
N s/m stay far below 2 Z, so the Stribeck drop, not viscosity, shapes the motion.
Location changes during a render take effect at once (the gains jump; the state is kept).

Regimes (measured map: examples/friction_regimes.py). A mode sings when the friction force
falls with slip speed around the operating point, i.e. for slip speeds up to a few
``stribeck`` speeds: faster, the force is flat (Coulomb) and the contact slides silently.
More force raises the level until, at low speed, the contact sticks too long and the motion
turns raucous or moves to a lower mode; too little force for the speed gives several slips
per period (higher partials): Schelleng's diagram for the bowed string.
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
from ugens import cells, driving_point, heard, kernels, modal, noise
from ugens.cells import store
from ugens.driving_point import MODE_ROWS, driving_point_modes, free_motion, settle
from ugens.heard import heard_run, impulse_invariant
from ugens.kernels import FASTMATH
from ugens.modal import HEARD_LEVEL, ModelParams, design
from ugens.noise import seed_spec, uniform

# its cache holds copies of their kernels and constants
drop_stale_cache(__file__, [cells, driving_point, heard, kernels, modal, noise])

#: Normal forces at or below this (N) mean no contact (keeps z_ss representable).
MIN_CONTACT = 1e-9
#: Floor of f_ss relative to f_c (static = 0 would make z_ss vanish at v = 0).
FSS_FLOOR = 1e-3
#: Newton iterations before the bracketed fallback.
NEWTON_ITERATIONS = 8
#: Residual tolerance, relative to the deflection scale (f_s + f_c) / sigma0 + |z|.
RELATIVE_TOLERANCE = 1e-11


class FrictionParams(NamedTuple):
    """Settings of :func:`friction_run`, stored in this order in the float64 array ``par``."""

    fs: float  #: sample rate (Hz)
    sigma0: float  #: bristle stiffness (N/m)
    sigma1: float  #: bristle damping (N s/m)
    sigma2: float  #: viscous friction (N s/m)
    sigma3: float  #: noise coefficient (sqrt(N s/m))
    static: float  #: static friction coefficient
    dynamic: float  #: Coulomb (dynamic) friction coefficient
    stribeck: float  #: Stribeck velocity v_s (m/s)
    breakaway: float  #: break-away deflection as a share of f_c / sigma0
    gain_sum: float  #: G = sum_k g_k: the contact displacement per newton within the sample (m/N)


@nb.njit(inline="always", cache=True)
def friction_params(par):
    """The FrictionParams record held in ``par``."""
    return FrictionParams(par[0], par[1], par[2], par[3], par[4], par[5], par[6], par[7], par[8], par[9])


class FrictionState(NamedTuple):
    """State of :func:`friction_run`, stored in this order in the float64 array ``state``."""

    z: float  #: mean bristle deflection (m)
    x_prev: float  #: contact displacement of the last sample (m)
    v_prev: float  #: relative velocity of the last sample (m/s)


@nb.njit(inline="always", cache=True)
def friction_state(state):
    """The FrictionState record held in ``state``."""
    return FrictionState(state[0], state[1], state[2])


class Sample(NamedTuple):
    """A sample's bristle equation: the deflection z0 at its start and the relative velocity
    v(z) = (A - K z) / D as a function of the deflection z at its end (see the module doc)."""

    z0: float  #: bristle deflection at the start of the sample (m)
    A: float  #: v(0) D (m/s)
    K: float  #: -dv/dz D (1/s)
    D: float  #: 1 + G fs sigma2


class Bristle(NamedTuple):
    """The elasto-plastic bristle's constants for one sample."""

    T: float  #: sample period (s)
    s0: float  #: bristle stiffness sigma0 (N/m)
    f_s: float  #: static friction force (N)
    f_c: float  #: Coulomb friction force (N)
    v_s: float  #: Stribeck velocity (m/s)
    z_ba: float  #: break-away deflection (m)


class Drive(NamedTuple):
    """Per-sample inputs of :func:`friction_run`."""

    speeds: np.ndarray  #: bow (surface) speed (m/s)
    normals: np.ndarray  #: normal force (N)
    strikes: np.ndarray  #: external force on the contact point (N)


@nb.njit(fastmath=FASTMATH, cache=True)
def bristle_residual(z, sample, bristle):
    """R(z) = z - z0 - T g(z, v(z)) and dR/dz, with v(z) = (A - K z) / D and
    g = dz/dt of the elasto-plastic bristle (a Sample and a Bristle)."""
    z0, A, K, D = sample
    T, s0, f_s, f_c, v_s, z_ba = bristle
    v = (A - K * z) / D
    if v == 0.0:
        g = 0.0
        dgdz = 0.0
        dgdv = 1.0
    else:
        a = abs(v)
        sgn = 1.0 if v > 0.0 else -1.0
        x = a / v_s
        e = math.exp(-x * x)
        fss = f_c + (f_s - f_c) * e
        floored = fss < FSS_FLOOR * f_c
        z_ss = (FSS_FLOOR * f_c if floored else fss) / s0
        m = z * sgn  # deflection along the sliding direction (negative: opposite sign)
        if m < z_ss and m < z_ba:
            g = v
            dgdz = 0.0
            dgdv = 1.0
        else:
            if m >= z_ss:
                alpha = 1.0
                da_dm = 0.0
                da_dzss = 0.0
            else:
                width = z_ss - z_ba
                phi = math.pi * (m - 0.5 * (z_ss + z_ba)) / width
                alpha = 0.5 + 0.5 * math.sin(phi)
                c = 0.5 * math.pi * math.cos(phi) / width
                da_dm = c
                da_dzss = c * (z_ba - m) / width
            h = alpha * m / z_ss
            g = v * (1.0 - h)
            dgdz = -a * (da_dm * m + alpha) / z_ss
            dh_dzss = (m / z_ss) * (da_dzss * z_ss - alpha) / z_ss
            dzss_da = 0.0 if floored else -2.0 * a / (v_s * v_s) * (f_s - f_c) * e / s0
            dgdv = (1.0 - h) - a * dh_dzss * dzss_da
    r = z - z0 - T * g
    dr = 1.0 - T * (dgdz - dgdv * K / D)
    return r, dr


@nb.njit(fastmath=FASTMATH, cache=True)
def solve_bristle(sample, bristle):
    """The bristle deflection z[n] solving R(z) = 0 (a Sample and a Bristle; see the module
    docstring)."""
    z0, A, K, D = sample
    T, s0, f_s, f_c, v_s, z_ba = bristle
    tol = RELATIVE_TOLERANCE * ((f_s + f_c) / s0 + abs(z0))
    z = z0
    for _ in range(NEWTON_ITERATIONS):
        r, dr = bristle_residual(z, sample, bristle)
        if abs(r) <= tol:
            return z
        if not dr > 0.0:
            break
        z -= r / dr
    # fallback: grow a bracket from z0 in the direction of the root, then Newton-bisection
    r0, _ = bristle_residual(z0, sample, bristle)
    if r0 == 0.0:
        return z0
    step = T * abs(A) / D + 1e-3 * ((f_s + f_c) / s0 + abs(z0)) + 1e-300
    direction = 1.0 if r0 < 0.0 else -1.0
    near = z0
    far = z0 + direction * step
    for _ in range(2000):
        rf, _ = bristle_residual(far, sample, bristle)
        if rf * direction >= 0.0:
            break
        near = far
        step *= 2.0
        far = z0 + direction * step
    lo = min(near, far)
    hi = max(near, far)
    z = 0.5 * (lo + hi)
    for _ in range(200):
        r, dr = bristle_residual(z, sample, bristle)
        if abs(r) <= tol or hi - lo <= 1e-15 * (abs(lo) + abs(hi)):
            return z
        if r < 0.0:
            lo = z
        else:
            hi = z
        znew = z - r / dr if dr > 0.0 else lo - 1.0
        z = znew if lo < znew < hi else 0.5 * (lo + hi)
    return z


@nb.njit(fastmath=FASTMATH, cache=True)
def friction_run(out, fout, n, drive, modes, h, state, rng, par):
    """n samples of the closed loop. drive: the Drive (its strikes are added to the
    resonator's free motion before the bristle is solved); modes rows: c1, c2, g, y1, y2;
    h: scratch per mode; state holds a FrictionState, par a FrictionParams."""
    speeds, normals, strikes = drive
    prm = friction_params(par)
    fs = prm.fs
    T = 1.0 / fs
    s0 = prm.sigma0
    s1 = prm.sigma1
    s2 = prm.sigma2
    s3 = prm.sigma3
    G = prm.gain_sum
    Gv = G * fs
    held = friction_state(state)
    z = held.z
    x_prev = held.x_prev
    v_prev = held.v_prev
    s = rng[0]
    for i in range(n):
        xh = free_motion(modes, h, strikes[i])
        s, u = uniform(s)
        fn = normals[i]
        vb = speeds[i]
        if fn > MIN_CONTACT:
            # the friction laws' settings are read in the loop: read once before it, fastmath
            # may fold breakaway / s0 and the renders change in their last bits
            laws = friction_params(par)
            f_s = laws.static * fn
            f_c = laws.dynamic * fn
            z_ba = laws.breakaway * f_c / s0
            w = s3 * u * math.sqrt(abs(v_prev) * fn)
            z0 = z
            D = 1.0 + Gv * s2
            K = Gv * (s0 + s1 * fs)
            A = vb - (xh - x_prev) * fs + Gv * (s1 * fs * z0 - w)
            z = solve_bristle(Sample(z0, A, K, D), Bristle(T, s0, f_s, f_c, laws.stribeck, z_ba))
            v = (A - K * z) / D
            f = s0 * z + s1 * fs * (z - z0) + s2 * v + w
        else:
            z = 0.0
            f = 0.0
            v = vb - (xh - x_prev) * fs
        settle(modes, h, f)
        x = xh + G * f
        out[i] = x
        fout[i] = f
        x_prev = x
        v_prev = v
    store(state, FrictionState(z, x_prev, v_prev))
    rng[0] = s


def _coef(default, low, high, unit, doc, low_open=False):
    return ParamSpec("float", default, low=low, high=high, low_open=low_open, unit=unit, doc=doc)


@register
class Friction(ModelParams, UGen):
    """Elasto-plastic bristle friction driving its own modal resonator (bow on a string,
    finger on a glass, a squeaking hinge). Dupont et al., IEEE TAC 2002; Avanzini, Serafin
    & Rocchesso, IEEE TSAP 2005; SDT ``friction~``.

    Input ``strike`` (optional): a force in N on the same point of the same resonator (an
    ImpactForce: a glass struck while it is rubbed); the friction loop feels its motion.
    Output: the resonator's displacement at the model's pickup (m, signed gains), or with
    ``level = "calibrated"`` that times the model's reference gain: the scale of a calibrated
    ModalBank, so a rubbed and a struck resonator sound at the same level as a bank. Extra
    outputs ``contact``: the contact displacement (m, driving-point gains); ``force``: the
    friction force on the resonator (N, positive along +speed).
    """

    type_name = "Friction"
    driving_point = True
    outputs = ("force", "contact")
    inputs = ("strike",)
    optional_inputs = ("strike",)
    param_specs = {
        "model": ParamSpec("model", required=True, fixed=True, doc="the resonator's ModalModel"),
        "location": ParamSpec("location", 0, doc="contact location on the model"),
        "force": ParamSpec(
            "float", 0.0, low=0.0, high=1e4, unit="N", smooth=True, doc="normal force F_N (0: no contact)"
        ),
        "speed": ParamSpec(
            "float", 0.0, low=-100.0, high=100.0, unit="m/s", smooth=True, doc="exciter velocity"
        ),
        "static": _coef(0.8, 0.0, 10.0, "", "static friction coefficient k_s (f_s = k_s F_N)"),
        "dynamic": _coef(
            0.2, 0.0, 10.0, "", "dynamic (Coulomb) coefficient k_d (f_c = k_d F_N)", low_open=True
        ),
        "stribeck": _coef(0.1, 0.0, 100.0, "m/s", "Stribeck velocity v_s", low_open=True),
        "breakaway": _coef(0.1, 0.0, 0.99, "", "break-away deflection k_ba, relative to f_c / sigma0"),
        "sigma0": _coef(1e5, 0.0, 1e9, "N/m", "bristle stiffness", low_open=True),
        "sigma1": _coef(0.02, 0.0, 1e4, "N s/m", "bristle damping"),
        "sigma2": _coef(0.01, 0.0, 1e4, "N s/m", "viscous friction"),
        "noise": _coef(0.0, 0.0, 1e3, "sqrt(N s/m)", "sigma3: roughness noise sigma3 u sqrt(|v| F_N)"),
        "seed": seed_spec("random seed of the noise"),
        "level": HEARD_LEVEL,
    }

    def _prepare(self) -> None:
        self.validate_model()
        self.check_param("location", self.values["location"], f"nodes.{self.name}.location")  # gains >= 0
        self.modes = np.zeros((MODE_ROWS, self.model.n_modes))  # c1, c2, g, y1, y2
        self.scratch = np.zeros(self.model.n_modes)
        self.state = np.zeros(len(FrictionState._fields))
        self.rng = np.zeros(1, dtype=np.uint64)
        self.par = np.zeros(len(FrictionParams._fields))
        self.signed = self.model.driving is not None  # heard through the signed gains
        self.heard_coef = np.zeros((6, self.model.n_modes))
        self.heard_state = np.zeros((2, self.model.n_modes))
        self._drive = np.zeros(self.max_block)  # friction + strike force heard at the pickup
        self._level_gain = self.level_gain()
        self.speed = self.smoothed("speed")
        self.force = self.smoothed("force")
        self._speeds = Control(self.speed, self.max_block)
        self._forces = Control(self.force, self.max_block)
        self._design()
        self._run = specialise(
            friction_run,
            self.out,
            self.out,
            0,
            Drive(self._speeds.buffer, self._forces.buffer, self.input_buffer("strike")),
            self.modes,
            self.scratch,
            self.state,
            self.rng,
            self.par,
        )

    def _design(self) -> None:
        """Mode coefficients and the parameter vector from the current values."""
        v, fs = self.values, self.sample_rate
        gain_sum = driving_point_modes(self.model, v["location"], fs, self.modes)
        if self.signed:
            _, _, s = design(self.model.frequencies, self.model.decays, fs)
            heard = s / fs * self.model.gains_at(v["location"]) * self._level_gain
            self.heard_coef[:] = impulse_invariant(self.modes[0], self.modes[1], heard)
        self.par[:] = FrictionParams(
            fs=fs,
            sigma0=v["sigma0"],
            sigma1=v["sigma1"],
            sigma2=v["sigma2"],
            sigma3=v["noise"],
            static=v["static"],
            dynamic=v["dynamic"],
            stribeck=v["stribeck"],
            breakaway=v["breakaway"],
            gain_sum=gain_sum,
        )

    def _reset(self) -> None:
        self.heard_state[:] = 0.0
        self.modes[3:] = 0.0
        self.state[:] = 0.0
        self.rng[0] = self.values["seed"]
        for ramp in (self.speed, self.force):
            ramp.set(ramp.target, 0, jump=True)

    def _param_changed(self, key: str, value: Any, jump: bool) -> None:
        if key in ("speed", "force"):
            getattr(self, key).set(value, self.ramp_samples(), jump)
        else:
            self._design()

    def process(self, start: int, n: int) -> None:
        self._run(
            self.extra["contact"],
            self.extra["force"],
            n,
            Drive(self._speeds.values(n), self._forces.values(n), self.input_buffer("strike")),
            self.modes,
            self.scratch,
            self.state,
            self.rng,
            self.par,
        )
        if self.signed:
            drive = self.extra["force"]
            if "strike" in self.sources:  # the pickup hears the strike's force too
                drive = self._drive
                np.add(self.extra["force"][:n], self.sources["strike"].out[:n], out=drive[:n])
            heard_run(drive, self.out, n, self.heard_coef, self.heard_state)
        else:
            np.multiply(self.extra["contact"][:n], self._level_gain, out=self.out[:n])

    def state_arrays(self) -> dict[str, np.ndarray]:
        return {
            "modes": self.modes,
            "state": self.state,
            "rng": self.rng,
            "speed": self.speed.ramp,
            "force": self.force.ramp,
            "par": self.par,
            "heard_state": self.heard_state,
        }
