"""DrillSource: the excitation of a surgical burr cutting bone.

Agus et al., "Real-time haptic and visual simulation of bone dissection" (IEEE VR 2002,
pp. 209-216; Presence 12(1):110-122, 2003): the burr spins at ``rpm`` against bone with normal force
``force`` and removes material at ``removal``. Sound model (after the modal-synthesis
contact sources of van den Doel, Kry & Pai, FoleyAutomatic, SIGGRAPH 2001):

* rotation: the contact force ripples at the harmonics of the rotation frequency
  f_r = rpm / 60, the tooth-passing harmonics (multiples of ``flutes``) emphasised:
  force * ripple * sum_k g_k sin(k phi), phi' = 2 pi f_r, g_k ~ k^-1/2 (x ``flute_gain`` at
  k = flutes, 2 flutes, ...), normalised to sum g_k^2 = 1; harmonics at or above 0.45 fs
  are dropped per sample;
* cutting noise: uniform white noise (seeded splitmix64) of peak amplitude
  noise * force + chips * removal (N).

Main output: the excitation force (N) for a ModalBank (the bone's resonances). Extra
output ``motor``: the airborne handpiece whine idle * sum_k g_k sin(k phi) (unitless, not
scaled by force), to mix in directly. Controls ``rpm``, ``force`` and ``removal`` are
smoothed (follow a physics DrillTrack via jassy.events.track_events).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba as nb
import numpy as np

from jassy.jit import drop_stale_cache
from jassy.levels import ForceSpectrum, band_line_power, response_power, tonal_level_factor
from jassy.params import ParamSpec
from jassy.registry import register
from jassy.ugen import UGen
from ugens import noise, tonal_level
from ugens.cells import slot
from ugens.kernels import FASTMATH
from ugens.noise import seed_spec, uniform
from ugens.tonal_level import LEVEL_POINTS, TONAL_LEVEL_SPECS, TonalLevel, log_table

drop_stale_cache(__file__, [noise, tonal_level])  # its cache holds copies of their kernels

MAX_HARMONICS = 64
#: The reference operating point of a calibrated level: a light cut, 1 N of normal force
#: removing 1 mm^3 of bone per second.
REFERENCE_FORCE = 1.0
REFERENCE_REMOVAL = 1.0
#: Top of the rpm range (the ``rpm`` parameter's) that the level table spans.
RPM_HIGH = 200000.0


class DrillConfig(NamedTuple):
    """Settings of :func:`drill_kernel`, stored in this order in the float64 array ``cfg``."""

    fs: float  #: sample rate (Hz)
    ripple: float  #: rotational force ripple (fraction of the normal force)
    noise: float  #: cutting-noise peak per N of normal force
    chips: float  #: cutting-noise peak per mm^3/s of removal (N s/mm^3)
    idle: float  #: amplitude of the motor output
    level_step: float  #: rpm step of the level table after the record; 0: no table


#: The level table (log of the calibrated level's factor at i x level_step rpm, LEVEL_POINTS
#: entries) is stored in ``cfg`` after its DrillConfig.
LEVEL_TABLE = len(DrillConfig._fields)


@nb.njit(inline="always", cache=True)
def drill_config(cfg):
    """The DrillConfig record held in ``cfg``."""
    return DrillConfig(cfg[0], cfg[1], cfg[2], cfg[3], cfg[4], cfg[5])


@nb.njit(fastmath=FASTMATH, cache=True)
def drill_kernel(out, motor, n, rpms, forces, removals, gains, phase, rng, cfg):
    """Rotation harmonics plus cutting noise (module docstring); with a level table, the
    force times the table's factor at each sample's rpm."""
    c = drill_config(cfg)
    fs = c.fs
    s = rng[0]
    ph = phase[0]
    two_pi = 2.0 * math.pi
    nh = gains.size
    for i in range(n):
        f_r = rpms[i] / 60.0
        cs = math.cos(ph)
        s1 = math.sin(ph)
        s0 = 0.0  # sin(0 * ph)
        acc = 0.0
        limit = 0.45 * fs
        for k in range(nh):
            if (k + 1) * f_r >= limit:
                break
            acc += gains[k] * s1
            s2 = 2.0 * cs * s1 - s0  # sin((k + 2) ph) by the Chebyshev recurrence
            s0 = s1
            s1 = s2
        s, u = uniform(s)
        amp = c.noise * forces[i] + c.chips * removals[i]
        if c.level_step > 0.0:
            out[i] = (c.ripple * forces[i] * acc + amp * u) * log_table(
                cfg, LEVEL_TABLE, rpms[i] / c.level_step
            )
        else:
            out[i] = c.ripple * forces[i] * acc + amp * u
        motor[i] = c.idle * acc
        ph += two_pi * f_r / fs
        if ph >= two_pi:
            ph -= two_pi * math.floor(ph / two_pi)
    phase[0] = ph
    rng[0] = s


@register
class DrillSource(TonalLevel, UGen):
    """A spinning burr cutting bone: rotation harmonics plus cutting noise (force, N).

    Agus et al. IEEE VR 2002 / Presence 2003 (burr-bone model); the ``force`` and
    ``removal`` controls come from physics.burr's haptic loop. Given the ``model`` it drives
    (``level`` 'auto' or 'calibrated'), the force (not ``motor``) is scaled by a table over
    the rpm, computed once from the modes, so that at REFERENCE_FORCE and REFERENCE_REMOVAL
    a calibrated ModalBank of that model rings at jassy.levels.TONAL_RMS_DBFS at every rpm:
    each table entry is calibrated on the harmonics' response averaged over the entry's rpm
    step (195 rpm; jassy.levels.band_line_power), so the level follows where the harmonics
    fall among the modes while a harmonic crossing a single mode still rings out
    (ugens/tonal_level.py).
    """

    type_name = "DrillSource"
    outputs = ("motor",)
    param_specs = {
        "rpm": ParamSpec("float", 30000.0, low=0.0, high=200000.0, unit="rev/min", smooth=True,
                         doc="burr rotation speed"),
        "force": ParamSpec("float", 0.0, low=0.0, high=1000.0, unit="N", smooth=True,
                           doc="normal contact force of the burr on the bone"),
        "removal": ParamSpec("float", 0.0, low=0.0, high=1e6, unit="mm^3/s", smooth=True,
                             doc="bone removal rate (volume of full-density bone per second)"),
        "harmonics": ParamSpec("int", 24, low=1, high=MAX_HARMONICS, fixed=True,
                               doc="number of rotation harmonics"),
        "flutes": ParamSpec("int", 6, low=1, high=32, fixed=True, doc="cutting flutes of the burr"),
        "flute_gain": ParamSpec("float", 4.0, low=0.0, high=100.0, fixed=True,
                                doc="emphasis of the tooth-passing harmonics (multiples of flutes)"),
        "ripple": ParamSpec("float", 0.3, low=0.0, high=10.0,
                            doc="rotational force ripple, fraction of the normal force"),
        "noise": ParamSpec("float", 0.2, low=0.0, high=100.0, unit="N/N",
                           doc="cutting-noise peak amplitude per newton of normal force"),
        "chips": ParamSpec("float", 0.05, low=0.0, high=100.0, unit="N s/mm^3",
                           doc="cutting-noise peak amplitude per mm^3/s of removal"),
        "idle": ParamSpec("float", 0.05, low=0.0, high=10.0, doc="amplitude of the motor output"),
        "seed": seed_spec(),
        **TONAL_LEVEL_SPECS,
    }  # fmt: skip

    def force_spectrum(self) -> ForceSpectrum:
        """The force at the reference operating point and the ``rpm`` set: the rotation
        harmonics below 0.45 fs as lines, the uniform cutting noise (variance A^2 / 3) as a
        white density."""
        v, fs = self.values, self.sample_rate
        f = np.arange(1, self.gains.size + 1) * v["rpm"] / 60.0
        audible = (f < 0.45 * fs) & (f > 0.0)
        amplitude = v["noise"] * REFERENCE_FORCE + v["chips"] * REFERENCE_REMOVAL
        return ForceSpectrum(
            f[audible],
            v["ripple"] * REFERENCE_FORCE * self.gains[audible],
            lambda freqs: np.full(freqs.shape, 2.0 * amplitude**2 / (3.0 * fs)),
        )

    def level_table(self) -> tuple[float, np.ndarray]:
        """(rpm step, log of the calibrated level's factor at i x step rpm) over 0..RPM_HIGH:
        per entry, the mean square response at the reference operating point with each
        harmonic averaged over the entry's rpm step and the white cutting noise (the
        harmonics' amplitudes and the ripple at render start). Not calibrated: no table."""
        if not self.is_calibrated():
            return 0.0, np.zeros(LEVEL_POINTS)
        model, fs = self.calibration_model(), self.sample_rate
        step = RPM_HIGH / (LEVEL_POINTS - 1)
        rpm = step * np.arange(LEVEL_POINTS)[:, None]
        harmonic = np.arange(1, self.gains.size + 1)
        edges = np.maximum(step * (np.arange(LEVEL_POINTS + 1)[:, None] - 0.5), 0.0) * harmonic / 60.0
        # the kernel drops a harmonic at or above 0.45 fs; so does the table, at the entry's rpm
        amplitudes = np.where(rpm * harmonic / 60.0 < 0.45 * fs, self.values["ripple"] * self.gains, 0.0)
        lines = band_line_power(model, edges, REFERENCE_FORCE * amplitudes, fs)
        no_lines = self.force_spectrum()._replace(line_frequencies=np.zeros(0), line_amplitudes=np.zeros(0))
        noise = response_power(model, no_lines, fs).mean()
        return step, np.log(tonal_level_factor(model, lines + noise, fs))

    def _prepare(self) -> None:
        self.rpm = self.smoothed("rpm")
        self.force = self.smoothed("force")
        self.removal = self.smoothed("removal")
        self.phase = np.zeros(1)
        self.rng = np.zeros(1, dtype=np.uint64)
        k = np.arange(1, self.values["harmonics"] + 1, dtype=np.float64)
        g = k**-0.5
        g[(k % self.values["flutes"]) == 0] *= self.values["flute_gain"]
        self.gains = g / math.sqrt(float(np.sum(g * g)))
        self._bufs = np.zeros((3, self.max_block))
        step, table = self.level_table()
        self.cfg = np.concatenate([np.zeros(LEVEL_TABLE), table])
        self.cfg[:LEVEL_TABLE] = self._config(step)

    def _config(self, level_step: float) -> DrillConfig:
        v = self.values
        return DrillConfig(self.sample_rate, v["ripple"], v["noise"], v["chips"], v["idle"], level_step)

    def _reset(self) -> None:
        for sm in (self.rpm, self.force, self.removal):
            sm.set(sm.target, 0, jump=True)
        self.phase[0] = 0.0
        self.rng[0] = self.values["seed"]

    def _param_changed(self, key, value, jump) -> None:
        if key in ("rpm", "force", "removal"):
            getattr(self, key).set(value, self.ramp_samples(), jump)
        elif key in ("ripple", "noise", "chips", "idle"):
            self.cfg[:LEVEL_TABLE] = self._config(self.cfg[slot(DrillConfig, "level_step")])

    def process(self, start: int, n: int) -> None:
        rpms = self.rpm.fill(self._bufs[0], n)
        forces = self.force.fill(self._bufs[1], n)
        removals = self.removal.fill(self._bufs[2], n)
        drill_kernel(
            self.out,
            self.extra["motor"],
            n,
            rpms,
            forces,
            removals,
            self.gains,
            self.phase,
            self.rng,
            self.cfg,
        )

    def state_arrays(self):
        return {
            "phase": self.phase,
            "rng": self.rng,
            "rpm": self.rpm.ramp,
            "force": self.force.ramp,
            "removal": self.removal.ramp,
        }
