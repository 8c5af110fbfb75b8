"""Engine: firing pulses of a combustion engine through an exhaust-pipe waveguide.

Firing. A phase accumulator counts firings: it advances by f_fire / fs per sample with

    f_fire = rpm / 60 * cylinders / 2   (four strokes: each cylinder fires every 2 turns)
    f_fire = rpm / 60 * cylinders       (two strokes),

rpm smoothed per sample, so rpm ramps bend the pitch without any phase jump. Each
wrap of the phase is a firing at its exact fractional sample time. Per firing, three
draws of the seeded splitmix64 stream (always three, so the stream does not depend on
the settings) give: a timing jitter (a delay of up to ``irregularity`` * JITTER of the
firing interval), an amplitude factor 1 + ``irregularity`` * AMPLITUDE_JITTER * U[-1, 1),
and a misfire (amplitude 0) with probability ``misfire`` (JASS EngineApplet
"Beatupness"). The amplitude is proportional to ``throttle``.

Pulse. Each firing releases an exhaust-gas pressure pulse p(t) = A (t/tau) e^{1 - t/tau}
(peak A at t = tau = ``pulse`` s: a fast rise as the exhaust valve opens, then a decaying
blow-down), evaluated at its sub-sample onset. The sum of all pulses is computed by an
exact two-state recursion (S1 = sum A r^(n - t_k), S2 = sum A (n - t_k) r^(n - t_k),
r = e^{-1/(tau fs)}), so overlapping pulses cost nothing extra.

Exhaust (a digital waveguide, the design of SDT ``motor~``, Baldan et al., SIVE 2015, cut
down to one pipe). The pulse train enters the forward pressure wave at the port end of a
pipe of length L = ``exhaust_length``; waves travel L / c one way (fractional delay,
linear interpolation). At the open end the reflection is R(z) = -(1 - p) / (1 - p z^-1)
(an inverting one-pole low-pass: |R| ~ 1 - (ka)^2 / 2 for an unflanged pipe of radius a,
Levine & Schwinger, so the cut-off is c / (2 pi a)); at the port end the backward wave
reflects with ``port_reflection`` (< 1: the loop is stable). The pipe resonates near
(2m - 1) c / (4 L). The radiated sound is the wave transmitted at the open end,
(1 + R) p+ = p (1 - z^-1) / (1 - p z^-1) p+: a high-pass with a zero at DC, which
removes the mean exhaust pressure.

Band limiting. A pulse starts with a corner (value 0, slope A e / tau), which sampled as is
folds energy above Nyquist back into the top octave. The waveguide is fed the pulse train
with a band-limited ramp correction (BLAMP; Esqueda, Valimaki & Bilbao, "Rounding corners
with BLAMP", DAFx 2016) at each onset: the residual of a unit ramp filtered by a
Kaiser-windowed sinc (cut-off BLAMP_CUTOFF of the rate, BLAMP_HALF samples either side),
tabulated over sub-sample positions, times the slope jump. The correction reaches
BLAMP_HALF samples before the onset, so the waveguide input (and the sound) lags the
``pulses`` output by BLAMP_HALF samples (0.67 ms at 48 kHz); ``pulses`` stays the exact
pulse train.

Output: sound pressure (unitless), scaled so that throttle 1 at 3000 rpm with no
irregularity peaks at 0.5 (the scale is measured at prepare time by running the kernel).
Extra output ``pulses``: the port pressure pulse train on the same scale. Intake and
engine-block (mechanical) noise are added from that pulse train (``intake_level``,
``mechanical_level``; extra outputs ``intake`` and ``mechanical``; model in
:mod:`ugens.engine_noise`). Not modelled: cylinder waveguides, mufflers, backfire
(SDT ``motor~``).
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numba as nb
import numpy as np

from jassy.errors import PatchError
from jassy.jit import drop_stale_cache, specialise
from jassy.params import Control, ParamSpec
from jassy.registry import register
from jassy.ugen import UGen
from ugens import cells, engine_noise, noise
from ugens.cells import ONSET_AMPLITUDE, ONSET_AT, ONSET_COLUMNS, add_onset, decay_sums, drop_row, slot, store
from ugens.kernels import FASTMATH
from ugens.noise import seed_spec, uniform

drop_stale_cache(__file__, [cells, noise])  # its cache holds copies of their kernels

#: Largest firing delay, as a fraction of the firing interval, at irregularity 1.
JITTER = 0.25
#: Largest relative amplitude deviation of a firing at irregularity 1.
AMPLITUDE_JITTER = 0.5
#: Reference operating point of the output scale: throttle 1 at this rpm peaks at PEAK.
REFERENCE_RPM = 3000.0
PEAK = 0.5
#: Capacity of the queue of firings waiting for their (jittered) onset.
QUEUE = 16
#: XORed into the seed for the intake and mechanical noise (a stream of its own).
NOISE_STREAM = 0x5DEECE66D
#: Noise level parameters -> fields of ugens.engine_noise.NoiseLevels.
_NOISE_LEVELS = {"intake_level": "intake", "hiss": "hiss", "mechanical_level": "mechanical"}
#: Where the two levels that switch the noise on sit in the levels array.
_NOISE_INTAKE, _NOISE_MECHANICAL = (slot(engine_noise.NoiseLevels, k) for k in ("intake", "mechanical"))
#: Rate (Hz) at which the noise levels are as set; other rates keep the spectral density.
NOISE_RATE = 48000.0
#: Band-limited ramp correction: samples either side of an onset, cut-off (fraction of
#: the sample rate), Kaiser window beta, sub-sample positions tabulated.
BLAMP_HALF = 32
BLAMP_CUTOFF = 0.47
BLAMP_BETA = 8.0
BLAMP_PHASES = 256


def blamp_table(half: int = BLAMP_HALF, cutoff: float = BLAMP_CUTOFF, beta: float = BLAMP_BETA,
                phases: int = BLAMP_PHASES) -> np.ndarray:  # fmt: skip
    """Residuals of a band-limited unit ramp: row p, column j holds (R * h)(x) - R(x) at
    x = j - half + p / phases (samples from the corner), R(x) = max(x, 0), h the Kaiser-
    windowed sinc of unit area with cut-off ``cutoff`` (cycles per sample)."""
    grid = 64  # integration points per sample
    tau = np.linspace(-half, half, 2 * half * grid + 1)
    h = 2.0 * cutoff * np.sinc(2.0 * cutoff * tau) * np.kaiser(tau.size, beta)
    step = tau[1] - tau[0]
    h /= np.trapezoid(h, dx=step)
    # R_s(x) = x C0(x) - C1(x), C0 = int_{-half}^x h, C1 = int_{-half}^x tau h (trapezoids)
    c0 = np.concatenate([[0.0], np.cumsum(0.5 * (h[1:] + h[:-1]) * step)])
    th = tau * h
    c1 = np.concatenate([[0.0], np.cumsum(0.5 * (th[1:] + th[:-1]) * step)])
    x = np.arange(2 * half)[None, :] - half + np.arange(phases + 1)[:, None] / phases
    smooth = x * np.interp(x, tau, c0, right=1.0) - np.interp(x, tau, c1, right=c1[-1])
    return smooth - np.maximum(x, 0.0)


_BLAMP = blamp_table()


class EngineParams(NamedTuple):
    """Settings of :func:`engine_run`, stored in this order in the float64 array ``par``."""

    fs: float  #: sample rate (Hz)
    per_rev: float  #: firings per crankshaft revolution
    irregularity: float  #: per-firing jitter of timing and amplitude (0: periodic)
    misfire: float  #: probability that a firing fails
    r: float  #: per-sample decay of a pulse, e^{-1/(tau fs)}
    norm: float  #: e / (tau fs): a pulse's peak 1 at tau
    delay: float  #: one-way travel time of the pipe (samples)
    port: float  #: reflection coefficient at the port end
    pole: float  #: pole of the open end's reflection low-pass
    gain: float  #: output scale


@nb.njit(inline="always", cache=True)
def engine_params(par):
    """The EngineParams record held in ``par``."""
    return EngineParams(par[0], par[1], par[2], par[3], par[4], par[5], par[6], par[7], par[8], par[9])


class EngineState(NamedTuple):
    """Float state of :func:`engine_run`, stored in this order in the float64 array ``st``."""

    phase: float  #: firing phase (fraction of the firing interval)
    s1: float  #: sum of the pulses' A r^x
    s2: float  #: sum of the pulses' x A r^x
    lp_back: float  #: open-end low-pass of the backward wave
    lp_out: float  #: open-end low-pass of the radiated wave


@nb.njit(inline="always", cache=True)
def engine_state(st):
    """The EngineState record held in ``st``."""
    return EngineState(st[0], st[1], st[2], st[3], st[4])


#: Slots of EngineData.ist: the queued firings and the exhaust ring's write slot.
QUEUED, RING_WRITE = 0, 1


class EngineData(NamedTuple):
    """The arrays :func:`engine_run` updates."""

    st: np.ndarray  #: an EngineState
    queue: np.ndarray  #: (QUEUE, ONSET_COLUMNS): the queued firings, a cells.Onset per row
    ist: np.ndarray  #: int64 [queued firings, ring write slot] (QUEUED, RING_WRITE)
    rng: np.ndarray  #: uint64 [splitmix64 state]
    ring: np.ndarray  #: the exhaust pipe's delay line
    lead: np.ndarray  #: the pulse train with its band-limiting corrections, by frame modulo its length


def engine_data(delay: float) -> EngineData:
    """Zeroed EngineData for a pipe of ``delay`` samples one way."""
    return EngineData(
        np.zeros(len(EngineState._fields)),
        np.zeros((QUEUE, ONSET_COLUMNS)),
        np.zeros(2, dtype=np.int64),
        np.zeros(1, dtype=np.uint64),
        np.zeros(int(math.ceil(2.0 * delay)) + 2),
        np.zeros(2 * BLAMP_HALF + 2),
    )


_IRREGULARITY, _MISFIRE, _PORT, _GAIN = (
    slot(EngineParams, k) for k in ("irregularity", "misfire", "port", "gain")
)


@nb.njit(fastmath=FASTMATH, cache=True)
def _tap(ring, w, delay):
    """The ring's sample written ``delay`` (>= 1, fractional) samples before slot w."""
    size = ring.size
    d = int(delay)
    frac = delay - d
    i0 = w - d
    if i0 < 0:
        i0 += size
    i1 = i0 - 1
    if i1 < 0:
        i1 += size
    return (1.0 - frac) * ring[i0] + frac * ring[i1]


