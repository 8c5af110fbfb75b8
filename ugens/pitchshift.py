"""PitchShift: a two-tap Doppler delay-line pitch shifter (duration unchanged).

Reading a delay line whose delay changes at the rate dd/dt = 1 - r (samples per sample)
plays its input back at r times its speed: every frequency is multiplied by r, the
Doppler effect of a moving read head. The delay cannot change for ever, so it saws
between D0 and D0 + W (W = ``window`` fs samples): d = D0 + W phi, with phi advancing by
(1 - r) / W per sample, wrapped to [0, 1). A second head reads at phi + 1/2, and the two
are cross-faded with the weights sin^2(pi phi) and cos^2(pi phi) (which sum to 1 and
vanish where a head jumps), so the output is continuous (Lent, "An efficient method
for pitch shifting digitally sampled sounds", Computer Music J. 13(4), 1989; Zoelzer,
*DAFX*, 2nd ed., 6.4). Reads interpolate with a 4-point, 3rd-order Hermite polynomial
(D0 = 2 samples, so both neighbours are in the past). The input's duration is kept: the
output is delayed by D0 + W / 2 samples on average. SDT counterpart: ``pitchshift~``.
"""

from __future__ import annotations

import math
from typing import Any

import numba as nb
import numpy as np

from jassy.jit import specialise
from jassy.params import Control, ParamSpec
from jassy.registry import register
from jassy.ugen import UGen
from ugens.kernels import FASTMATH

#: Smallest delay of a read head (samples): the 4-point interpolation needs x[n - d + 1].
MIN_DELAY = 2.0


@nb.njit(fastmath=FASTMATH, cache=True)
def hermite_read(ring, w, delay):
    """The ring's value ``delay`` (>= 2, fractional) samples before slot w (written last)."""
    mask = ring.size - 1
    d = int(delay)
    t = delay - d
    # samples at delays d - 1, d, d + 1, d + 2: x1 = x[n - d], x2 = x[n - d - 1]
    x0 = ring[(w - d + 1) & mask]
    x1 = ring[(w - d) & mask]
    x2 = ring[(w - d - 1) & mask]
    x3 = ring[(w - d - 2) & mask]
    c1 = 0.5 * (x2 - x0)
    c2 = x0 - 2.5 * x1 + 2.0 * x2 - 0.5 * x3
    c3 = 0.5 * (x3 - x0) + 1.5 * (x1 - x2)
    return ((c3 * t + c2) * t + c1) * t + x1


@nb.njit(fastmath=FASTMATH, cache=True)
def pitch_shift(x, out, n, ratios, ring, st, ist, window, wet):
    """n samples; st = [phi], ist = [write slot]; window in samples."""
    mask = ring.size - 1
    phi = st[0]
    w = ist[0]
    for i in range(n):
        w = (w + 1) & mask
        ring[w] = x[i]
        a = phi
        b = phi + 0.5
        if b >= 1.0:
            b -= 1.0
        sa = math.sin(math.pi * a)
        sb = math.sin(math.pi * b)
        y = sa * sa * hermite_read(ring, w, MIN_DELAY + window * a)
        y += sb * sb * hermite_read(ring, w, MIN_DELAY + window * b)
        out[i] = wet * y + (1.0 - wet) * x[i]
        phi += (1.0 - ratios[i]) / window
        phi -= math.floor(phi)
    st[0] = phi
    ist[0] = w


@register
class PitchShift(UGen):
    """Pitch shifter: two cross-faded Doppler read heads on a delay line; frequencies
    times ``ratio``, duration unchanged (latency ~ window / 2). SDT ``pitchshift~``."""

    type_name = "PitchShift"
    inputs = ("input",)
    param_specs = {
        "ratio": ParamSpec(
            "float", 1.5, low=0.25, high=4.0, smooth=True, doc="frequency ratio (2: an octave up)"
        ),
        "window": ParamSpec(
            "float",
            0.04,
            low=0.002,
            high=1.0,
            unit="s",
            fixed=True,
            doc="span of a read head's delay sweep (longer: smoother, more latency)",
        ),
        "wet": ParamSpec("float", 1.0, low=0.0, high=1.0, doc="share of the shifted signal (0: dry)"),
    }

    def _prepare(self) -> None:
        self.window = self.values["window"] * self.sample_rate
        size = 1 << int(math.ceil(math.log2(self.window + MIN_DELAY + 4)))
        self.ring = np.zeros(size)
        self.st = np.zeros(1)
        self.ist = np.zeros(1, dtype=np.int64)
        self.ratio = self.smoothed("ratio")
        self._ratios = Control(self.ratio, self.max_block)
        self.wet = float(self.values["wet"])
        self._run = specialise(
            pitch_shift,
            self.input_buffer("input"),
            self.out,
            0,
            self._ratios.buffer,
            self.ring,
            self.st,
            self.ist,
            self.window,
            self.wet,
        )

    def _reset(self) -> None:
        self.ring[:] = 0.0
        self.st[:] = 0.0
        self.ist[:] = 0
        self.ratio.set(self.ratio.target, 0, jump=True)

    def _param_changed(self, key: str, value: Any, jump: bool) -> None:
        if key == "ratio":
            self.ratio.set(value, self.ramp_samples(), jump)
        elif key == "wet":
            self.wet = float(value)

    def process(self, start: int, n: int) -> None:
        self._run(
            self.input_buffer("input"),
            self.out,
            n,
            self._ratios.values(n),
            self.ring,
            self.st,
            self.ist,
            self.window,
            self.wet,
        )

    def state_arrays(self) -> dict[str, np.ndarray]:
        return {"ring": self.ring, "st": self.st, "ist": self.ist, "ratio": self.ratio.ramp}
