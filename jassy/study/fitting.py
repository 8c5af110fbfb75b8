"""Maximum-likelihood fits with profile-likelihood intervals and an identifiability check.

The binomial log likelihood of a :class:`~jassy.study.models.Model` is evaluated on a
parameter grid (scale parameters in log, the lapse rate on a few values in [0, 0.1]).
For each parameter the *profile* likelihood (the maximum over the others) gives the 95 %
interval {theta_i : 2 (l_max - l_profile(theta_i)) < 3.84} (chi-square, 1 degree of
freedom; Venzon & Moolgavkar 1988). A first, wide grid (location over the tested offsets
extended by their span on each side; scales from span/200 to 4 spans) decides
identifiability: a parameter whose interval reaches the edge of that grid is not
constrained by the data (the design cannot identify it), and no interval is reported for
it. A second grid, spanning the joint 95 % region of the first with one step to spare,
resolves the intervals (interpolated where the profile crosses the threshold), and the
point estimate is polished by scipy (Nelder-Mead) from the best grid point. The
intervals are likelihood based, so they hold for adaptive designs too (the likelihood
does not depend on how the offsets were chosen).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from scipy.optimize import minimize

from jassy.study.models import LAPSE_GRID, MAX_LAPSE, Model, derived_from

CHI2_95 = 3.841458820694124  # 95 % point of chi-square with 1 degree of freedom


class Estimate(NamedTuple):
    """One fitted quantity: maximum-likelihood value and 95 % interval (None when the
    quantity is not identifiable from the data)."""

    value: float
    low: float | None
    high: float | None
    identifiable: bool


class FitResult(NamedTuple):
    """A fit: the model, trials, log likelihood and an Estimate per reported quantity."""

    task: str
    function: str
    trials: int
    loglik: float
    estimates: dict[str, Estimate]

    def as_dict(self) -> dict:
        return {
            "task": self.task,
            "function": self.function,
            "trials": self.trials,
            "loglik": self.loglik,
            **{
                name: {
                    "value": e.value,
                    "ci95": None if e.low is None else [e.low, e.high],
                    "identifiable": e.identifiable,
                }
                for name, e in self.estimates.items()
            },
        }


def aggregate(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Distinct offsets, positive answers and trials at each."""
    levels, inverse = np.unique(np.asarray(x, dtype=float), return_inverse=True)
    n = np.bincount(inverse, minlength=levels.size).astype(float)
    k = np.bincount(inverse, weights=np.asarray(y, dtype=float), minlength=levels.size)
    return levels, k, n


def wide_ranges(model: Model, levels: np.ndarray) -> dict[str, tuple[float, float]]:
    """The identifiability grid's range per parameter (log10-free: scale ranges in ms)."""
    mags = np.abs(levels) if model.task in ("2afc", "3afc") else levels
    lo, hi = float(mags.min()), float(mags.max())
    span = max(hi - lo, float(np.max(np.abs(levels))), 1e-3)
    out = {}
    for p in model.params:
        if p.name == "lapse":
            continue
        if p.name == "pss":
            out[p.name] = (lo - span, hi + span)
        elif p.name == "slope":
            out[p.name] = (0.3, 20.0)
        elif p.name == "threshold":
            out[p.name] = (max(hi, 1e-3) / 200.0, 4.0 * max(hi, 1e-3))
        elif p.name == "window":
            out[p.name] = (span / 100.0, 4.0 * span)
        else:
            out[p.name] = (span / 200.0, 4.0 * span)
    return out


def _axes(
    model: Model, ranges: dict[str, tuple[float, float]], points: int, fine: bool = False
) -> list[np.ndarray]:
    """Grid axes: ``points`` per parameter over ``ranges`` (log spaced for scales); the
    lapse rate on LAPSE_GRID, or every 0.01 in [0, MAX_LAPSE] when ``fine``."""
    axes = []
    for p in model.params:
        if p.name == "lapse":
            axes.append(np.linspace(0.0, MAX_LAPSE, 11) if fine else np.asarray(LAPSE_GRID))
        elif p.scale:
            lo, hi = ranges[p.name]
            axes.append(np.geomspace(lo, hi, points))
        else:
            axes.append(np.linspace(*ranges[p.name], points))
    return axes


