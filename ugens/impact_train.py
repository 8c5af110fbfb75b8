"""ImpactTrain: hard contacts as bursts of micro-collisions, and bouncing objects as pulse trains.

FoleyAutomatic (van den Doel, Kry & Pai, SIGGRAPH 2001) observes that in hard impacts "the
micro-collisions take place within 15 ms", and that very hard contacts involve multiple
bounces rendered as pulse trains. Every collision here is a 1 - cos pulse with an exact
impulse (as :class:`ugens.impact.ImpactForce`): the output is a force in N.

``impact`` splits an impulse J over ``micro`` micro-collisions (seeded splitmix64 draws,
so renders are reproducible and block-size independent). Distribution, with u, w' i.i.d.
uniform on [0, 1) and s = ``spread``:

* onsets: t_0 = 0 (the event time), t_j = s u_j for j >= 1;
* weights: w_j = (1 + w_j') / 2 * exp(-2 t_j / s), normalised to sum 1, so later
  micro-collisions are weaker on average (each one loses energy) and the total is exactly J.

``bounce`` is a ball dropped on a rigid floor (rigid-body bounce law, contact time << flight
time): with v_0 the first impact speed and e the coefficient of restitution, bounce i has
impact speed v_i = e^i v_0 and impulse m (1 + e) v_i, and the flight after it lasts
2 e v_i / g (rebound speed e v_i up and down), so t_{i+1} = t_i + 2 e v_i / g; bounces stop
when v_i < ``min_speed`` or t_i - t_0 > ``until``. (The flight time 2 v / g uses the
rebound speed v = e v_i; the train ends at t_0 + 2 e v_0 / (g (1 - e)).) A ``location``
given with the event applies to the whole train (the scheduler forwards it once).

Contact duration: ``hardness`` (s), or Hertz theory when ``radius``, ``youngs`` and a mass
(``mass`` or ``density``) are given: a sphere of radius R and mass m hitting a half-space at
speed v stays in contact for

    tau = 2.87 (m^2 / (R E*^2 v))^(1/5),   1/E* = (1 - nu_1^2)/E_1 + (1 - nu_2^2)/E_2

(Hertz 1882; K. L. Johnson, "Contact Mechanics", CUP 1985, sec. 11.4). The constant is
2 (15/16)^(2/5) int_0^1 (1 - s^(5/2))^(-1/2) ds = 2.868, from integrating
m x'' = -(4/3) E* sqrt(R) x^(3/2). Harder and faster impacts are shorter: tau ~ v^(-1/5).
"""

from __future__ import annotations

import math
from typing import Any

import numba as nb
import numpy as np

from jassy.errors import PatchError
from jassy.jit import drop_stale_cache
from jassy.params import ParamSpec
from jassy.registry import register
from ugens import noise
from ugens.impact import PulseSource
from ugens.noise import seed_spec, uniform

drop_stale_cache(__file__, [noise])  # its cache holds copies of their kernels

#: 2 (15/16)^(2/5) int_0^1 (1 - s^(5/2))^(-1/2) ds (Johnson 1985, eq. 11.24 for a sphere).
HERTZ_CONSTANT = 2.868
#: Durations at or above this are soft enough for one pulse when ``micro`` is automatic.
_SOFT = 1e-3
_MAX_AUTO_MICRO = 8


def effective_modulus(youngs: float, poisson: float, youngs2: float | None, poisson2: float) -> float:
    """E* (Pa) of two bodies in contact: 1/E* = (1 - nu1^2)/E1 + (1 - nu2^2)/E2.

    ``youngs2`` None means a second body of the same material as the first.
    """
    if youngs2 is None:
        youngs2, poisson2 = youngs, poisson
    return 1.0 / ((1.0 - poisson**2) / youngs + (1.0 - poisson2**2) / youngs2)


def hertz_duration(speed: float, radius: float, mass: float, e_star: float) -> float:
    """Hertz contact time (s) of a sphere (radius m, mass kg) hitting a half-space at speed m/s."""
    return HERTZ_CONSTANT * (mass**2 / (radius * e_star**2 * speed)) ** 0.2


def auto_micro(duration: float) -> int:
    """Micro-collisions per impact when ``micro`` = 0: one per halving of tau below 1 ms.

    1 + round(log2(1 ms / tau)), clamped to [1, 8]: a design rule (harder contacts rattle
    more), not a measured law.
    """
    if duration >= _SOFT:
        return 1
    return int(min(_MAX_AUTO_MICRO, 1 + round(math.log2(_SOFT / duration))))


