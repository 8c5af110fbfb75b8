"""Psychometric models of the study tasks: the probability of the "positive" answer at an
audio-haptic offset x (ms, audio minus haptic onset: negative = audio first).

Every model is a binary-outcome model p(x; theta), vectorised over parameter grids, so the
same code serves the simulated observer, QUEST+ and the likelihood fits. A lapse (rate
``lapse``) is a random answer.

* ``toj`` (temporal-order judgement, "which came first"): P("haptic first") =
  lapse/2 + (1 - lapse) F((x - pss) / sigma), F the cumulative Gaussian or the logistic.
  JND = the distance from the 50 % to the 75 % point of F: 0.6745 sigma (Gaussian) or
  sigma ln 3 (logistic).
* ``sj`` (simultaneity judgement): P("simultaneous") = lapse/2 + (1 - lapse) W(x) with
  W either a Gaussian window exp(-(x - pss)^2 / (2 sigma^2)) (window = its full width at
  half height, 2 sqrt(2 ln 2) sigma) or the difference of two cumulative Gaussians
  Phi((x - pss + window/2) / sigma) - Phi((x - pss - window/2) / sigma): two decision
  boundaries window apart, centred on the PSS, each blurred by sensory noise sigma
  (Yarrow et al. 2011, Conscious. Cogn. 20: 1518).
* ``2afc`` / ``3afc`` (m-interval forced choice: which interval was asynchronous):
  P(correct) = 1/m + (1 - 1/m)(1 - lapse) F(|x|), F(a) = 1 - exp(-ln 2 (a / threshold)^slope)
  a Weibull with F(threshold) = 1/2 (75 % correct in 2AFC without lapses).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from scipy.special import ndtr, ndtri

TASKS = ("toj", "sj", "2afc", "3afc")
FUNCTIONS = {
    "toj": ("gaussian", "logistic"),
    "sj": ("gaussian", "difference"),
    "2afc": ("weibull",),
    "3afc": ("weibull",),
}
LAPSE_GRID = (0.0, 0.01, 0.02, 0.04, 0.07, 0.1)
MAX_LAPSE = 0.1
FWHM = 2.0 * math.sqrt(2.0 * math.log(2.0))


class Param(NamedTuple):
    """A model parameter: name, unit, whether it is a scale (positive, gridded in log)."""

    name: str
    unit: str
    scale: bool


class Model(NamedTuple):
    """A task's psychometric model (see the module docstring)."""

    task: str
    function: str

    @property
    def params(self) -> tuple[Param, ...]:
        if self.task == "toj":
            return (Param("pss", "ms", False), Param("sigma", "ms", True), Param("lapse", "", False))
        if self.task == "sj" and self.function == "difference":
            return (
                Param("pss", "ms", False),
                Param("window", "ms", True),
                Param("sigma", "ms", True),
                Param("lapse", "", False),
            )
        if self.task == "sj":
            return (Param("pss", "ms", False), Param("sigma", "ms", True), Param("lapse", "", False))
        return (Param("threshold", "ms", True), Param("slope", "", True), Param("lapse", "", False))

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.params)

    @property
    def alternatives(self) -> int:
        """Number of response alternatives (intervals for m-AFC, else 2)."""
        return int(self.task[0]) if self.task in ("2afc", "3afc") else 2

    def prob(self, x, **theta) -> np.ndarray:
        """P(positive answer) at offsets x (ms); parameters broadcast against x."""
        x = np.asarray(x, dtype=float)
        lapse = theta["lapse"]
        if self.task == "toj":
            z = (x - theta["pss"]) / theta["sigma"]
            core = ndtr(z) if self.function == "gaussian" else 0.5 * (1.0 + np.tanh(0.5 * z))
            return 0.5 * lapse + (1.0 - lapse) * core
        if self.task == "sj":
            d = x - theta["pss"]
            s = theta["sigma"]
            if self.function == "difference":
                half = 0.5 * theta["window"]
                core = ndtr((d + half) / s) - ndtr((d - half) / s)
            else:
                core = np.exp(-0.5 * (d / s) ** 2)
            return 0.5 * lapse + (1.0 - lapse) * core
        guess = 1.0 / self.alternatives
        a = np.abs(x) / theta["threshold"]
        with np.errstate(over="ignore"):  # a ** slope = inf far above threshold: F = 1 exactly
            core = -np.expm1(-math.log(2.0) * a ** theta["slope"])
        return guess + (1.0 - guess) * (1.0 - lapse) * core

    def derived(self, theta: dict[str, float]) -> dict[str, float]:
        """The reported quantities (JND, window, threshold) from the parameters."""
        if self.task == "toj":
            return {"jnd": theta["sigma"] * jnd_factor(self.function)}
        if self.task == "sj" and self.function == "gaussian":
            return {"window": theta["sigma"] * FWHM}
        return {}

    def reported(self) -> tuple[str, ...]:
        """Names of the quantities a report gives (parameters and derived), in order."""
        if self.task == "toj":
            return ("pss", "jnd", "sigma", "lapse")
        if self.task == "sj" and self.function == "gaussian":
            return ("pss", "window", "sigma", "lapse")
        return self.names


def jnd_factor(function: str) -> float:
    """JND / sigma of a TOJ model: z(0.75) for the Gaussian, ln 3 for the logistic."""
    return float(ndtri(0.75)) if function == "gaussian" else math.log(3.0)


def derived_from(model: Model, name: str, param_value: float) -> tuple[str, float] | None:
    """(derived name, value) for a monotone function of one parameter (e.g. sigma -> jnd)."""
    if model.task == "toj" and name == "sigma":
        return "jnd", param_value * jnd_factor(model.function)
    if model.task == "sj" and model.function == "gaussian" and name == "sigma":
        return "window", param_value * FWHM
    return None


def make_model(task: str, function: str | None = None) -> Model:
    """The model of ``task`` (default function: the first of FUNCTIONS[task])."""
    if task not in TASKS:
        raise ValueError(f"task: expected one of {', '.join(TASKS)}, got {task!r}")
    function = function or FUNCTIONS[task][0]
    if function not in FUNCTIONS[task]:
        raise ValueError(
            f"function: expected one of {', '.join(FUNCTIONS[task])} for {task}, got {function!r}"
        )
    return Model(task, function)