@nb.njit(fastmath=FASTMATH, cache=True)
def engine_run(out, pulses_out, start, n, rpms, throttles, data, par, blamp):
    """n samples from absolute frame ``start``; data: an EngineData, par holds an
    EngineParams; blamp: the residual table (:func:`blamp_table`); the pulse train
    data.lead (length 2 BLAMP_HALF + 2) is read BLAMP_HALF frames late."""
    st, queue, ist, rng, ring, lead = data
    prm = engine_params(par)
    fs = prm.fs
    per_rev = prm.per_rev
    irr = prm.irregularity
    mis = prm.misfire
    r = prm.r
    norm = prm.norm
    delay = prm.delay
    port = prm.port
    pole = prm.pole
    gain = prm.gain
    state = engine_state(st)
    phase = state.phase
    s1 = state.s1
    s2 = state.s2
    lp_back = state.lp_back
    lp_out = state.lp_out
    count = ist[QUEUED]
    w = ist[RING_WRITE]
    s = rng[0]
    size = ring.size
    log_r = math.log(r)
    half = blamp.shape[1] // 2
    phases = blamp.shape[0] - 1
    span = lead.size
    for i in range(n):
        t = float(start + i)
        inc = rpms[i] * per_rev / (60.0 * fs)
        phase += inc
        while phase >= 1.0:
            phase -= 1.0
            crossing = t - phase / inc
            s, u1 = uniform(s)
            s, u2 = uniform(s)
            s, u3 = uniform(s)
            amp = throttles[i] * (1.0 + irr * AMPLITUDE_JITTER * u2)
            if 0.5 * (u3 + 1.0) < mis:
                amp = 0.0
            if count < queue.shape[0]:
                queue[count, ONSET_AT] = crossing + irr * JITTER * 0.5 * (u1 + 1.0) / inc
                queue[count, ONSET_AMPLITUDE] = amp
                count += 1
        # propagate the pulse sum to frame t, then start the pulses whose onset has come
        s1, s2 = decay_sums(s1, s2, r)
        k = 0
        while k < count:
            onset = queue[k, ONSET_AT]
            if onset <= t:
                x = t - onset
                s1, s2 = add_onset(s1, s2, queue[k, ONSET_AMPLITUDE], x, log_r)
                # band-limited corner: slope norm * A per sample at the onset
                q = x * phases
                row = min(int(q), phases - 1)
                w1 = q - row
                slope = norm * queue[k, ONSET_AMPLITUDE]
                for j in range(2 * half):
                    c = (1.0 - w1) * blamp[row, j] + w1 * blamp[row + 1, j]
                    lead[int(start + i - half + j) % span] += slope * c
                count = drop_row(queue, k, count)
            else:
                k += 1
        p = norm * s2
        now = int(start + i) % span
        lead[now] += p
        late = int(start + i - half) % span
        p_bl = lead[late]
        lead[late] = 0.0
        # exhaust waveguide: forward wave written at the port, read at the open end
        back = _tap(ring, w, 2.0 * delay)
        lp_back += (1.0 - pole) * (back - lp_back)
        x_port = p_bl - port * lp_back
        ring[w] = x_port
        w += 1
        if w == size:
            w = 0
        front = _tap(ring, w, delay)
        lp_out += (1.0 - pole) * (front - lp_out)
        out[i] = gain * (front - lp_out)
        pulses_out[i] = gain * p
    store(st, EngineState(phase, s1, s2, lp_back, lp_out))
    ist[QUEUED] = count
    ist[RING_WRITE] = w
    rng[0] = s


