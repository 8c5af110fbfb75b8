"""Psychophysical methods: constant stimuli, staircases, QUEST and QUEST+, each a *track*
that proposes offsets (ms) and learns from the answers, with a stopping rule.

A track has ``next_offset() -> float | None`` (None: its stopping rule is met),
``update(offset_ms, positive, correct)`` and ``summary()``. ``positive`` is the model's
positive answer ("haptic first", "simultaneous", or a correct m-AFC choice); ``correct``
is None where a task has no right answer. Tracks are deterministic given their seed and
the answers, so a session can be replayed from its log.

* :class:`ConstantTrack`: every offset ``repetitions`` times, in seeded random order.
* :class:`Staircase`: n-down/1-up on the offset magnitude (Levitt 1971, J. Acoust. Soc.
  Am. 49: 467), stops after ``reversals`` reversals or ``max_trials`` trials.
* :class:`QuestTrack`: QUEST (Watson & Pelli 1983, Percept. Psychophys. 33: 113): a
  Bayesian posterior over the offset at which the model gives probability ``target``,
  slope and lapse fixed at guesses, a Gaussian prior; each trial is placed at the
  posterior mean (King-Smith et al. 1994). For TOJ two tracks target 25 % and 75 %
  (PSS = their midpoint, JND = half their distance); for m-AFC one track targets F = 1/2.
  Stops at ``max_trials`` or when the posterior SD falls below ``stop_sd_ms``.
* :class:`QuestPlusTrack`: QUEST+ (Watson 2017, J. Vision 17(3): 10): a posterior over
  all parameters of the task's model on a grid; each trial is the offset that minimises
  the expected posterior entropy (seeded choice among the ``choose_from`` best). Stops
  at ``max_trials`` or when the posterior SD of ``stop_param`` is below ``stop_sd``
  (after ``min_trials``). Implemented here rather than with the ``questplus`` package,
  whose likelihoods are a fixed list (Weibull, cumulative normals, CSF) without the SJ
  window models, the logistic or the m-AFC form used here, and whose xarray trial
  (choice and update) takes about 100x the CPU time of this one on the same grid; tests
  check this implementation's choices against ``questplus`` on its ``norm_cdf_2`` model.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy.special import ndtri

from jassy.study.models import LAPSE_GRID, Model

RULES = {"1down1up": 1, "2down1up": 2, "3down1up": 3}


class ConstantTrack:
    """Method of constant stimuli: the listed offsets, each ``repetitions`` times."""

    kind = "constant"

    def __init__(self, name: str, offsets_ms, repetitions: int, rng: np.random.Generator):
        trials = np.repeat(np.asarray(offsets_ms, dtype=float), repetitions)
        self.name = name
        self.offsets = trials[rng.permutation(trials.size)]
        self.position = 0

    @property
    def remaining(self) -> int:
        return int(self.offsets.size - self.position)

    def next_offset(self) -> float | None:
        return float(self.offsets[self.position]) if self.position < self.offsets.size else None

    def update(self, offset_ms: float, positive: bool, correct: bool | None) -> None:
        self.position += 1

    def summary(self) -> dict[str, Any]:
        return {"method": self.kind, "trials": self.position}


class Staircase:
    """An n-down/1-up staircase on the offset magnitude (ms) with a sign (the leading
    modality). After ``n_down`` consecutive correct answers the magnitude decreases by the
    current step, after each error it increases (clamped to [min_ms, max_ms]); at each
    change of direction (a reversal) the step moves to the next of ``steps_ms``. It
    converges on the magnitude answered correctly with probability 0.5 ** (1 / n_down)."""

    kind = "staircase"
    remaining = None

    def __init__(self, name, sign, rule, start_ms, steps_ms, min_ms, max_ms, reversals, max_trials):
        self.name, self.sign = name, sign
        self.n_down = RULES[rule]
        self.magnitude = float(start_ms)
        self.steps = [float(s) for s in steps_ms]
        self.min_ms, self.max_ms = float(min_ms), float(max_ms)
        self.max_reversals, self.max_trials = int(reversals), int(max_trials)
        self.step_index = self.run = self.direction = self.trials = 0
        self.reversal_values: list[float] = []

    @property
    def done(self) -> bool:
        return len(self.reversal_values) >= self.max_reversals or self.trials >= self.max_trials

    def next_offset(self) -> float | None:
        return None if self.done else self.sign * self.magnitude

    def update(self, offset_ms: float, positive: bool, correct: bool | None) -> None:
        self.trials += 1
        if correct:
            self.run += 1
            if self.run < self.n_down:
                return
            self.run, move = 0, -1
        else:
            self.run, move = 0, 1
        if self.direction != 0 and move != self.direction:
            self.reversal_values.append(self.magnitude)
            self.step_index = min(self.step_index + 1, len(self.steps) - 1)
        self.direction = move
        self.magnitude = min(
            max(self.magnitude + move * self.steps[self.step_index], self.min_ms), self.max_ms
        )

    def threshold(self) -> float | None:
        """Mean magnitude at the reversals after the first two (None if too few)."""
        values = self.reversal_values[2:]
        return float(np.mean(values)) if values else None

    def summary(self) -> dict[str, Any]:
        return {
            "method": self.kind,
            "trials": self.trials,
            "reversals": self.reversal_values,
            "threshold_ms": self.threshold(),
            "rule": f"{self.n_down}down1up",
        }


class QuestTrack:
    """QUEST on one quantile: posterior over q, the offset (ms; for m-AFC the magnitude,
    in log) where the model with the guessed ``sigma_ms`` / ``slope`` and ``lapse`` gives
    probability ``target`` of the positive answer."""

    kind = "quest"
    remaining = None

    def __init__(
        self,
        name: str,
        model: Model,
        target: float,
        guess_ms: float,
        prior_sd_ms: float,
        sigma_ms: float,
        slope: float,
        lapse: float,
        max_trials: int,
        stop_sd_ms: float = 0.0,
        min_trials: int = 0,
        sign: float = 1.0,
    ):
        self.name, self.model, self.target = name, model, target
        self.sign = sign
        self.max_trials, self.stop_sd_ms, self.min_trials = max_trials, stop_sd_ms, min_trials
        self.afc = model.task in ("2afc", "3afc")
        self.trials = 0
        if self.afc:  # log magnitude: the Weibull is a shift family in log offset
            centre = math.log(max(abs(guess_ms), 1e-3))
            self.grid = np.linspace(centre - 4.0, centre + 4.0, 801)
            self.logpost = (
                -0.5 * ((self.grid - centre) / max(prior_sd_ms / max(abs(guess_ms), 1e-3), 0.05)) ** 2
            )
            guess = 1.0 / model.alternatives
            f = (target - guess) / ((1.0 - guess) * (1.0 - lapse))
            # F(a) = target fraction at a = q: threshold = q / (ln(1/(1-f)) / ln 2) ** (1/slope)
            self._shift = math.log((math.log(1.0 / (1.0 - f)) / math.log(2.0)) ** (1.0 / slope))
            self._params = {"slope": slope, "lapse": lapse}
        else:
            self.grid = np.linspace(guess_ms - 5 * prior_sd_ms, guess_ms + 5 * prior_sd_ms, 801)
            self.logpost = -0.5 * ((self.grid - guess_ms) / prior_sd_ms) ** 2
            f = (target - 0.5 * lapse) / (1.0 - lapse)
            z = float(ndtri(f)) if model.function == "gaussian" else math.log(f / (1.0 - f))
            self._shift = z * sigma_ms  # pss = q - z sigma
            self._params = {"sigma": sigma_ms, "lapse": lapse}

    def _p(self, offset_ms: float) -> np.ndarray:
        if self.afc:
            return self.model.prob(offset_ms, threshold=np.exp(self.grid - self._shift), **self._params)
        return self.model.prob(offset_ms, pss=self.grid - self._shift, **self._params)

    def _moments(self) -> tuple[float, float]:
        w = np.exp(self.logpost - self.logpost.max())
        w /= w.sum()
        mean = float(w @ self.grid)
        sd = math.sqrt(max(float(w @ (self.grid - mean) ** 2), 0.0))
        if self.afc:
            return math.exp(mean), math.exp(mean) * sd  # delta method for the SD in ms
        return mean, sd

    @property
    def done(self) -> bool:
        if self.trials >= self.max_trials:
            return True
        return self.trials >= self.min_trials and self.stop_sd_ms > 0 and self._moments()[1] < self.stop_sd_ms

    def next_offset(self) -> float | None:
        if self.done:
            return None
        mean = self._moments()[0]
        return self.sign * mean if self.afc else mean

    def update(self, offset_ms: float, positive: bool, correct: bool | None) -> None:
        p = np.clip(self._p(offset_ms), 1e-12, 1 - 1e-12)
        self.logpost += np.log(p if positive else 1.0 - p)
        self.trials += 1

    def summary(self) -> dict[str, Any]:
        mean, sd = self._moments()
        return {
            "method": self.kind,
            "trials": self.trials,
            "target": self.target,
            "estimate_ms": mean,
            "sd_ms": sd,
        }


def quest_plus_grid(model: Model, offsets: np.ndarray, points: int = 25) -> dict[str, np.ndarray]:
    """A default parameter grid for QUEST+ from the stimulus domain (offsets, ms)."""
    top = float(np.max(np.abs(offsets)))
    grid: dict[str, np.ndarray] = {}
    for p in model.params:
        if p.name == "lapse":
            grid[p.name] = np.asarray(LAPSE_GRID[::2] if len(model.params) > 3 else LAPSE_GRID)
        elif p.name == "pss":
            grid[p.name] = np.linspace(-top / 2.0, top / 2.0, points + 8)
        elif p.name == "slope":
            grid[p.name] = np.geomspace(0.7, 8.0, 12)
        elif p.name == "window":
            grid[p.name] = np.geomspace(top / 30.0, 1.5 * top, points)
        elif p.name == "threshold":
            grid[p.name] = np.geomspace(top / 50.0, top, points)
        else:
            grid[p.name] = np.geomspace(top / 60.0, top, points)
    return grid


class QuestPlusTrack:
    """QUEST+: posterior over a parameter grid, next offset by minimum expected entropy."""

    kind = "quest_plus"
    remaining = None

    def __init__(
        self,
        name: str,
        model: Model,
        offsets_ms,
        grid: dict[str, np.ndarray],
        max_trials: int,
        rng: np.random.Generator,
        stop_param: str = "",
        stop_sd: float = 0.0,
        min_trials: int = 0,
        choose_from: int = 1,
    ):
        self.name, self.model = name, model
        self.offsets = np.asarray(offsets_ms, dtype=float)
        self.max_trials, self.min_trials = max_trials, min_trials
        self.stop_param, self.stop_sd, self.choose_from = stop_param, stop_sd, max(1, choose_from)
        self.rng = rng
        axes = [np.asarray(grid[p.name], dtype=float) for p in model.params]
        mesh = np.meshgrid(*axes, indexing="ij")
        self.values = {p.name: m.ravel() for p, m in zip(model.params, mesh, strict=True)}
        # likelihood of the positive answer: (stimuli, parameter points)
        self.like = np.clip(
            model.prob(self.offsets[:, None], **{k: v[None, :] for k, v in self.values.items()}),
            1e-12,
            1 - 1e-12,
        )
        self.like_log_like = self.like * np.log(self.like)
        self.miss_log_miss = (1.0 - self.like) * np.log1p(-self.like)
        self.post = np.full(self.like.shape[1], 1.0 / self.like.shape[1])
        self.trials = 0
        self._next: float | None = None

    def posterior_sd(self, name: str) -> float:
        v = self.values[name]
        mean = float(self.post @ v)
        return math.sqrt(max(float(self.post @ (v - mean) ** 2), 0.0))

    def estimate(self) -> dict[str, float]:
        """Posterior means of the parameters."""
        return {k: float(self.post @ v) for k, v in self.values.items()}

    @property
    def done(self) -> bool:
        if self.trials >= self.max_trials:
            return True
        return (
            bool(self.stop_param)
            and self.trials >= self.min_trials
            and self.posterior_sd(self.stop_param) < self.stop_sd
        )

    def expected_entropy(self) -> np.ndarray:
        """Expected posterior entropy after one more trial at each offset. For an answer
        with likelihood L (per parameter point) and posterior w, its probability is
        p = L.w and p H = p ln p - sum w L (ln w + ln L): four matrix-vector products."""
        post = self.post
        w_log_w = post * np.log(np.maximum(post, 1e-300))
        p_yes = self.like @ post
        yes = self.like @ w_log_w + self.like_log_like @ post
        no = (w_log_w.sum() - self.like @ w_log_w) + self.miss_log_miss @ post
        p_no = 1.0 - p_yes
        return p_yes * np.log(p_yes) - yes + p_no * np.log(p_no) - no

    def next_offset(self) -> float | None:
        if self.done:
            return None
        if self._next is None:
            order = np.argsort(self.expected_entropy(), kind="stable")
            pick = (
                order[0]
                if self.choose_from == 1
                else order[int(self.rng.integers(min(self.choose_from, order.size)))]
            )
            self._next = float(self.offsets[pick])
        return self._next

    def update(self, offset_ms: float, positive: bool, correct: bool | None) -> None:
        i = int(np.argmin(np.abs(self.offsets - offset_ms)))
        self.post *= self.like[i] if positive else 1.0 - self.like[i]
        self.post /= self.post.sum()
        self.trials += 1
        self._next = None

    def summary(self) -> dict[str, Any]:
        est = self.estimate()
        return {
            "method": self.kind,
            "trials": self.trials,
            "posterior_mean": est,
            "posterior_sd": {k: self.posterior_sd(k) for k in self.values},
        }
