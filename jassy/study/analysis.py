"""Analysis of study results: per condition, per participant, pooled and group fits,
intervals only where the design identifies the parameters, plots and exports.

For every condition (a combination of the design's factor levels) each participant is
fitted alone (:func:`jassy.study.fitting.fit`: maximum likelihood, 95 % profile-likelihood
intervals, "not identifiable" where the data do not constrain a parameter). With several
participants two group estimates follow:

* ``pooled``: one fit of all participants' trials together (a fixed-effects fit: it
  ignores differences between observers and so understates the group's spread);
* ``group``: the two-stage random-effects estimate, the mean of the per-participant
  estimates with a t interval from their spread (participants whose estimate is not
  identifiable are left out and counted).

For TOJ designs with two offsets (like the pilot) the report adds percent correct with an
exact binomial test against chance, the criterion such a design can support.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from jassy.errors import JassyError
from jassy.study.fitting import FitResult, aggregate, fit
from jassy.study.models import FUNCTIONS, make_model


class Dataset(NamedTuple):
    """Analysed trials (practice excluded) of one or more results files."""

    x: np.ndarray  # offset, ms (measured; magnitude for m-AFC)
    y: np.ndarray  # 1 = positive answer
    participant: np.ndarray
    condition: np.ndarray  # condition label
    task: str
    function: str
    sources: list[str]


def load_results(paths: Sequence[str | os.PathLike], use: str = "measured") -> Dataset:
    """Read results CSVs (with their JSON sidecars) into one dataset."""
    from jassy.study.runner import CORE_COLUMNS, TRIAL_COLUMNS, read_header, read_rows

    fixed = set(CORE_COLUMNS + TRIAL_COLUMNS)
    xs, ys, ps, cs = [], [], [], []
    task = function = None
    paths = [p for p in paths if not str(p).endswith(("_summary.csv", "_fits.csv"))]  # outputs of ours
    for path in paths:
        if not Path(path).is_file():
            raise JassyError(f"{path}: no such results file")
        header = read_header(path)
        t, f = header.get("task"), header.get("function")
        if t is None:
            raise JassyError(f"{path}: no JSON sidecar with the task ({Path(path).with_suffix('.json')})")
        if task is not None and (t, f) != (task, function):
            raise JassyError(f"{path}: task {t}/{f} differs from the other files' {task}/{function}")
        task, function = t, f
        # the leading modality is the sign of a TOJ/SJ offset, not a condition of its function
        sign_only = {"leading"} if task in ("toj", "sj") else set()
        factors = [c for c in header.get("columns", []) if c not in fixed and c not in sign_only]
        for row in read_rows(path):
            if row["practice"] != "0":
                continue
            try:
                x = float(row[f"{use}_ms"])
            except (KeyError, ValueError):
                raise JassyError(f"{path}: trial {row.get('trial')}: bad {use}_ms value") from None
            xs.append(abs(x) if task in ("2afc", "3afc") else x)
            ys.append(1.0 if row["positive"] == "1" else 0.0)
            ps.append(row["participant"])
            cs.append(" ".join(f"{k}={row[k]}" for k in factors) or "all")
    if not xs:
        raise JassyError(f"{', '.join(map(str, paths))}: no trials (practice trials are not analysed)")
    return Dataset(
        np.array(xs), np.array(ys), np.array(ps), np.array(cs), task, function, [str(p) for p in paths]
    )


def group_estimate(values: list[float], level: float = 0.95) -> dict[str, Any]:
    """Mean of per-participant estimates with a t interval (two-stage random effects)."""
    from scipy.stats import t as student

    v = np.asarray(values, dtype=float)
    if v.size < 2:
        return {"value": float(v.mean()) if v.size else None, "ci95": None, "participants": int(v.size)}
    half = float(student.ppf(0.5 + level / 2, v.size - 1) * v.std(ddof=1) / math.sqrt(v.size))
    m = float(v.mean())
    return {"value": m, "ci95": [m - half, m + half], "participants": int(v.size)}


def analyze(
    paths: Sequence[str | os.PathLike], function: str | None = None, use: str = "measured"
) -> dict[str, Any]:
    """Fits per condition: each participant, pooled and group (see the module docstring)."""
    data = load_results(paths, use)
    function = function or data.function
    if function not in FUNCTIONS[data.task]:
        raise JassyError(
            f"--function: expected one of {', '.join(FUNCTIONS[data.task])} for {data.task}, got {function!r}"
        )
    model = make_model(data.task, function)
    report: dict[str, Any] = {
        "task": data.task,
        "function": function,
        "intervals": "95% profile likelihood; 'not identifiable' where the data do not bound a parameter",
        "sources": data.sources,
        "conditions": {},
    }
    for label in dict.fromkeys(data.condition):
        in_cond = data.condition == label
        entry: dict[str, Any] = {"participants": {}}
        who_list = sorted(set(data.participant[in_cond]))
        fits: dict[str, FitResult] = {}
        for who in who_list:
            sel = in_cond & (data.participant == who)
            fits[who] = fit(model, data.x[sel], data.y[sel])
            entry["participants"][who] = {
                **fits[who].as_dict(),
                **_proportions(data.x[sel], data.y[sel], data.task),
            }
        if len(who_list) > 1:
            pooled = fit(model, data.x[in_cond], data.y[in_cond])
            entry["pooled"] = {
                **pooled.as_dict(),
                **_proportions(data.x[in_cond], data.y[in_cond], data.task),
            }
            entry["group"] = {}
            for name in model.reported():
                if name == "lapse":
                    continue
                ok = [f.estimates[name].value for f in fits.values() if f.estimates[name].identifiable]
                entry["group"][name] = {**group_estimate(ok), "not_identifiable": len(fits) - len(ok)}
        report["conditions"][label] = entry
    report["_data"] = data
    return report


def _proportions(x: np.ndarray, y: np.ndarray, task: str) -> dict[str, Any]:
    """Answers per offset and, for TOJ, percent correct with an exact binomial test
    against chance (the criterion of a two-offset design like the pilot)."""
    from scipy.stats import binomtest

    levels, k, n = aggregate(x, y)
    out: dict[str, Any] = {
        "levels": [
            {"offset_ms": float(v), "trials": int(m), "positive": int(c)}
            for v, c, m in zip(levels, k, n, strict=True)
        ]
    }
    if task == "toj":
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


def _quantities(report: dict[str, Any]) -> list[str]:
    return [n for n in make_model(report["task"], report["function"]).reported() if n != "lapse"]


def _cell(e: dict[str, Any]) -> str:
    if not e["identifiable"]:
        return "not identifiable"
    return f"{e['value']:.2f} [{e['ci95'][0]:.2f}, {e['ci95'][1]:.2f}]"


def format_report(report: dict[str, Any]) -> str:
    names = _quantities(report)
    lines = [f"task {report['task']}, model {report['function']}; intervals: {report['intervals']}"]
    for label, entry in report["conditions"].items():
        lines.append(f"condition {label}")
        lines.append(
            f"  {'who':<12}{'trials':>7}" + "".join(f"{n + ' ms' if n != 'slope' else n:>28}" for n in names)
        )
        rows = list(entry["participants"].items())
        if "pooled" in entry:
            rows.append(("pooled", entry["pooled"]))
        for who, f in rows:
            lines.append(f"  {who:<12}{f['trials']:>7}" + "".join(f"{_cell(f[n]):>28}" for n in names))
        if "group" in entry:
            cells = []
            for n in names:
                g = entry["group"][n]
                if g["ci95"] is None:
                    cells.append("too few identifiable")
                else:
                    cells.append(f"{g['value']:.2f} [{g['ci95'][0]:.2f}, {g['ci95'][1]:.2f}]")
            lines.append(f"  {'group':<12}{'':>7}" + "".join(f"{c:>28}" for c in cells))
            lost = {
                n: entry["group"][n]["not_identifiable"]
                for n in names
                if entry["group"][n]["not_identifiable"]
            }
            if lost:
                lines.append(f"  group: left out as not identifiable: {lost}")
        for who, f in rows:
            if "percent_correct" in f:
                lo, hi = f["percent_correct_ci"]
                lines.append(
                    f"  {who}: {f['percent_correct']:.1f}% correct (95% CI {lo:.1f}-{hi:.1f}%), "
                    f"binomial test against chance p = {f['chance_p_value']:.3g}"
                )
    return "\n".join(lines)


def export_fits(report: dict[str, Any], prefix: str | os.PathLike) -> tuple[Path, Path]:
    """PREFIX_fits.csv (one row per condition and fit) and PREFIX_fits.json, atomically."""
    from jassy.study.runner import write_text_atomic

    names = _quantities(report) + ["lapse"]
    head = ["condition", "who", "trials"]
    for n in names:
        head += [n, f"{n}_low", f"{n}_high", f"{n}_identifiable"]
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(head)
    for label, entry in report["conditions"].items():
        rows = list(entry["participants"].items()) + (
            [("pooled", entry["pooled"])] if "pooled" in entry else []
        )
        for who, f in rows:
            line = [label, who, f["trials"]]
            for n in names:
                e = f[n]
                ci = e["ci95"] or ["", ""]
                line += [f"{e['value']:.6g}" if e["identifiable"] else "", *ci, int(e["identifiable"])]
            w.writerow(line)
        if "group" in entry:
            line = [label, "group", ""]
            for n in names:
                g = entry["group"].get(n)
                if g is None or g["ci95"] is None:
                    line += ["", "", "", 0]
                else:
                    line += [f"{g['value']:.6g}", *g["ci95"], 1]
            w.writerow(line)
    base = Path(prefix)
    csv_path = base.with_name(base.name + "_fits.csv")
    json_path = base.with_name(base.name + "_fits.json")
    write_text_atomic(csv_path, buf.getvalue())
    clean = {k: v for k, v in report.items() if k != "_data"}
    write_text_atomic(json_path, json.dumps(clean, indent=2) + "\n")
    return csv_path, json_path


def plot_report(report: dict[str, Any], path: str | os.PathLike) -> None:
    """One panel per condition: proportions per offset (marker area ~ trials) and the
    fitted curves of each participant and the pooled fit, to a PNG."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        raise JassyError("--plot needs matplotlib: pip install 'jassy[plot]'") from None
    data: Dataset = report["_data"]
    model = make_model(report["task"], report["function"])
    labels = list(report["conditions"])
    cols = min(len(labels), 2)
    rows = math.ceil(len(labels) / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(5.2 * cols, 3.6 * rows), squeeze=False)
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    span = np.linspace(data.x.min(), data.x.max(), 400)
    if span[0] == span[-1]:
        span = np.linspace(span[0] - 1, span[0] + 1, 400)
    for ax, label in zip(axes.ravel(), labels, strict=False):
        entry = report["conditions"][label]
        for i, (who, f) in enumerate(entry["participants"].items()):
            c = colors[i % len(colors)]
            sel = (data.condition == label) & (data.participant == who)
            levels, k, n = aggregate(data.x[sel], data.y[sel])
            ax.scatter(levels, k / n, s=8 + 40 * n / n.max(), color=c, alpha=0.6)
            if all(f[p.name]["identifiable"] for p in model.params):
                theta = {p.name: f[p.name]["value"] for p in model.params}
                ax.plot(span, model.prob(span, **theta), color=c, lw=1.0, label=who)
            else:
                ax.plot([], [], color=c, lw=1.0, ls=":", label=f"{who} (not identifiable)")
        f = entry.get("pooled")
        if f and all(f[p.name]["identifiable"] for p in model.params):
            theta = {p.name: f[p.name]["value"] for p in model.params}
            ax.plot(span, model.prob(span, **theta), color="k", lw=2.0, label="pooled")
        ax.set_title(label, fontsize=9)
        ax.set_ylim(-0.03, 1.03)
        ax.set_xlabel(
            "|offset| (ms)"
            if model.task in ("2afc", "3afc")
            else "audio - haptic onset (ms; < 0 audio first)"
        )
        ax.set_ylabel({"toj": 'P("haptic first")', "sj": 'P("simultaneous")'}.get(model.task, "P(correct)"))
        ax.legend(fontsize=7, loc="best")
    for ax in axes.ravel()[len(labels) :]:
        ax.set_visible(False)
    fig.tight_layout()
    tmp = Path(path).with_name(f".{Path(path).name}.tmp.png")
    fig.savefig(tmp, dpi=90)
    plt.close(fig)
    os.replace(tmp, path)