@nb.njit(cache=True)
def micro_schedule(rng, n, spread, times, weights):
    """Draw n micro-collision onsets (s after the event) and weights summing to 1.

    t_0 = 0, t_j = spread u_j; w_j = (1 + u'_j) / 2 exp(-2 t_j / spread) (u, u' uniform on
    [0, 1)); sorted by time. rng: uint64 splitmix64 state, advanced by 2n - 1 draws.
    """
    s = rng[0]
    total = 0.0
    for j in range(n):
        t = 0.0
        if j > 0:
            s, u = uniform(s)
            t = 0.5 * (u + 1.0) * spread
        s, u = uniform(s)
        w = 0.25 * (u + 3.0) * math.exp(-2.0 * t / spread)
        times[j] = t
        weights[j] = w
        total += w
    rng[0] = s
    for j in range(n):
        weights[j] /= total
    # insertion sort by time (n is small); t_0 = 0 stays first
    for j in range(1, n):
        t = times[j]
        w = weights[j]
        i = j - 1
        while i >= 0 and times[i] > t:
            times[i + 1] = times[i]
            weights[i + 1] = weights[i]
            i -= 1
        times[i + 1] = t
        weights[i + 1] = w


def bounce_schedule(
    speed: float, restitution: float, gravity: float, min_speed: float, until: float
) -> tuple[np.ndarray, np.ndarray]:
    """(times after the first impact in s, impact speeds in m/s) of a bouncing ball.

    v_i = e^i v_0, t_0 = 0, t_{i+1} = t_i + 2 e v_i / g; while v_i >= min_speed and t_i <= until.
    """
    times, speeds = [], []
    t, v = 0.0, speed
    while v >= min_speed and t <= until and len(times) < 100_000:
        times.append(t)
        speeds.append(v)
        t += 2.0 * restitution * v / gravity
        v *= restitution
    return np.asarray(times), np.asarray(speeds)


def _opt(low: float, high: float, unit: str, doc: str, low_open: bool = True) -> ParamSpec:
    return ParamSpec("float", None, low=low, low_open=low_open, high=high, unit=unit, doc=doc)


