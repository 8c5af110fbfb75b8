"""Psychometric analysis of study results: maximum-likelihood fits with a lapse rate,
bootstrap confidence intervals, pooling over participants and a PNG plot.

Model (x = audio minus haptic offset in ms, as measured on the presented buffers):

* which_first: P("haptic first") = lapse/2 + (1 - lapse) F((x - mu) / sigma), F the
  cumulative Gaussian (default) or the logistic. PSS = mu (the offset judged "audio
  first" and "haptic first" equally often). JND = the distance from the 50 % to the 75 %
  point of F: sigma * z(0.75) = 0.6745 sigma (Gaussian) or sigma * ln 3 (logistic).
* simultaneous: P("simultaneous") = lapse/2 + (1 - lapse) exp(-(x - mu)^2 / (2 sigma^2)).
  PSS = mu (the peak); JND = the half width at half height, sigma * sqrt(2 ln 2).

The lapse rate (a random answer with probability lapse) is fitted in [0, 0.1]. The
negative log likelihood of the binomial counts per offset is minimised from the best
point of a coarse grid by damped Fisher scoring (all bootstrap samples at once), polished
with scipy.optimize (SLSQP) for the main fit. Confidence intervals are percentile
intervals of a seeded bootstrap: parametric (new responses drawn from the fitted
function at the same offsets; default) or nonparametric (trials resampled with
replacement). Pooling concatenates the trials of all participants; each participant is
also fitted alone.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from scipy.optimize import minimize
from scipy.special import ndtr, ndtri

from jassy.errors import JassyError
from jassy.study.observer import POSITIVE, p_positive

MAX_LAPSE = 0.1


def jnd_factor(question: str, function: str) -> float:
    """JND / sigma for the model (see the module docstring)."""
    if question == "simultaneous":
        return math.sqrt(2.0 * math.log(2.0))
    return float(ndtri(0.75)) if function == "gaussian" else math.log(3.0)


@dataclass
class Fit:
    """A maximum-likelihood fit; *_ci are (low, high) bootstrap percentile intervals."""

    n: int
    pss: float
    sigma: float
    jnd: float
    lapse: float
    nll: float
    pss_ci: tuple[float, float] | None = None
    jnd_ci: tuple[float, float] | None = None
    lapse_ci: tuple[float, float] | None = None
    bootstrap: int = 0
    at_bound: list[str] = field(default_factory=list)

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


def _aggregate(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    levels, inverse = np.unique(x, return_inverse=True)
    n = np.bincount(inverse, minlength=levels.size).astype(float)
    k = np.bincount(inverse, weights=y, minlength=levels.size)
    return levels, k, n


def _model(levels, mu, s, lapse, question, function):
    """p and its gradient wrt (mu, log sigma, lapse); parameters are arrays (B,), levels (L,).

    Returns p (B, L) and dp (B, L, 3)."""
    sigma = np.exp(s)[:, None]
    z = (levels[None, :] - mu[:, None]) / sigma
    lam = lapse[:, None]
    if question == "which_first":
        if function == "gaussian":
            core, dens = ndtr(z), np.exp(-0.5 * z * z) / math.sqrt(2.0 * math.pi)
        else:
            core = 0.5 * (1.0 + np.tanh(0.5 * z))
            dens = core * (1.0 - core)
        dcore_dz = dens
    else:
        core = np.exp(-0.5 * z * z)
        dcore_dz = -z * core
    p = 0.5 * lam + (1.0 - lam) * core
    dp = np.empty(p.shape + (3,))
    dp[..., 0] = -(1.0 - lam) * dcore_dz / sigma
    dp[..., 1] = -(1.0 - lam) * dcore_dz * z
    dp[..., 2] = 0.5 - core
    return p, dp


def _nll_batch(theta, levels, k, n, question, function):
    p, _ = _model(levels, theta[:, 0], theta[:, 1], theta[:, 2], question, function)
    p = np.clip(p, 1e-12, 1.0 - 1e-12)
    return -np.sum(k * np.log(p) + (n - k) * np.log1p(-p), axis=1)


def _nll(theta, levels, k, n, question, function) -> float:
    return float(
        _nll_batch(np.asarray(theta, dtype=float)[None, :], levels, k[None], n[None], question, function)[0]
    )


def _bounds(x: np.ndarray) -> np.ndarray:
    """Rows (low, high) for mu, log sigma, lapse."""
    lo, hi = float(np.min(x)), float(np.max(x))
    span = max(hi - lo, 1.0)
    return np.array(
        [(lo - span, hi + span), (math.log(span * 1e-3), math.log(span * 20.0)), (0.0, MAX_LAPSE)]
    )


def _fit_batch(
    levels, k, n, question, function, bounds, iterations: int = 100
) -> tuple[np.ndarray, np.ndarray]:
    """Maximum likelihood for B count vectors k (B, L) of the same levels at once: the
    best point of a coarse grid, then damped Fisher scoring (Levenberg-Marquardt) within
    the bounds. Returns theta (B, 3) = (mu, log sigma, lapse) and the NLL (B,)."""
    lo_b, hi_b = bounds[:, 0], bounds[:, 1]
    span = max(float(levels.max() - levels.min()), 1.0)
    mus = np.linspace(levels.min() - 0.25 * span, levels.max() + 0.25 * span, 41)
    logs = np.linspace(lo_b[1] + 1.0, hi_b[1] - 0.5, 30)
    lapses = np.array([0.0, 0.02, 0.05, MAX_LAPSE])
    grid = np.stack(np.meshgrid(mus, logs, lapses, indexing="ij"), axis=-1).reshape(-1, 3)
    pg, _ = _model(levels, grid[:, 0], grid[:, 1], grid[:, 2], question, function)
    pg = np.clip(pg, 1e-12, 1.0 - 1e-12)
    table = -(k @ np.log(pg).T + (n - k) @ np.log1p(-pg).T)  # (B, grid)
    theta = grid[np.argmin(table, axis=1)].copy()
    value = _nll_batch(theta, levels, k, n, question, function)
    damping = np.full(theta.shape[0], 1e-3)
    eye = np.eye(3)
    for _ in range(iterations):
        p, dp = _model(levels, theta[:, 0], theta[:, 1], theta[:, 2], question, function)
        p = np.clip(p, 1e-9, 1.0 - 1e-9)
        w = n / (p * (1.0 - p))
        score = np.einsum("bl,blj->bj", (k - n * p) / (p * (1.0 - p)), dp)
        info = np.einsum("bl,bli,blj->bij", w, dp, dp)
        diag = np.einsum("bii->bi", info)
        a = info + (damping[:, None, None] * (diag[:, :, None] * eye + 1e-9 * eye))
        step = np.linalg.solve(a, score[..., None])[..., 0]
        # parameters at a bound whose step points outwards are held there (projected step)
        fixed = ((theta <= lo_b + 1e-12) & (step < 0)) | ((theta >= hi_b - 1e-12) & (step > 0))
        if fixed.any():
            free = (~fixed).astype(float)
            a = a * free[:, :, None] * free[:, None, :] + fixed[:, :, None] * eye
            step = np.linalg.solve(a, (score * free)[..., None])[..., 0]
        trial = np.clip(theta + step, lo_b, hi_b)
        tv = _nll_batch(trial, levels, k, n, question, function)
        better = tv < value - 1e-12
        theta[better], value[better] = trial[better], tv[better]
        damping = np.where(better, np.maximum(damping / 5.0, 1e-9), np.minimum(damping * 10.0, 1e9))
        if np.all(np.abs(step[better]).max(initial=0.0) < 1e-10) and np.all(damping > 1e6):
            break
    return theta, value


def fit_psychometric(
    x: Sequence[float] | np.ndarray,
    y: Sequence[int] | np.ndarray,
    question: str = "which_first",
    function: str = "gaussian",
    bootstrap: int = 1000,
    seed: int = 0,
    method: str = "parametric",
    level: float = 0.95,
) -> Fit:
    """Fit offsets ``x`` (ms) and binary answers ``y`` (1 = "haptic first" or
    "simultaneous") by maximum likelihood; bootstrap CIs if ``bootstrap`` > 0."""
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    if x.size == 0 or x.shape != y.shape:
        raise JassyError("fit: no trials to fit")
    if function not in ("gaussian", "logistic"):
        raise JassyError(f"--function: expected gaussian or logistic, got {function!r}")
    if method not in ("parametric", "nonparametric"):
        raise JassyError(f"--bootstrap-method: expected parametric or nonparametric, got {method!r}")
    levels, k, n = _aggregate(x, y)
    bounds = _bounds(x)
    theta_b, val_b = _fit_batch(levels, k[None], n[None], question, function, bounds)
    theta, val = theta_b[0], float(val_b[0])
    res = minimize(_nll, theta, args=(levels, k, n, question, function), method="SLSQP", bounds=bounds)
    if res.fun < val:  # scipy's polish, when it helps
        theta, val = np.clip(res.x, bounds[:, 0], bounds[:, 1]), float(res.fun)
    factor = jnd_factor(question, function)
    mu, sigma, lapse = float(theta[0]), math.exp(theta[1]), float(theta[2])
    names = ["pss", "sigma"]
    at_bound = [
        names[i]
        for i in range(2)
        if abs(theta[i] - bounds[i, 0]) < 1e-6 or abs(theta[i] - bounds[i, 1]) < 1e-6
    ]
    fit = Fit(int(x.size), mu, sigma, sigma * factor, lapse, val, at_bound=at_bound)
    if bootstrap > 0:
        rng = np.random.default_rng(seed)
        if method == "parametric":
            p_hat = p_positive(levels, mu, sigma, lapse, question, function)
            kb = rng.binomial(np.broadcast_to(n.astype(np.int64), (bootstrap, n.size)), p_hat).astype(float)
            samples, _ = _fit_batch(levels, kb, np.broadcast_to(n, kb.shape), question, function, bounds)
        else:  # resample trials: counts per level from a multinomial draw of trials
            _, inverse = np.unique(x, return_inverse=True)
            picks = rng.integers(0, x.size, (bootstrap, x.size))
            nb_ = np.stack([np.bincount(inverse[r], minlength=levels.size) for r in picks]).astype(float)
            kb = np.stack([np.bincount(inverse[r], weights=y[r], minlength=levels.size) for r in picks])
            samples, _ = _fit_batch(levels, kb, nb_, question, function, bounds)
        alpha = (1.0 - level) / 2.0
        q = [100 * alpha, 100 * (1 - alpha)]
        fit.pss_ci = tuple(float(v) for v in np.percentile(samples[:, 0], q))
        fit.jnd_ci = tuple(float(v) for v in np.percentile(np.exp(samples[:, 1]) * factor, q))
        fit.lapse_ci = tuple(float(v) for v in np.percentile(samples[:, 2], q))
        fit.bootstrap = bootstrap
    return fit


# --------------------------------------------------------------------------- results files
@dataclass
class Dataset:
    """Trials of one or more results files."""

    x: np.ndarray  # offset, ms (measured)
    y: np.ndarray  # 1 = positive answer
    participant: np.ndarray
    question: str
    sources: list[str]


def load_results(paths: Sequence[str | os.PathLike], use: str = "measured") -> Dataset:
    """Read results CSVs (with their JSON sidecars) into one dataset."""
    from jassy.study.runner import read_header, read_rows

    xs, ys, ps = [], [], []
    question = None
    for path in paths:
        if not Path(path).is_file():
            raise JassyError(f"{path}: no such results file")
        header = read_header(path)
        q = header.get("design", {}).get("study", {}).get("question", "which_first")
        if question is not None and q != question:
            raise JassyError(f"{path}: question {q!r} differs from the other files' {question!r}")
        question = q
        rows = read_rows(path)
        for row in rows:
            try:
                xs.append(float(row[f"{use}_ms"]))
            except (KeyError, ValueError):
                raise JassyError(f"{path}: trial {row.get('trial')}: bad {use}_ms value") from None
            ys.append(1.0 if row["response"] == POSITIVE[q] else 0.0)
            ps.append(row["participant"])
    if not xs:
        raise JassyError(f"{', '.join(map(str, paths))}: no trials")
    return Dataset(
        np.array(xs), np.array(ys), np.array(ps), question or "which_first", [str(p) for p in paths]
    )


def analyze(
    paths: Sequence[str | os.PathLike],
    function: str = "gaussian",
    bootstrap: int = 1000,
    seed: int = 0,
    method: str = "parametric",
    use: str = "measured",
) -> dict[str, Any]:
    """Per-participant fits and (with more than one participant) the pooled fit."""
    data = load_results(paths, use)
    report: dict[str, Any] = {
        "question": data.question,
        "function": function,
        "jnd_definition": (
            "half width at half height of the simultaneity curve"
            if data.question == "simultaneous"
            else "distance from the 50% to the 75% point of the psychometric function"
        ),
        "bootstrap": {"samples": bootstrap, "method": method, "seed": seed, "level": 0.95},
        "sources": data.sources,
        "participants": {},
    }
    groups = [(who, data.participant == who) for who in sorted(set(data.participant))]
    if len(groups) > 1:
        groups.append(("pooled", np.ones(data.x.size, dtype=bool)))
    for who, sel in groups:
        fit = fit_psychometric(data.x[sel], data.y[sel], data.question, function, bootstrap, seed, method)
        entry = fit.as_dict()
        entry.update(_proportions(data.x[sel], data.y[sel], data.question))
        if who == "pooled":
            report["pooled"] = entry
        else:
            report["participants"][who] = entry
    report["_data"] = data
    return report


def _proportions(x: np.ndarray, y: np.ndarray, question: str) -> dict[str, Any]:
    """Answers per offset and, for which_first, percent correct with an exact binomial test
    against chance (the 2AFC criterion of the pilot: at chance = asynchrony not perceived)."""
    from scipy.stats import binomtest

    levels, k, n = _aggregate(x, y)
    out: dict[str, Any] = {
        "levels": [
            {"offset_ms": float(v), "trials": int(m), "positive": int(c)}
            for v, c, m in zip(levels, k, n, strict=True)
        ]
    }
    if question == "which_first":
        sel = x != 0
        right = int(np.sum((y[sel] == 1) == (x[sel] > 0)))
        total = int(np.sum(sel))
        if total:
            test = binomtest(right, total, 0.5)
            ci = test.proportion_ci(0.95)
            out["percent_correct"] = 100.0 * right / total
            out["percent_correct_ci"] = (100.0 * ci.low, 100.0 * ci.high)
            out["chance_p_value"] = float(test.pvalue)
    return out


def format_report(report: dict[str, Any]) -> str:
    lines = [
        f"question: {report['question']}, function: {report['function']}; JND = {report['jnd_definition']}",
        f"95% CIs: {report['bootstrap']['method']} bootstrap, {report['bootstrap']['samples']} samples",
        f"{'participant':<14}{'trials':>7}{'PSS ms':>10}{'95% CI':>22}"
        f"{'JND ms':>10}{'95% CI':>22}{'lapse':>8}",
    ]
    rows = list(report["participants"].items())
    if "pooled" in report:
        rows.append(("pooled", report["pooled"]))

    def ci(v):
        return f"[{v[0]:.2f}, {v[1]:.2f}]" if v else "-"

    for who, f in rows:
        note = f"  (at bound: {', '.join(f['at_bound'])})" if f["at_bound"] else ""
        lines.append(
            f"{who:<14}{f['n']:>7}{f['pss']:>10.2f}{ci(f['pss_ci']):>22}{f['jnd']:>10.2f}"
            f"{ci(f['jnd_ci']):>22}{f['lapse']:>8.3f}{note}"
        )
    for who, f in rows:
        if "percent_correct" in f:
            lo, hi = f["percent_correct_ci"]
            lines.append(
                f"{who}: {f['percent_correct']:.1f}% correct (95% CI {lo:.1f}-{hi:.1f}%), "
                f"binomial test against chance p = {f['chance_p_value']:.3g}"
            )
        if len(f["levels"]) < 3:
            lines.append(
                f"{who}: only {len(f['levels'])} offsets: the function's PSS and JND are not identifiable"
            )
    return "\n".join(lines)


def plot_report(report: dict[str, Any], path: str | os.PathLike) -> None:
    """Proportions per offset (marker area ~ trials) and fitted curves, to a PNG."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        raise JassyError("--plot needs matplotlib: pip install 'jassy[plot]'") from None
    data: Dataset = report["_data"]
    q, function = report["question"], report["function"]
    fig, ax = plt.subplots(figsize=(7, 4.5))
    f0 = report.get("pooled") or next(iter(report["participants"].values()))
    ends = [data.x.min(), data.x.max(), *(f0["pss_ci"] or ())]
    span = np.linspace(min(ends), max(ends), 400)
    if span[0] == span[-1]:
        span = np.linspace(span[0] - 1, span[0] + 1, 400)
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    items = list(report["participants"].items())
    for i, (who, f) in enumerate(items):
        c = colors[i % len(colors)]
        sel = data.participant == who
        levels, k, n = _aggregate(data.x[sel], data.y[sel])
        ax.scatter(levels, k / n, s=12 + 60 * n / n.max(), color=c, alpha=0.7, label=f"{who} (n={f['n']})")
        ax.plot(span, p_positive(span, f["pss"], f["sigma"], f["lapse"], q, function), color=c, lw=1.2)
    if "pooled" in report:
        f = report["pooled"]
        ax.plot(
            span,
            p_positive(span, f["pss"], f["sigma"], f["lapse"], q, function),
            color="k",
            lw=2.2,
            label="pooled fit",
        )
    f = report.get("pooled") or items[0][1]
    ax.axvline(f["pss"], color="k", ls="--", lw=0.8)
    if f["pss_ci"]:
        ax.axvspan(*f["pss_ci"], color="0.85", zorder=0, label="PSS 95% CI")
    ax.set_xlabel("audio - haptic onset (ms; negative = audio first)")
    ax.set_ylabel('P("haptic first")' if q == "which_first" else 'P("simultaneous")')
    ax.set_ylim(-0.03, 1.03)
    ax.set_title(f"PSS {f['pss']:.2f} ms, JND {f['jnd']:.2f} ms ({function})")
    ax.legend(fontsize=8, loc="best")
    fig.tight_layout()
    tmp = Path(path).with_name(f".{Path(path).name}.tmp.png")
    fig.savefig(tmp, dpi=120)
    plt.close(fig)
    os.replace(tmp, path)