@register
class Engine(UGen):
    """Combustion engine: firing pulses of N cylinders (2 or 4 strokes) at ``rpm`` through
    an exhaust-pipe waveguide (after SDT ``motor~``, Baldan et al., SIVE 2015, and the JASS
    EngineApplet). Output: sound pressure, throttle 1 at 3000 rpm peaks at ~0.5."""

    type_name = "Engine"
    outputs = ("pulses", "intake", "mechanical")
    param_specs = {
        "rpm": ParamSpec(
            "float", 800.0, low=0.0, high=20000.0, unit="1/min", smooth=True, doc="crankshaft speed"
        ),
        "throttle": ParamSpec(
            "float", 0.2, low=0.0, high=1.0, smooth=True, doc="firing amplitude (0 closed, 1 open)"
        ),
        "cylinders": ParamSpec("int", 4, low=1, high=16, fixed=True, doc="number of cylinders"),
        "strokes": ParamSpec("int", 4, low=2, high=4, fixed=True, doc="2 or 4 strokes per cycle"),
        "irregularity": ParamSpec(
            "float", 0.1, low=0.0, high=1.0, doc="per-firing jitter of timing and amplitude (0: periodic)"
        ),
        "misfire": ParamSpec("float", 0.0, low=0.0, high=1.0, doc="probability that a firing fails"),
        "seed": seed_spec(),
        "pulse": ParamSpec(
            "float",
            0.0015,
            low=1e-5,
            high=0.1,
            unit="s",
            fixed=True,
            doc="rise time tau of a firing's pressure pulse (its peak)",
        ),
        "exhaust_length": ParamSpec(
            "float", 1.2, low=0.0, low_open=True, high=50.0, unit="m", fixed=True, doc="exhaust pipe length"
        ),
        "c": ParamSpec(
            "float",
            450.0,
            low=100.0,
            high=5000.0,
            unit="m/s",
            fixed=True,
            doc="speed of sound in the exhaust gas (~450 m/s at 500 K)",
        ),
        "radius": ParamSpec(
            "float",
            0.025,
            low=0.0,
            low_open=True,
            high=1.0,
            unit="m",
            fixed=True,
            doc="pipe radius: open-end reflection low-pass cut-off c / (2 pi radius)",
        ),
        "port_reflection": ParamSpec(
            "float", 0.7, low=0.0, high=0.99, doc="reflection coefficient at the port (engine) end"
        ),
        **engine_noise.NOISE_SPECS,
    }

    def check_param(self, key: str, value: Any, where: str) -> Any:
        value = super().check_param(key, value, where)
        if key == "strokes" and value not in (2, 4):
            raise PatchError(f"{where}: expected 2 or 4 strokes, got {value!r}")
        return value

    def _prepare(self) -> None:
        v, fs = self.values, self.sample_rate
        delay = v["exhaust_length"] / v["c"] * fs
        if delay < 1.0:
            raise PatchError(
                f"nodes.{self.name}.exhaust_length: the pipe must be at least one sample long "
                f"(c / fs = {v['c'] / fs:.3g} m at {fs:g} Hz), got {v['exhaust_length']!r} m"
            )
        self.data = engine_data(delay)
        self.par = np.zeros(len(EngineParams._fields))
        self.noise_coef = engine_noise.design(v, fs)
        self.noise_state = np.zeros((3, 2))
        self.noise_rng = np.zeros(1, dtype=np.uint64)
        self.noise_levels = np.zeros(len(engine_noise.NoiseLevels._fields))
        self._noise = engine_noise.EngineNoise(
            self.noise_levels, self.noise_coef, self.noise_state, self.noise_rng
        )
        self._noise_run = None
        for key in ("intake_level", "hiss", "mechanical_level"):
            self._param_changed(key, v[key], True)
        self.rpm = self.smoothed("rpm")
        self.throttle = self.smoothed("throttle")
        self._rpms = Control(self.rpm, self.max_block)
        self._throttles = Control(self.throttle, self.max_block)
        self.par[:] = self._kernel_parameters(fs)
        self.par[_GAIN] = PEAK / self._reference_peak()
        self._run = specialise(
            engine_run,
            self.out,
            self.out,
            0,
            0,
            self._rpms.buffer,
            self._throttles.buffer,
            self.data,
            self.par,
            _BLAMP,
        )

    def _kernel_parameters(self, fs: float) -> np.ndarray:
        """The kernel's parameter vector at rate fs (gain 1)."""
        v = self.values
        tau = v["pulse"] * fs
        params = EngineParams(
            fs=fs,
            per_rev=v["cylinders"] / (2.0 if v["strokes"] == 4 else 1.0),
            irregularity=v["irregularity"],
            misfire=v["misfire"],
            r=math.exp(-1.0 / tau),
            norm=math.e / tau,
            delay=v["exhaust_length"] / v["c"] * fs,
            port=v["port_reflection"],
            pole=math.exp(-v["c"] / (v["radius"] * fs)),  # cut-off c / (2 pi radius)
            gain=1.0,
        )
        return np.array(params, dtype=np.float64)

    def _reference_peak(self) -> float:
        """Steady peak of the unscaled output at throttle 1, REFERENCE_RPM, no irregularity,
        rendered at NOISE_RATE (so the scale does not change with the rate: a band-limited
        peak grows with it) unless the pipe is shorter than a sample there."""
        fs = (
            NOISE_RATE
            if self.values["exhaust_length"] / self.values["c"] * NOISE_RATE >= 1.0
            else self.sample_rate
        )
        par = self._kernel_parameters(fs)
        par[_IRREGULARITY] = 0.0
        par[_MISFIRE] = 0.0
        n = int(0.6 * fs)
        out, pulses = np.zeros(n), np.zeros(n)
        engine_run(
            out,
            pulses,
            0,
            n,
            np.full(n, REFERENCE_RPM),
            np.ones(n),
            engine_data(par[slot(EngineParams, "delay")]),
            par,
            _BLAMP,
        )
        peak = float(np.max(np.abs(out[n // 2 :])))
        return peak if peak > 0.0 else 1.0

    def _reset(self) -> None:
        for array in self.data:
            array[:] = 0
        self.data.rng[0] = self.values["seed"]
        self.noise_state[:] = 0.0
        self.noise_rng[0] = self.values["seed"] ^ NOISE_STREAM
        for ramp in (self.rpm, self.throttle):
            ramp.set(ramp.target, 0, jump=True)

    def _param_changed(self, key: str, value: Any, jump: bool) -> None:
        if key in ("rpm", "throttle"):
            getattr(self, key).set(value, self.ramp_samples(), jump)
        elif key == "irregularity":
            self.par[_IRREGULARITY] = value
        elif key == "misfire":
            self.par[_MISFIRE] = value
        elif key == "port_reflection":
            self.par[_PORT] = value
        elif key in _NOISE_LEVELS:
            # white noise of a fixed variance spreads over fs / 2: the noise terms (hiss,
            # block) scale by sqrt(fs / NOISE_RATE) to keep their spectral density at any rate
            density = 1.0 if key == "intake_level" else math.sqrt(self.sample_rate / NOISE_RATE)
            self.noise_levels[slot(engine_noise.NoiseLevels, _NOISE_LEVELS[key])] = value * density

    def process(self, start: int, n: int) -> None:
        self._run(
            self.out,
            self.extra["pulses"],
            start,
            n,
            self._rpms.values(n),
            self._throttles.values(n),
            self.data,
            self.par,
            _BLAMP,
        )
        if self.noise_levels[_NOISE_INTAKE] > 0.0 or self.noise_levels[_NOISE_MECHANICAL] > 0.0:
            args = (
                self.extra["pulses"],
                self.out,
                self.extra["intake"],
                self.extra["mechanical"],
                n,
                self._rpms.buffer,
                self._throttles.buffer,
                self._noise,
            )
            if self._noise_run is None:  # the same arrays at every block: one typed entry point
                self._noise_run = specialise(engine_noise.engine_noise, *args)
            self._noise_run(*args)
        else:
            self.extra["intake"][:n] = 0.0
            self.extra["mechanical"][:n] = 0.0

    def state_arrays(self) -> dict[str, np.ndarray]:
        return {
            **self.data._asdict(),
            "par": self.par,
            "noise_state": self.noise_state,
            "noise_rng": self.noise_rng,
            "noise_levels": self.noise_levels,
            "rpm": self.rpm.ramp,
            "throttle": self.throttle.ramp,
        }
