"""Analysis ugens: control signals measured from an audio input (SDT's perception
processors ``envelope~``, ``zerox~``, ``spectralfeats~``, ``pitch~``, ``onset~``).

Sample-rate followers:

* ``EnvelopeFollower``: y += a (v - y) with v = |x| (``peak``) or x^2 (``rms``, output
  sqrt(y)), a = 1 - e^{-1 / (T fs)}, T = ``attack`` while v > y and ``release`` otherwise:
  a DC step of level A is followed as A (1 - e^{-t / T}).
* ``ZeroCrossings``: sign changes of the input in the last ``window`` s, per second
  (a sine of f Hz gives 2 f; white noise fs / 2).

Frame features (a frame of ``size`` samples, Hann window, every ``hop`` samples; the
value of the frame ending before sample t is output from t on, held until the next):

* ``SpectralFeatures`` (rfft by pyfftw): main output the centroid sum f |X| / sum |X| (Hz);
  extra outputs ``spread`` sqrt(sum (f - centroid)^2 |X| / sum |X|) (Hz), ``flatness``
  exp(mean ln P) / mean P of the power spectrum P = |X|^2 (0 for a sine; e^-gamma = 0.561
  for white noise, whose periodogram bins are exponentially distributed), ``rolloff`` the
  frequency below which ``rolloff_fraction`` of the power lies, and ``flux`` the distance
  between successive magnitude spectra, sqrt(sum (|X| - |X_prev|)^2) / sqrt(sum |X|^2)
  (Peeters, "A large set of audio features", CUIDADO report, 2004).
* ``Pitch``: YIN (de Cheveigne & Kawahara, JASA 111(4), 2002): difference function
  d(tau) = sum_{j<W} (x_j - x_{j+tau})^2 (W = size / 2, by FFT), cumulative mean
  normalised d'(tau) = d(tau) tau / sum_{k<=tau} d(k), the first dip below ``threshold``
  (its local minimum, refined by a parabola), f0 = fs / tau; 0 Hz when no dip is found
  (unvoiced) or the frame is silent. Extra output ``clarity`` 1 - d'(tau) (0 unvoiced).
* ``Onset``: positive spectral flux sum max(0, |X| - |X_prev|) / sum |X|; an onset is
  reported (output 1 for one sample, else 0) when it exceeds ``threshold`` and the mean
  of the previous 8 frames' flux by the factor ``ratio``, at most once per
  ``min_interval`` s (Bello et al., "A tutorial on onset detection in music signals",
  IEEE TSAP 13(5), 2005). Extra output ``strength``: the flux.

Each output is a signal like any other: multiply a source by an envelope, or turn a
rendered feature curve into parameter events (``jassy analyze`` writes them as CSV).
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

import numba as nb
import numpy as np

from jassy.errors import PatchError
from jassy.params import ParamSpec
from jassy.registry import register
from jassy.ugen import UGen
from ugens.kernels import FASTMATH

#: Frames of flux history the onset threshold is relative to.
ONSET_HISTORY = 8
_PEAK, _RMS = 0, 1


@nb.njit(fastmath=FASTMATH, cache=True)
def follow(x, out, n, mode, attack, release, st):
    """Envelope follower (module docstring); st = [y]."""
    y = st[0]
    for i in range(n):
        v = abs(x[i]) if mode == _PEAK else x[i] * x[i]
        y += (attack if v > y else release) * (v - y)
        out[i] = y if mode == _PEAK else math.sqrt(y)
    st[0] = y


@nb.njit(fastmath=FASTMATH, cache=True)
def zero_crossings(x, out, n, flags, ist, scale):
    """Sign changes in the last flags.size samples, times scale; ist = [slot, count, last
    sign (+1 / -1, 0 before the first sample)]."""
    w = ist[0]
    count = ist[1]
    last = ist[2]
    size = flags.size
    for i in range(n):
        sign = 1 if x[i] >= 0.0 else -1
        change = 1 if (last != 0 and sign != last) else 0
        last = sign
        count += change - flags[w]
        flags[w] = change
        w += 1
        if w == size:
            w = 0
        out[i] = count * scale
    ist[0] = w
    ist[1] = count
    ist[2] = last


_ATTACK = ParamSpec("float", 0.005, low=1e-5, high=10.0, unit="s", doc="time constant while rising")


@register
class EnvelopeFollower(UGen):
    """Amplitude envelope of the input: one-pole follower of |x| (peak) or x^2 (rms) with
    attack and release time constants. SDT ``envelope~``."""

    type_name = "EnvelopeFollower"
    inputs = ("input",)
    param_specs = {
        "mode": ParamSpec("str", "rms", choices=("peak", "rms"), fixed=True, doc="follow |x| or the RMS"),
        "attack": _ATTACK,
        "release": ParamSpec("float", 0.05, low=1e-5, high=10.0, unit="s", doc="time constant while falling"),
    }

    def _prepare(self) -> None:
        self.st = np.zeros(1)
        self.mode = _PEAK if self.values["mode"] == "peak" else _RMS

    def _coefficient(self, key: str) -> float:
        return -math.expm1(-1.0 / (self.values[key] * self.sample_rate))

    def _reset(self) -> None:
        self.st[0] = 0.0

    def process(self, start: int, n: int) -> None:
        follow(
            self.input_buffer("input"),
            self.out,
            n,
            self.mode,
            self._coefficient("attack"),
            self._coefficient("release"),
            self.st,
        )

    def state_arrays(self) -> dict[str, np.ndarray]:
        return {"st": self.st}


@register
class ZeroCrossings(UGen):
    """Zero-crossing rate of the input: sign changes per second over a sliding window
    (2 f for a sine of f Hz). SDT ``zerox~``."""

    type_name = "ZeroCrossings"
    inputs = ("input",)
    param_specs = {
        "window": ParamSpec("float", 0.02, low=1e-4, high=10.0, unit="s", fixed=True, doc="window length"),
    }

    def _prepare(self) -> None:
        size = max(1, int(round(self.values["window"] * self.sample_rate)))
        self.flags = np.zeros(size, dtype=np.int64)
        self.ist = np.zeros(3, dtype=np.int64)
        self.scale = self.sample_rate / size

    def _reset(self) -> None:
        self.flags[:] = 0
        self.ist[:] = 0

    def process(self, start: int, n: int) -> None:
        zero_crossings(self.input_buffer("input"), self.out, n, self.flags, self.ist, self.scale)

    def state_arrays(self) -> dict[str, np.ndarray]:
        return {"flags": self.flags, "ist": self.ist}


def _power_of_two(where: str, value: int) -> None:
    if value & (value - 1):
        raise PatchError(f"{where}: expected a power of two, got {value}")


class _Framed(UGen):
    """Frames of ``size`` input samples every ``hop`` samples; subclasses turn a frame
    into output values (:meth:`_analyse`), held from the frame's end on."""

    inputs = ("input",)
    #: Output names whose values a frame sets: "" is the main output, others in outputs.
    values_of: ClassVar[tuple[str, ...]] = ("",)

    def check_param(self, key: str, value: Any, where: str) -> Any:
        value = super().check_param(key, value, where)
        if key == "size":
            _power_of_two(where, value)
        return value

    def _prepare(self) -> None:
        size = self.values["size"]
        self.size = size
        self.hop = self.values["hop"]
        self.history = np.zeros(size + self.max_block)
        self.held = np.zeros(len(self.values_of))
        self.window = np.hanning(size + 1)[:size]
        from jassy.fftw import import_pyfftw  # imported on use: pyfftw's interfaces slow every start

        pyfftw = import_pyfftw()

        self.frame = pyfftw.empty_aligned(size, dtype="float64")
        self.fft = pyfftw.builders.rfft(self.frame, threads=1)
        self.freqs = np.fft.rfftfreq(size, 1.0 / self.sample_rate)

    def _reset(self) -> None:
        self.history[:] = 0.0
        self.held[:] = 0.0

    def _buffers(self) -> list[np.ndarray]:
        return [self.out if name == "" else self.extra[name] for name in self.values_of]

    def _spectrum(self, samples: np.ndarray) -> np.ndarray:
        """|rfft| of the Hann-windowed frame."""
        np.multiply(samples, self.window, out=self.frame)
        return np.abs(self.fft())

    def _analyse(self, samples: np.ndarray, t: int) -> None:
        """Set self.held from the frame ``samples``: the ``size`` input samples before
        absolute sample t."""
        raise NotImplementedError

    def process(self, start: int, n: int) -> None:
        h = self.history
        h[:-n] = h[n:]
        h[-n:] = self.input_buffer("input")[:n]
        outs = self._buffers()
        first = -(-start // self.hop) * self.hop
        begin = 0
        for t in range(max(first, self.hop), start + n, self.hop):
            i = t - start
            for out, value in zip(outs, self.held, strict=True):
                out[begin:i] = value
            end = h.size - n + i  # history index of sample t: the frame is [t - size, t)
            self._analyse(h[end - self.size : end], t)
            begin = i
        for out, value in zip(outs, self.held, strict=True):
            out[begin:n] = value

    def state_arrays(self) -> dict[str, np.ndarray]:
        return {"history": self.history, "held": self.held}


_SIZE = ParamSpec("int", 1024, low=64, high=65536, fixed=True, doc="frame length in samples (power of two)")
_HOP = ParamSpec("int", 512, low=1, high=65536, fixed=True, doc="samples between frames")


@register
class SpectralFeatures(_Framed):
    """Spectral centroid (Hz) of a running FFT (pyfftw), with extra outputs spread,
    flatness, rolloff and flux. SDT ``spectralfeats~``; formulas in the module docstring."""

    type_name = "SpectralFeatures"
    outputs = ("spread", "flatness", "rolloff", "flux")
    values_of = ("", "spread", "flatness", "rolloff", "flux")
    param_specs = {
        "size": _SIZE,
        "hop": _HOP,
        "rolloff_fraction": ParamSpec(
            "float", 0.85, low=0.01, high=0.999, fixed=True, doc="power fraction of the rolloff"
        ),
    }

    def _prepare(self) -> None:
        super()._prepare()
        self.previous = np.zeros(self.size // 2 + 1)

    def _reset(self) -> None:
        super()._reset()
        self.previous[:] = 0.0

    def _analyse(self, samples: np.ndarray, t: int) -> None:
        mag = self._spectrum(samples)
        total = mag.sum()
        power = mag * mag
        if total <= 0.0:
            self.held[:] = 0.0
        else:
            f = self.freqs
            centroid = float(np.dot(f, mag) / total)
            spread = math.sqrt(float(np.dot((f - centroid) ** 2, mag) / total))
            inner = power[1:-1] + 1e-300
            flatness = float(np.exp(np.mean(np.log(inner))) / np.mean(inner))
            cumulative = np.cumsum(power)
            rolloff = float(f[np.searchsorted(cumulative, self.values["rolloff_fraction"] * cumulative[-1])])
            flux = float(np.linalg.norm(mag - self.previous) / math.sqrt(float(power.sum())))
            self.held[:] = (centroid, spread, flatness, rolloff, flux)
        self.previous[:] = mag

    def state_arrays(self) -> dict[str, np.ndarray]:
        return {**super().state_arrays(), "previous": self.previous}


@nb.njit(fastmath=FASTMATH, cache=True)
def yin_pick(cmnd, tau_min, tau_max, threshold):
    """(tau, d') of YIN's first dip of cmnd below threshold in [tau_min, tau_max), the
    local minimum refined by a parabola; (0, 1) if there is none."""
    tau = tau_min
    while tau < tau_max:
        if cmnd[tau] < threshold:
            while tau + 1 < tau_max and cmnd[tau + 1] < cmnd[tau]:
                tau += 1
            a = cmnd[tau - 1]
            b = cmnd[tau]
            c = cmnd[tau + 1] if tau + 1 < cmnd.size else b
            den = a - 2.0 * b + c
            shift = 0.5 * (a - c) / den if den > 0.0 else 0.0
            return tau + shift, b
        tau += 1
    return 0.0, 1.0


@register
class Pitch(_Framed):
    """Fundamental frequency (Hz, 0 when unvoiced) by YIN; extra output ``clarity``.
    SDT ``pitch~``; algorithm in the module docstring."""

    type_name = "Pitch"
    outputs = ("clarity",)
    values_of = ("", "clarity")
    param_specs = {
        "size": ParamSpec(
            "int", 2048, low=64, high=65536, fixed=True, doc="frame length (power of two; 2 x longest period)"
        ),
        "hop": _HOP,
        "min_freq": ParamSpec("float", 60.0, low=1.0, high=20000.0, unit="Hz", fixed=True, doc="lowest f0"),
        "max_freq": ParamSpec(
            "float", 2000.0, low=1.0, high=20000.0, unit="Hz", fixed=True, doc="highest f0"
        ),
        "threshold": ParamSpec("float", 0.1, low=0.001, high=1.0, fixed=True, doc="YIN dip threshold"),
    }

    def _prepare(self) -> None:
        super()._prepare()
        v, fs = self.values, self.sample_rate
        half = self.size // 2
        self.tau_min = max(2, int(fs / v["max_freq"]))
        self.tau_max = min(half - 1, int(math.ceil(fs / v["min_freq"])) + 1)
        if self.tau_min >= self.tau_max:
            raise PatchError(
                f"nodes.{self.name}: min_freq {v['min_freq']:g} Hz needs a frame of more than "
                f"2 fs / min_freq samples and below max_freq; got size {self.size}"
            )
        from jassy.fftw import import_pyfftw

        pyfftw = import_pyfftw()
        self.padded = pyfftw.empty_aligned(2 * self.size, dtype="float64")
        self.forward = pyfftw.builders.rfft(self.padded, threads=1)

    def _analyse(self, samples: np.ndarray, t: int) -> None:
        half = self.size // 2
        if not np.any(samples[: half + half]):  # silence: nothing to measure
            self.held[:] = 0.0
            return
        # cross term r(tau) = sum_{j<W} x_j x_{j+tau} by FFT correlation (zero padded)
        self.padded[:] = 0.0
        self.padded[: self.size] = samples
        whole = self.forward().copy()
        self.padded[:] = 0.0
        self.padded[:half] = samples[:half]
        head = self.forward()
        r = np.fft.irfft(np.conj(head) * whole, 2 * self.size)[:half]
        squares = np.concatenate([[0.0], np.cumsum(samples * samples)])
        energy_head = squares[half]
        energy_lag = squares[half : half + half] - squares[:half]  # sum_{j<W} x_{j+tau}^2
        d = energy_head + energy_lag - 2.0 * r
        d[0] = 0.0
        running = np.cumsum(d[1:])
        cmnd = np.ones(half)
        cmnd[1:] = d[1:] * np.arange(1, half) / np.where(running > 0.0, running, 1.0)
        tau, dip = yin_pick(cmnd, self.tau_min, self.tau_max, self.values["threshold"])
        self.held[0] = self.sample_rate / tau if tau > 0.0 else 0.0
        self.held[1] = 1.0 - dip


@register
class Onset(_Framed):
    """Onset detector: 1 for one sample when the positive spectral flux jumps (relative
    to the recent frames), else 0; extra output ``strength``. SDT ``onset~``."""

    type_name = "Onset"
    outputs = ("strength",)
    values_of = ("strength",)
    param_specs = {
        "size": _SIZE,
        "hop": _HOP,
        "threshold": ParamSpec("float", 0.1, low=0.0, high=100.0, fixed=True, doc="smallest onset flux"),
        "ratio": ParamSpec(
            "float", 2.0, low=1.0, high=100.0, fixed=True, doc="flux over the recent mean it must exceed"
        ),
        "min_interval": ParamSpec(
            "float", 0.05, low=0.0, high=10.0, unit="s", fixed=True, doc="shortest time between onsets"
        ),
    }

    def _prepare(self) -> None:
        super()._prepare()
        self.previous = np.zeros(self.size // 2 + 1)
        self.recent = np.zeros(ONSET_HISTORY)
        # [frames seen, samples since the last onset, onset pending for the next frame start]
        self.count = np.zeros(3, dtype=np.int64)

    def _reset(self) -> None:
        super()._reset()
        self.previous[:] = 0.0
        self.recent[:] = 0.0
        self.count[:] = 0
        self.count[1] = 1 << 40

    def process(self, start: int, n: int) -> None:
        self._marks: list[int] = []
        super().process(start, n)
        self.out[:n] = 0.0
        for t in self._marks:
            self.out[t - start] = 1.0

    def _analyse(self, samples: np.ndarray, t: int) -> None:
        mag = self._spectrum(samples)
        total = mag.sum()
        flux = float(np.maximum(mag - self.previous, 0.0).sum() / total) if total > 0.0 else 0.0
        self.previous[:] = mag
        frames, since = int(self.count[0]), int(self.count[1]) + self.hop
        mean = self.recent[: min(frames, ONSET_HISTORY)].mean() if frames else 0.0
        if (
            flux > self.values["threshold"]
            and flux > self.values["ratio"] * mean
            and since >= self.values["min_interval"] * self.sample_rate
        ):
            since = 0
            self._marks.append(t)
        self.recent[frames % ONSET_HISTORY] = flux
        self.count[0] = frames + 1
        self.count[1] = since
        self.held[0] = flux

    def state_arrays(self) -> dict[str, np.ndarray]:
        return {
            **super().state_arrays(),
            "previous": self.previous,
            "recent": self.recent,
            "count": self.count,
        }
