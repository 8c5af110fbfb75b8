"""Aerodynamic noise: Wind, KarmanWhistle (Aeolian tones) and CavityTone (a blown bottle).

All three are seeded white noise (splitmix64, see :mod:`ugens.noise`) shaped by a flow
whose speed v (m/s) sets both the spectrum and the level.

Colour. Turbulence sheds eddies at the Strouhal frequency f = St v / L of an obstacle of
size L (St ~ 0.2 for a cylinder over 300 < Re < 2e5; Blevins, *Flow-Induced Vibration*,
1990, ch. 3). The noise goes through an RBJ band-pass (0 dB peak) centred on f with
quality ``q``: broad for wind in foliage and around ears (``Wind``, L = eddy size), narrow
for the vortex street behind a wire (``KarmanWhistle``, L = diameter: the Aeolian tone).
The band-pass is redesigned on every sample whose f differs from the last, so speed ramps
glide; f is held within [1 Hz, 0.45 fs].

Level. A compact body in a flow radiates as a dipole whose acoustic power grows as
v^6 (Curle 1955), so the RMS output is ``level`` * (v / 10 m/s)^3: the noise is scaled by
sqrt(3 / b0) (b0 = the band-pass's first coefficient, which equals the sum of squares of
its impulse response) so that the band-pass output has exactly that RMS whatever f and q.
The RMS is set after a band of fixed width in Hz, so the spectral density does not depend
on the sample rate (no sqrt(fs) factor; band levels at 48 and 96 kHz agree within 0.4 dB).

Gusts. The speed is v (1 + gustiness g(t)) (floored at 0), g an Ornstein-Uhlenbeck
process of unit variance and correlation time ``gust_time`` (white noise through a
one-pole low-pass), the usual first-order model of wind turbulence.

Cavity. ``CavityTone``: the jet across a bottle mouth (edge-tone noise at St v / w, w the
mouth width) drives a Helmholtz resonator of volume V with a neck of length L and radius
a, which rings at

    f_H = c / (2 pi) sqrt(S / (V L')),  S = pi a^2,  L' = L + 1.43 a

(end corrections 0.61 a unflanged outside and 0.82 a flanged inside; Kinsler et al.,
*Fundamentals of Acoustics*, 4th ed., 10.8; Levine & Schwinger 1948). The resonator is a
band-pass of quality ``q`` at f_H; the tone is loudest when the jet's frequency meets f_H.
SDT's counterparts: ``windflow~``, ``windkarman~``, ``windcavity~`` (Baldan et al. 2017).
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
from ugens import filters, noise
from ugens.cells import slot
from ugens.filters import biquad_coefficients, biquad_step, design_biquad
from ugens.kernels import FASTMATH
from ugens.noise import seed_spec, uniform

drop_stale_cache(__file__, [filters, noise])  # its cache holds copies of their kernels

#: Reference speed of the ``level`` parameter (m/s).
REFERENCE_SPEED = 10.0
#: Helmholtz neck end corrections, in neck radii: unflanged outer end + flanged inner end.
END_CORRECTION = 0.6133 + 0.8216
_BANDPASS = 2


class WindParams(NamedTuple):
    """Settings of :func:`flow_noise`, stored in this order in the float64 array ``par`` (the
    kernel reads them through the slots below, cells.slot)."""

    fs: float  #: sample rate (Hz)
    strouhal: float  #: Strouhal number St: the band-pass centre is St v / size
    q: float  #: the band-pass's Q
    level: float  #: output level at REFERENCE_SPEED
    gust: float  #: gustiness: relative speed fluctuation
    gust_pole: float  #: pole of the gusts' one-pole low-pass
    gust_norm: float  #: scale that gives the low-passed gust noise unit variance
    resonator: float  #: 1.0 when the noise also drives the Helmholtz resonator's band-pass
    res_gain: float  #: the resonator's gain, 1 / sqrt(b0 of its band-pass)


class WindState(NamedTuple):
    """State of :func:`flow_noise`, stored in this order in the float64 array ``st``."""

    s1: float  #: band-pass DF2T state
    s2: float
    last_f: float  #: the band-pass's last centre frequency (Hz; < 0: redesign)
    g: float  #: the gust's low-passed noise
    r1: float  #: resonator DF2T state
    r2: float


_FS, _ST, _Q, _LEVEL, _GUST, _GUST_POLE, _GUST_NORM, _RESONATOR, _RES_GAIN = (
    slot(WindParams, key) for key in WindParams._fields
)
_S1, _S2, _LAST_F, _G, _R1, _R2 = (slot(WindState, key) for key in WindState._fields)


@nb.njit(fastmath=FASTMATH, cache=True)
def flow_noise(out, n, rng, speeds, sizes, par, coef, res_coef, st):
    """n samples of flow noise: speed v = speeds[i] (1 + gust), band-pass at St v / sizes[i].

    With par[_RESONATOR] != 0 the result also goes through the band-pass res_coef,
    scaled by sqrt(b0 / b0_res) (unit gain for noise centred on the resonance)."""
    fs = par[_FS]
    inv_fs = 1.0 / fs
    st_number = par[_ST]
    q = par[_Q]
    level = par[_LEVEL] / REFERENCE_SPEED**3
    gust = par[_GUST]
    gust_pole = par[_GUST_POLE]
    gust_norm = par[_GUST_NORM]
    resonate = par[_RESONATOR] != 0.0
    res_gain = par[_RES_GAIN]
    f_max = 0.45 * fs
    s = rng[0]
    s1 = st[_S1]
    s2 = st[_S2]
    last_f = st[_LAST_F]
    g = st[_G]
    r1 = st[_R1]
    r2 = st[_R2]
    for i in range(n):
        v = speeds[i]
        if gust > 0.0:
            s, u = uniform(s)
            g = gust_pole * g + (1.0 - gust_pole) * gust_norm * u
            v *= max(0.0, 1.0 + gust * g)
        f = min(max(st_number * v / sizes[i], 1.0), f_max)
        if f != last_f:
            design_biquad(_BANDPASS, f, q, inv_fs, coef)
            last_f = f
        s, u = uniform(s)
        x = level * v * v * v * math.sqrt(3.0 / coef[0]) * u
        y, s1, s2 = biquad_step(biquad_coefficients(coef), x, s1, s2)
        if resonate:
            x = y * res_gain * math.sqrt(coef[0])
            y, r1, r2 = biquad_step(biquad_coefficients(res_coef), x, r1, r2)
        out[i] = y
    rng[0] = s
    st[_S1] = s1
    st[_S2] = s2
    st[_LAST_F] = last_f
    st[_G] = g
    st[_R1] = r1
    st[_R2] = r2


def _speed_spec(default: float) -> ParamSpec:
    return ParamSpec("float", default, low=0.0, high=340.0, unit="m/s", smooth=True, doc="flow speed")


_LEVEL_SPEC = ParamSpec(
    "float", 0.1, low=0.0, high=100.0, doc="RMS output at 10 m/s (grows as speed^3: dipole power ~ v^6)"
)
_GUSTINESS_SPEC = ParamSpec(
    "float", 0.0, low=0.0, high=2.0, doc="relative RMS speed fluctuation of the gusts (0: steady flow)"
)
_GUST_TIME_SPEC = ParamSpec(
    "float", 1.5, low=0.01, high=100.0, unit="s", fixed=True, doc="correlation time of the gusts"
)


class _Flow(UGen):
    """Shared state and kernel call of the flow-noise ugens; ``size_key`` names the
    parameter holding the obstacle size L of the Strouhal frequency St v / L."""

    size_key = ""

    def _prepare(self) -> None:
        fs = self.sample_rate
        self.speed = self.smoothed("speed")
        self.size = self.smoothed(self.size_key)
        self._speeds = Control(self.speed, self.max_block)
        self._sizes = Control(self.size, self.max_block)
        self.rng = np.zeros(1, dtype=np.uint64)
        self.st = np.zeros(len(WindState._fields))
        self.coef = np.zeros(5)
        self.res_coef = np.zeros(5)
        pole = math.exp(-1.0 / (self.values["gust_time"] * fs))
        self.par = np.zeros(len(WindParams._fields))
        self.par[_FS] = fs
        self.par[_GUST_POLE] = pole
        # one-pole output variance from uniform draws (variance 1/3): (1 - p) / (1 + p) / 3
        self.par[_GUST_NORM] = math.sqrt(3.0 * (1.0 + pole) / (1.0 - pole))
        self._update()
        self._run = specialise(
            flow_noise,
            self.out,
            0,
            self.rng,
            self._speeds.buffer,
            self._sizes.buffer,
            self.par,
            self.coef,
            self.res_coef,
            self.st,
        )

    def _update(self) -> None:
        """Copy the plain (unsmoothed) parameters into the kernel's vector."""
        v = self.values
        self.par[_ST] = v["strouhal"]
        self.par[_Q] = v["q"]
        self.par[_LEVEL] = v["level"]
        self.par[_GUST] = v["gustiness"]
        self.st[_LAST_F] = -1.0  # redesign the band-pass on the next sample

    def _reset(self) -> None:
        self.rng[0] = self.values["seed"]
        self.st[:] = 0.0
        self.st[_LAST_F] = -1.0
        for ramp in (self.speed, self.size):
            ramp.set(ramp.target, 0, jump=True)

    def _param_changed(self, key: str, value: Any, jump: bool) -> None:
        if key == "speed":
            self.speed.set(value, self.ramp_samples(), jump)
        elif key == self.size_key:
            self.size.set(value, self.ramp_samples(), jump)
        else:
            self._update()

    def process(self, start: int, n: int) -> None:
        self._run(
            self.out,
            n,
            self.rng,
            self._speeds.values(n),
            self._sizes.values(n),
            self.par,
            self.coef,
            self.res_coef,
            self.st,
        )

    def state_arrays(self) -> dict[str, np.ndarray]:
        return {
            "rng": self.rng,
            "st": self.st,
            "coef": self.coef,
            "speed": self.speed.ramp,
            "size": self.size.ramp,
        }