def loglik_grid(model: Model, axes: list[np.ndarray], levels, k, n) -> np.ndarray:
    """Binomial log likelihood on the grid spanned by ``axes`` (one dimension each)."""
    d = len(axes)
    theta = {
        p.name: a.reshape([-1 if i == j else 1 for j in range(d)] + [1])
        for i, (p, a) in enumerate(zip(model.params, axes, strict=True))
    }
    p = np.clip(model.prob(levels, **theta), 1e-12, 1.0 - 1e-12)
    return np.sum(k * np.log(p) + (n - k) * np.log1p(-p), axis=-1)


def _profile(ll: np.ndarray, i: int) -> np.ndarray:
    """The profile log likelihood along axis i: the maximum over the other axes."""
    return np.max(ll, axis=tuple(j for j in range(ll.ndim) if j != i))


def _crossing(axis: np.ndarray, prof: np.ndarray, cut: float, scale: bool) -> tuple[float, float]:
    """Ends of {prof >= cut}, linearly interpolated between grid points (in log for scales)."""
    t = np.log(axis) if scale else axis
    inside = np.flatnonzero(prof >= cut)
    a, b = inside[0], inside[-1]

    def interp(i_in, i_out):
        if i_out < 0 or i_out >= t.size:
            return t[i_in]
        f = (prof[i_in] - cut) / (prof[i_in] - prof[i_out])
        return t[i_in] + f * (t[i_out] - t[i_in])

    low, high = interp(a, a - 1), interp(b, b + 1)
    return (math.exp(low), math.exp(high)) if scale else (float(low), float(high))


def _nll_factory(model: Model, levels, k, n):
    def unpack(v):
        theta = {}
        for p, value in zip(model.params, v, strict=True):
            theta[p.name] = math.exp(value) if p.scale else value
        theta["lapse"] = min(max(theta["lapse"], 0.0), MAX_LAPSE)
        return theta

    def nll(v):
        p = np.clip(model.prob(levels, **unpack(v)), 1e-12, 1.0 - 1e-12)
        return -float(np.sum(k * np.log(p) + (n - k) * np.log1p(-p)))

    return nll, unpack


def _polish(model: Model, levels, k, n, axes, ll, ranges) -> tuple[dict[str, float], float]:
    """The likelihood maximum: Nelder-Mead from the best grid point, kept only if it stays
    within ``ranges`` and beats the grid."""
    best = np.unravel_index(np.argmax(ll), ll.shape)
    grid_theta = {p.name: float(a[j]) for p, a, j in zip(model.params, axes, best, strict=True)}
    start = [math.log(grid_theta[p.name]) if p.scale else grid_theta[p.name] for p in model.params]
    nll, unpack = _nll_factory(model, levels, k, n)
    res = minimize(nll, start, method="Nelder-Mead", options={"xatol": 1e-5, "fatol": 1e-8, "maxiter": 2000})
    polished = unpack(res.x)
    inside = all(ranges[name][0] <= polished[name] <= ranges[name][1] for name in ranges)
    if inside and -res.fun >= ll.max():
        return polished, float(-res.fun)
    return grid_theta, float(ll.max())