@register
class ImpactTrain(PulseSource):
    """Impacts as bursts of micro-collisions and bouncing trains: 1 - cos force pulses (N).

    FoleyAutomatic (van den Doel, Kry & Pai 2001) micro-collisions within ~15 ms; bounce law
    t_{i+1} = t_i + 2 e v_i / g, impulse m (1 + e) v_i; Hertz contact durations (Johnson 1985).
    """

    type_name = "ImpactTrain"
    param_specs = {
        "hardness": ParamSpec(
            "float",
            0.001,
            low=0.0,
            low_open=True,
            high=1.0,
            unit="s",
            doc="contact duration tau of one collision when the Hertz parameters are not all given",
        ),
        "micro": ParamSpec(
            "int",
            0,
            low=0,
            high=64,
            doc="micro-collisions per impact; 0 = automatic: 1 + round(log2(1 ms / tau)), at most 8",
        ),
        "spread": ParamSpec(
            "float",
            0.008,
            low=0.0,
            low_open=True,
            high=0.05,
            unit="s",
            doc="window of the micro-collisions after the impact time (FoleyAutomatic: within 15 ms)",
        ),
        "radius": _opt(0.0, 10.0, "m", "radius of the striking sphere (Hertz durations)"),
        "youngs": _opt(0.0, 1e13, "Pa", "Young's modulus of the striking sphere (Hertz durations)"),
        "poisson": ParamSpec("float", 0.3, low=0.0, high=0.5, doc="Poisson ratio of the striking sphere"),
        "surface_youngs": _opt(
            0.0, 1e13, "Pa", "Young's modulus of the struck surface (default: same as the sphere)"
        ),
        "surface_poisson": ParamSpec(
            "float", 0.3, low=0.0, high=0.5, doc="Poisson ratio of the struck surface"
        ),
        "density": _opt(0.0, 1e5, "kg/m^3", "density of the sphere (mass = 4/3 pi R^3 rho if no mass)"),
        "mass": _opt(0.0, 1e6, "kg", "mass of the striking object (Hertz durations, bounce impulses)"),
        "gravity": ParamSpec(
            "float", 9.81, low=0.0, low_open=True, high=1e3, unit="m/s^2", doc="gravity for bounces"
        ),
        "seed": seed_spec(),
    }
    actions = {
        "impact": {
            "impulse": ParamSpec("float", 1e-3, low=0.0, high=1e6, unit="N s", doc="total normal impulse J"),
            "speed": _opt(0.0, 1e4, "m/s", "impact speed (Hertz duration; default J / (2 m))"),
            "micro": ParamSpec("int", None, low=1, high=64, doc="micro-collisions (default: the param)"),
            "spread": _opt(0.0, 0.05, "s", "window of the micro-collisions (default: the param)"),
            "duration": _opt(0.0, 1.0, "s", "contact duration of each collision (overrides Hertz)"),
            "location": ParamSpec("location", None, doc="contact location on the struck model(s)"),
        },
        "bounce": {
            "speed": ParamSpec(
                "float",
                None,
                low=0.0,
                low_open=True,
                high=1e4,
                unit="m/s",
                required=True,
                doc="impact speed of the first bounce (sqrt(2 g h) for a drop from height h)",
            ),
            "restitution": ParamSpec(
                "float", 0.8, low=0.0, low_open=True, high=0.999, doc="coefficient of restitution e"
            ),
            "mass": _opt(0.0, 1e6, "kg", "mass of the ball (default: the mass param or from density)"),
            "until": ParamSpec(
                "float", 60.0, low=0.0, high=3600.0, unit="s", doc="no bounce later than this after the first"
            ),
            "min_speed": ParamSpec(
                "float",
                0.02,
                low=0.0,
                low_open=True,
                high=1e4,
                unit="m/s",
                doc="bounces stop when the impact speed falls below this",
            ),
            "micro": ParamSpec("int", 1, low=1, high=64, doc="micro-collisions per bounce"),
            "location": ParamSpec("location", None, doc="contact location on the struck model(s)"),
        },
    }

    # ----------------------------------------------------------------- physics
    def hertz_ready(self) -> bool:
        """True when radius, youngs and a mass (or density) are all set."""
        v = self.values
        return v["radius"] is not None and v["youngs"] is not None and self.ball_mass() is not None

    def ball_mass(self) -> float | None:
        """The mass param, else 4/3 pi R^3 rho, else None."""
        v = self.values
        if v["mass"] is not None:
            return v["mass"]
        if v["density"] is not None and v["radius"] is not None:
            return 4.0 / 3.0 * math.pi * v["radius"] ** 3 * v["density"]
        return None

    def contact_duration(self, speed: float | None) -> float:
        """tau (s): Hertz at ``speed`` if its parameters are set and speed is known, else hardness."""
        v = self.values
        if speed is None or speed <= 0 or not self.hertz_ready():
            return v["hardness"]
        e_star = effective_modulus(v["youngs"], v["poisson"], v["surface_youngs"], v["surface_poisson"])
        return hertz_duration(speed, v["radius"], self.ball_mass(), e_star)

    # --------------------------------------------------------------- lifecycle
    def _prepare(self) -> None:
        super()._prepare()
        self.rng = np.zeros(1, dtype=np.uint64)
        self._times = np.zeros(64)
        self._weights = np.zeros(64)

    def _reset(self) -> None:
        super()._reset()
        self.rng[0] = self.values["seed"]

    def _burst(self, sample_time: float, impulse: float, n: int, spread: float, tau: float):
        """Onsets (fractional samples), durations and impulses of one impact's micro-collisions."""
        if n == 1:
            return np.array([sample_time]), np.array([tau]), np.array([impulse])
        times, weights = self._times[:n], self._weights[:n]
        micro_schedule(self.rng, n, spread, times, weights)
        return sample_time + times * self.sample_rate, np.full(n, tau), impulse * weights

    def act(self, action: str, args: dict[str, Any], sample_time: float) -> None:
        """``impact``: a burst of micro-collisions; ``bounce``: a bouncing train (see module doc)."""
        if action == "impact":
            self._impact(args, sample_time)
        elif action == "bounce":
            self._bounce(args, sample_time)
        else:
            super().act(action, args, sample_time)

    def _impact(self, args: dict[str, Any], sample_time: float) -> None:
        impulse = args["impulse"]
        speed = args.get("speed")
        mass = self.ball_mass()
        if speed is None and mass is not None:
            speed = impulse / (2.0 * mass)  # elastic estimate: J = m (1 + e) v with e = 1
        tau = args.get("duration") or self.contact_duration(speed)
        n = args.get("micro") or self.values["micro"] or auto_micro(tau)
        spread = args.get("spread") or self.values["spread"]
        self.add_pulses(*self._burst(sample_time, impulse, n, spread, tau))

    def _bounce(self, args: dict[str, Any], sample_time: float) -> None:
        mass = args.get("mass") or self.ball_mass()
        if mass is None:
            raise PatchError(
                f"{self.name}.bounce.mass: give a mass (kg) in the event or the node's mass/density"
            )
        e = args["restitution"]
        times, speeds = bounce_schedule(
            args["speed"], e, self.values["gravity"], args["min_speed"], args["until"]
        )
        n = args["micro"]
        spread = self.values["spread"]
        parts = [
            self._burst(
                sample_time + t * self.sample_rate, mass * (1.0 + e) * v, n, spread, self.contact_duration(v)
            )
            for t, v in zip(times, speeds, strict=True)
        ]
        if parts:
            self.add_pulses(*(np.concatenate(p) for p in zip(*parts, strict=True)))

    def state_arrays(self) -> dict[str, np.ndarray]:
        return {**super().state_arrays(), "rng": self.rng}