@register
class Wind(_Flow):
    """Turbulent wind noise: level ~ v^3, colour centred on St v / eddy size, gusts.

    Model in the module docstring (Curle dipole level, Strouhal colour, Ornstein-Uhlenbeck
    gusts). SDT ``windflow~``."""

    type_name = "Wind"
    size_key = "eddy_size"
    param_specs = {
        "speed": _speed_spec(8.0),
        "eddy_size": ParamSpec(
            "float",
            0.005,
            low=1e-5,
            high=100.0,
            unit="m",
            smooth=True,
            doc="size of the obstacles shedding the eddies (colour: St v / size)",
        ),
        "strouhal": ParamSpec("float", 0.2, low=0.01, high=10.0, doc="Strouhal number St"),
        "q": ParamSpec("float", 0.5, low=0.1, high=100.0, doc="band-pass quality (breadth of the rush)"),
        "level": _LEVEL_SPEC,
        "gustiness": ParamSpec(
            "float", 0.3, low=0.0, high=2.0, doc="relative RMS speed fluctuation of the gusts"
        ),
        "gust_time": _GUST_TIME_SPEC,
        "seed": seed_spec(),
    }


def aeolian_pressure(speed, diameter, span, distance, strouhal=0.2, lift=0.5, correlation=3.0,
                     density=1.204, c=343.2):  # fmt: skip
    """RMS sound pressure (Pa) of a wire's Aeolian tone at ``distance`` m, on the axis of the
    lift (across the flow and the wire): Curle's compact dipole p = dF/dt / (4 pi c r) of the
    fluctuating lift, rms ``lift`` 1/2 rho v^2 d per unit length, at omega = 2 pi St v / d,
    correlated over ``correlation`` diameters and adding incoherently along the ``span``
    (Phillips 1956): p_rms = St rho v^3 C_L' sqrt(L l) / (4 c r), l = min(correlation d, L)."""
    length = min(correlation * diameter, span)
    return strouhal * density * speed**3 * lift * math.sqrt(span * length) / (4.0 * c * distance)