def fit(model: Model, x, y, points: int = 31) -> FitResult:
    """Fit ``model`` to offsets ``x`` (ms) and binary answers ``y`` (1 = positive)."""
    levels, k, n = aggregate(x, y)
    ranges = wide_ranges(model, levels)
    axes = _axes(model, ranges, points)
    ll = loglik_grid(model, axes, levels, k, n)
    theta, top = _polish(model, levels, k, n, axes, ll, ranges)
    cut = top - CHI2_95 / 2.0
    identifiable, box = {}, dict(ranges)
    for i, p in enumerate(model.params):
        if p.name == "lapse":
            continue
        prof = _profile(ll, i)
        identifiable[p.name] = bool(prof[0] < cut and prof[-1] < cut)
        if identifiable[p.name]:  # the cells within the cut and the optimum's, one step to spare
            cells = [*np.flatnonzero(prof >= cut), int(np.searchsorted(axes[i], theta[p.name]))]
            lo, hi = max(min(cells) - 1, 0), min(max(cells) + 1, axes[i].size - 1)
            box[p.name] = (axes[i][lo], axes[i][hi])
    fine_points = 31 if len(model.params) <= 3 else 21  # 4 parameters: 21^3 x 11 points
    for _ in range(6):  # refine; widen a box whose interval reaches its side
        axes = _axes(model, box, fine_points, fine=True)
        ll = loglik_grid(model, axes, levels, k, n)
        if ll.max() > top:
            theta, top = _polish(model, levels, k, n, axes, ll, box)
        cut = top - CHI2_95 / 2.0
        grown = False
        for i, p in enumerate(model.params):
            if not identifiable.get(p.name):
                continue
            prof = _profile(ll, i)
            lo, hi = box[p.name]
            wide_lo, wide_hi = ranges[p.name]
            step = (math.log(hi / lo) if p.scale else hi - lo) / 2.0
            if prof[0] >= cut and lo > wide_lo:
                lo = max(lo * math.exp(-step) if p.scale else lo - step, wide_lo)
                grown = True
            if prof[-1] >= cut and hi < wide_hi:
                hi = min(hi * math.exp(step) if p.scale else hi + step, wide_hi)
                grown = True
            box[p.name] = (lo, hi)
        if not grown:
            tight = {}  # then once more on boxes just around the intervals: finer steps
            for i, p in enumerate(model.params):
                if identifiable.get(p.name) and _profile(ll, i).max() >= cut:
                    low, high = _crossing(axes[i], _profile(ll, i), cut, p.scale)
                    lo, hi = (math.log(low), math.log(high)) if p.scale else (low, high)
                    pad = 0.15 * (hi - lo) + 1e-9
                    lo, hi = (math.exp(lo - pad), math.exp(hi + pad)) if p.scale else (lo - pad, hi + pad)
                    tight[p.name] = (max(lo, ranges[p.name][0]), min(hi, ranges[p.name][1]))
            if tight and tight != box:
                box.update(tight)
                axes = _axes(model, box, fine_points, fine=True)
                ll = loglik_grid(model, axes, levels, k, n)
                if ll.max() > top:
                    theta, top = _polish(model, levels, k, n, axes, ll, box)
                cut = top - CHI2_95 / 2.0
            break
    for i, p in enumerate(model.params):  # an interval still open at the wide range's edge
        if identifiable.get(p.name):
            prof = _profile(ll, i)
            at_edge = (prof[0] >= cut and box[p.name][0] <= ranges[p.name][0]) or (
                prof[-1] >= cut and box[p.name][1] >= ranges[p.name][1]
            )
            identifiable[p.name] = not at_edge
    estimates: dict[str, Estimate] = {}
    for i, p in enumerate(model.params):
        value = float(theta[p.name])
        if p.name == "lapse":
            estimates[p.name] = Estimate(value, None, None, True)
            continue
        ok = identifiable[p.name]
        prof = _profile(ll, i)
        # a grid too coarse in a partner parameter may stay below the cut: use its own peak
        level = cut if prof.max() >= cut else prof.max() - CHI2_95 / 2.0
        low, high = _crossing(axes[i], prof, level, p.scale) if ok else (None, None)
        if ok:  # the polished optimum lies inside its own interval
            low, high = min(low, value), max(high, value)
        estimates[p.name] = Estimate(value, low, high, ok)
        extra = derived_from(model, p.name, 1.0)
        if extra is not None:
            factor = extra[1]
            estimates[extra[0]] = Estimate(
                value * factor,
                None if low is None else low * factor,
                None if high is None else high * factor,
                ok,
            )
    order = model.reported()
    estimates = {name: estimates[name] for name in order if name in estimates}
    return FitResult(model.task, model.function, int(np.sum(n)), float(top), estimates)
