"""Anytime synthesis: one mode budget shared by every ModalBank of a graph.

Every ``period`` frames of the clock (the scheduler splits sub-blocks there, so the result
does not depend on the block size) the budget ranks all modes of all banks by importance

    I_k = w(f_k) * (A_k^2 + (a_k J_b)^2)

where A_k is the mode's current amplitude (from its two state samples), a_k J_b the
amplitude an impulse J_b gives it (J_b: the larger of the impulse the bank received in
the last period and the impulses of impacts scheduled upstream of it in this period), and
w the A-weighting power gain (IEC 61672) as loudness weighting. The top ``max_modes``
modes are computed for the next period; the rest are silenced.

Leaving without clicks: the scheduler knows the score, so the budget also ranks the modes
for the *following* period (amplitudes decayed by one period, impacts scheduled then). A
kept mode that will be displaced then is faded out during this period (its decay raised
to fall 60 dB in one period) while still counting against the budget, so the mode that
displaces it enters, from silence, exactly when its impact starts. Only a displacement
that could not be foreseen (a force that is not a scheduled event) cuts a sounding mode
at once. With ``cpu_fraction`` the budget adapts ``max_modes`` each period so that
rendering takes that fraction of real time (non-deterministic by nature).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from jassy.errors import PatchError


def a_weighting_power(f: np.ndarray) -> np.ndarray:
    """Squared A-weighting gain at frequencies f (Hz), normalised to 1 at 1 kHz."""
    f2 = np.asarray(f, dtype=np.float64) ** 2
    ra = (12194.0**2 * f2**2) / (
        (f2 + 20.6**2) * np.sqrt((f2 + 107.7**2) * (f2 + 737.9**2)) * (f2 + 12194.0**2)
    )
    return (ra / 0.7943282347242815) ** 2  # R_A(1 kHz) = 10^(-2/20)


@dataclass
class ModeBudget:
    """A budget of modes computed per period across all ModalBanks of a graph.

    max_modes: modes computed at most (leaving modes included); cpu_fraction: adapt
    max_modes so rendering takes this fraction of real time; period: frames between
    decisions.
    """

    max_modes: int | None = None
    cpu_fraction: float | None = None
    period: int = 512
    peak_modes: int = field(default=0, init=False)
    decisions: int = field(default=0, init=False)

    def __post_init__(self):
        if self.max_modes is None and self.cpu_fraction is None:
            raise PatchError("mode budget: give max_modes, cpu_fraction or both")
        if self.max_modes is not None and (not isinstance(self.max_modes, int) or self.max_modes < 1):
            raise PatchError(f"mode_budget: expected an integer >= 1, got {self.max_modes!r}")
        if self.cpu_fraction is not None and not 0 < self.cpu_fraction <= 10:
            raise PatchError(
                f"cpu_budget: expected a fraction of real time in (0, 10], got {self.cpu_fraction!r}"
            )
        if not isinstance(self.period, int) or self.period < 8:
            raise PatchError(f"budget period: expected an integer >= 8 frames, got {self.period!r}")

    def attach(self, banks: list, sample_rate: float, upcoming) -> None:
        """Start a render: ``banks`` expose anytime_importance/anytime_apply;
        ``upcoming(start, end)`` lists (node, impulse) of impacts scheduled in [start, end)."""
        self.banks = banks
        self.sample_rate = sample_rate
        self.upcoming = upcoming
        self.limit = self.max_modes or sum(b.model.n_modes for b in banks)
        self.peak_modes = 0
        self.decisions = 0
        self._clock = None

    def _predicted(self, start: int, end: int) -> dict[int, float]:
        """Largest scheduled impulse (N s) per bank in frames [start, end)."""
        predicted = {id(b): 0.0 for b in self.banks}
        for node_banks, impulse in self.upcoming(start, end):
            for bank in node_banks:
                if id(bank) in predicted:
                    predicted[id(bank)] = max(predicted[id(bank)], impulse)
        return predicted

    def _top(self, score: np.ndarray) -> np.ndarray:
        """Mask of the ``limit`` highest positive scores."""
        keep = np.zeros(score.size, dtype=bool)
        positive = np.flatnonzero(score > 0)
        if positive.size <= self.limit:
            keep[positive] = True
        else:
            keep[positive[np.argpartition(score[positive], -self.limit)[-self.limit :]]] = True
        return keep

    def step(self, start: int, n: int) -> None:
        """Graph step: decide at every multiple of ``period`` on the clock."""
        if start % self.period:
            return
        if self.cpu_fraction is not None:
            self._adapt()
        now = self._predicted(start, start + self.period)
        later = self._predicted(start + self.period, start + 2 * self.period)
        parts = [b.anytime_importance(now[id(b)], later[id(b)], self.period) for b in self.banks]
        keep = self._top(np.concatenate([p[0] for p in parts]))
        fade = (
            keep & ~self._top(np.concatenate([p[1] for p in parts])) & np.concatenate([p[2] for p in parts])
        )
        total, offset = 0, 0
        for bank, part in zip(self.banks, parts, strict=True):
            sl = slice(offset, offset + part[0].size)
            total += bank.anytime_apply(keep[sl] & ~fade[sl], fade[sl], self.period)
            offset += part[0].size
        self.peak_modes = max(self.peak_modes, total)
        self.decisions += 1

    def _adapt(self) -> None:
        now = time.perf_counter()
        if self._clock is not None:
            allowed = self.cpu_fraction * self.period / self.sample_rate
            used = max(now - self._clock, 1e-9)
            ceiling = self.max_modes or sum(b.model.n_modes for b in self.banks)
            self.limit = int(np.clip(self.limit * min(max(allowed / used, 0.5), 1.25), 16, ceiling))
        self._clock = now