@register
class KarmanWhistle(_Flow):
    """Aeolian tone of a wire or edge in a flow: narrow noise band at f = St v / d.

    The Karman vortex street sheds at f = St v / d (St ~ 0.2); level ~ v^3. Model in the
    module docstring. SDT ``windkarman~``. With a ``span`` > 0 the level is physical: the
    output is the sound pressure in Pa at ``distance`` m on the lift's axis (Curle's dipole
    of the fluctuating lift, Phillips 1956: :func:`aeolian_pressure`, with ``lift`` the rms
    lift coefficient, about 0.5 for a cylinder at 1e3 < Re < 1e5, and ``correlation`` the
    spanwise correlation length in diameters, about 3; Blevins, *Flow-Induced Vibration*,
    1990, ch. 3), instead of ``level``; a diameter ramp uses its target's level."""

    type_name = "KarmanWhistle"
    size_key = "diameter"
    param_specs = {
        "speed": _speed_spec(10.0),
        "diameter": ParamSpec(
            "float", 0.003, low=1e-5, high=10.0, unit="m", smooth=True, doc="wire or edge diameter d"
        ),
        "strouhal": ParamSpec("float", 0.2, low=0.01, high=10.0, doc="Strouhal number St"),
        "q": ParamSpec("float", 30.0, low=0.5, high=1000.0, doc="band-pass quality (purity of the tone)"),
        "level": _LEVEL_SPEC,
        "gustiness": _GUSTINESS_SPEC,
        "gust_time": _GUST_TIME_SPEC,
        "seed": seed_spec(),
        "span": ParamSpec(
            "float", 0.0, low=0.0, high=1e4, unit="m",
            doc="length of wire in the flow; > 0: output in Pa at `distance` (Curle dipole), `level` unused",
        ),
        "distance": ParamSpec(
            "float", 1.0, low=1e-3, high=1e5, unit="m", doc="listening distance of the physical level"
        ),
        "lift": ParamSpec(
            "float", 0.5, low=0.0, high=5.0, doc="rms lift coefficient C_L' of the physical level"
        ),
        "correlation": ParamSpec(
            "float", 3.0, low=0.1, high=1e3, doc="spanwise correlation length in diameters (physical level)"
        ),
    }  # fmt: skip

    def _update(self) -> None:
        super()._update()
        v = self.values
        if v["span"] > 0.0:  # the Pa RMS at the reference speed, as the kernel's level
            self.par[_LEVEL] = aeolian_pressure(
                REFERENCE_SPEED, v["diameter"], v["span"], v["distance"], v["strouhal"], v["lift"],
                v["correlation"],
            )  # fmt: skip

    def _param_changed(self, key: str, value: Any, jump: bool) -> None:
        super()._param_changed(key, value, jump)
        if key == "diameter" and self.values["span"] > 0.0:
            self._update()  # the physical level depends on the diameter


def helmholtz_frequency(volume: float, neck_length: float, neck_radius: float, c: float) -> float:
    """Helmholtz resonance (Hz) of a cavity of ``volume`` m^3 with a neck of length and
    radius in m: c / (2 pi) sqrt(S / (V L')), L' = L + END_CORRECTION a."""
    area = math.pi * neck_radius**2
    return c / (2.0 * math.pi) * math.sqrt(area / (volume * (neck_length + END_CORRECTION * neck_radius)))


@register
class CavityTone(_Flow):
    """Blowing across a bottle mouth: jet noise at St v / mouth exciting the Helmholtz
    resonance f_H = c / (2 pi) sqrt(S / (V L')) of the cavity.

    Model in the module docstring. SDT ``windcavity~`` (which uses a tube)."""

    type_name = "CavityTone"
    size_key = "mouth"
    param_specs = {
        "speed": _speed_spec(6.0),
        "mouth": ParamSpec(
            "float",
            0.02,
            low=1e-4,
            high=10.0,
            unit="m",
            smooth=True,
            doc="width w of the mouth the jet crosses (jet noise centred on St v / w)",
        ),
        "volume": ParamSpec(
            "float", 7.5e-4, low=1e-8, high=10.0, unit="m^3", doc="cavity volume V (air above the liquid)"
        ),
        "neck_length": ParamSpec("float", 0.08, low=0.0, high=10.0, unit="m", doc="neck length L"),
        "neck_radius": ParamSpec("float", 0.0095, low=1e-4, high=1.0, unit="m", doc="neck radius a"),
        "c": ParamSpec("float", 343.0, low=100.0, high=2000.0, unit="m/s", doc="speed of sound"),
        "resonance_q": ParamSpec(
            "float", 60.0, low=1.0, high=2000.0, doc="quality of the cavity resonance (losses)"
        ),
        "strouhal": ParamSpec("float", 0.2, low=0.01, high=10.0, doc="Strouhal number St of the jet"),
        "q": ParamSpec("float", 1.0, low=0.1, high=100.0, doc="band-pass quality of the jet noise"),
        "level": _LEVEL_SPEC,
        "gustiness": _GUSTINESS_SPEC,
        "gust_time": _GUST_TIME_SPEC,
        "seed": seed_spec(),
    }

    def resonance(self) -> float:
        """The cavity's Helmholtz frequency (Hz) from the current geometry."""
        v = self.values
        return helmholtz_frequency(v["volume"], v["neck_length"], v["neck_radius"], v["c"])

    def _update(self) -> None:
        super()._update()
        fs = self.sample_rate
        f = min(self.resonance(), 0.45 * fs)
        design_biquad(_BANDPASS, f, self.values["resonance_q"], 1.0 / fs, self.res_coef)
        self.par[_RESONATOR] = 1.0
        self.par[_RES_GAIN] = 1.0 / math.sqrt(self.res_coef[0])

    def state_arrays(self) -> dict[str, np.ndarray]:
        return {**super().state_arrays(), "res_coef": self.res_coef}
