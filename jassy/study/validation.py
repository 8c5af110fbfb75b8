"""Coverage study: do the fitted 95 % intervals contain the simulated observers' truth?

Each simulated participant draws true parameters from a population, answers a full
session of a method (constant stimuli or QUEST+; offsets rounded to whole samples at
48 kHz, as presented), and is fitted by :func:`jassy.study.fitting.fit`. A method/task
passes when the truth is inside the 95 % interval in at least 90 % of the participants
for each reported quantity (a non-identifiable fit counts as a miss). The QUEST+ runs
are also fitted after every ``step`` trials to find how many trials QUEST+ needs to reach
the median JND (TOJ) or window (SJ) interval width that constant stimuli reach with all
of theirs.

``jassy study coverage`` runs the full study (50 participants per row); the tests run a
smaller one.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from jassy.study.fitting import fit
from jassy.study.methods import ConstantTrack, QuestPlusTrack, quest_plus_grid
from jassy.study.models import Model, make_model

SAMPLE_RATE = 48000


class Scenario(NamedTuple):
    """A task with its population of observers and its designs."""

    model: Model
    population: dict[str, tuple[float, float]]  # name -> uniform (low, high)
    constant_offsets: tuple[float, ...]
    repetitions: int
    quest_offsets: tuple[float, ...]
    precision: str  # the quantity whose interval width is compared
    quest_plus: bool = True  # run QUEST+ too (4-parameter grids make it slow)


SCENARIOS = {
    "toj": Scenario(
        make_model("toj", "gaussian"),
        {"pss": (-30.0, 30.0), "sigma": (20.0, 50.0), "lapse": (0.0, 0.04)},
        (-200.0, -120.0, -80.0, -40.0, -20.0, 0.0, 20.0, 40.0, 80.0, 120.0, 200.0),
        16,
        tuple(np.arange(-200.0, 201.0, 10.0)),
        "jnd",
    ),
    "sj": Scenario(
        make_model("sj", "gaussian"),
        {"pss": (-20.0, 50.0), "sigma": (50.0, 110.0), "lapse": (0.0, 0.04)},
        (-400.0, -300.0, -200.0, -150.0, -100.0, -50.0, 0.0, 50.0, 100.0, 150.0, 200.0, 300.0, 400.0),
        14,
        tuple(np.arange(-400.0, 401.0, 20.0)),
        "window",
    ),
    "sj_difference": Scenario(
        make_model("sj", "difference"),
        {"pss": (-20.0, 50.0), "window": (100.0, 250.0), "sigma": (15.0, 40.0), "lapse": (0.0, 0.04)},
        (-400.0, -300.0, -200.0, -150.0, -100.0, -50.0, 0.0, 50.0, 100.0, 150.0, 200.0, 300.0, 400.0),
        14,
        (),
        "window",
        quest_plus=False,
    ),
}


class ParticipantRun(NamedTuple):
    truth: dict[str, float]
    offsets: np.ndarray
    answers: np.ndarray


def _truth(s: Scenario, rng: np.random.Generator) -> dict[str, float]:
    theta = {k: float(rng.uniform(*v)) for k, v in s.population.items()}
    theta.update(s.model.derived(theta))
    return theta


def _run(track, model: Model, theta: dict[str, float], rng: np.random.Generator) -> ParticipantRun:
    params = {p.name: theta[p.name] for p in model.params}
    xs, ys = [], []
    while (offset := track.next_offset()) is not None:
        x = round(offset * SAMPLE_RATE / 1000.0) * 1000.0 / SAMPLE_RATE
        positive = bool(rng.random() < model.prob(x, **params))
        track.update(offset, positive, None)
        xs.append(x)
        ys.append(positive)
    return ParticipantRun(theta, np.array(xs), np.array(ys, dtype=float))


def simulate(
    task: str, method: str, participants: int, seed: int, quest_trials: int = 200
) -> list[ParticipantRun]:
    """Sessions of ``participants`` simulated observers (seeded)."""
    s = SCENARIOS[task]
    runs = []
    for child in np.random.SeedSequence([seed, 0 if method == "constant" else 1]).spawn(participants):
        rng = np.random.default_rng(child)
        theta = _truth(s, rng)
        if method == "constant":
            track = ConstantTrack("c", s.constant_offsets, s.repetitions, rng)
        else:
            offsets = np.asarray(s.quest_offsets)
            track = QuestPlusTrack(
                "q", s.model, offsets, quest_plus_grid(s.model, offsets), quest_trials, rng
            )
        runs.append(_run(track, s.model, theta, rng))
    return runs


class CoverageRow(NamedTuple):
    task: str
    method: str
    participants: int
    trials: int
    covered: dict[str, int]  # quantity -> participants whose interval holds the truth
    not_identifiable: int
    median_width: float  # of the precision quantity's interval, ms


def coverage(task: str, method: str, runs: list[ParticipantRun], trials: int | None = None) -> CoverageRow:
    """Count intervals holding the truth, fitting the first ``trials`` trials of each run."""
    s = SCENARIOS[task]
    names = [n for n in s.model.reported() if n != "lapse"]
    covered = dict.fromkeys(names, 0)
    lost = 0
    widths = []
    for run in runs:
        n = run.offsets.size if trials is None else trials
        result = fit(s.model, run.offsets[:n], run.answers[:n])
        if not all(result.estimates[k].identifiable for k in names):
            lost += 1
        for k in names:
            e = result.estimates[k]
            if e.identifiable and e.low <= run.truth[k] <= e.high:
                covered[k] += 1
        e = result.estimates[s.precision]
        widths.append(e.high - e.low if e.identifiable else np.inf)
    n_trials = int(np.median([r.offsets.size for r in runs])) if trials is None else trials
    return CoverageRow(task, method, len(runs), n_trials, covered, lost, float(np.median(widths)))


def trials_for_precision(
    task: str, runs: list[ParticipantRun], width: float, step: int = 10
) -> tuple[int | None, list[tuple[int, float]]]:
    """The fewest QUEST+ trials (a multiple of ``step``) whose median interval width of the
    precision quantity is at most ``width``; and the (trials, median width) curve."""
    curve = []
    longest = min(r.offsets.size for r in runs)
    for n in range(step * 2, longest + 1, step):
        curve.append((n, coverage(task, "quest_plus", runs, n).median_width))
    needed = next((n for n, w in curve if w <= width), None)
    return needed, curve


def run_coverage(
    participants: int = 50, seed: int = 1, quest_trials: int = 200, plot: str | None = None
) -> str:
    """The coverage table (Markdown): TOJ and SJ (Gaussian window) with constant stimuli and
    QUEST+, SJ (difference of cumulative Gaussians) with constant stimuli; the QUEST+ trials
    needed for the constant-stimuli interval width; optionally a plot of that width."""
    lines = [
        "| task | method | participants | trials | truth inside 95 % interval | not identifiable "
        "| median width |",
        "|---|---|---|---|---|---|---|",
    ]
    notes, curves = [], {}
    for task in SCENARIOS:
        s = SCENARIOS[task]
        const = coverage(task, "constant", simulate(task, "constant", participants, seed))
        rows = [const]
        if s.quest_plus:
            quest_runs = simulate(task, "quest_plus", participants, seed, quest_trials)
            rows.append(coverage(task, "quest_plus", quest_runs))
        for row in rows:
            inside = ", ".join(f"{k} {100 * v / row.participants:.0f} %" for k, v in row.covered.items())
            lines.append(
                f"| {task} | {row.method} | {row.participants} | {row.trials} | {inside} "
                f"| {row.not_identifiable} | {s.precision} {row.median_width:.1f} ms |"
            )
        if not s.quest_plus:
            continue
        needed, curve = trials_for_precision(task, quest_runs, const.median_width)
        curves[task] = (curve, const)
        notes.append(
            f"{task}: QUEST+ reaches the median {s.precision} interval width of constant stimuli "
            f"({const.median_width:.1f} ms with {const.trials} trials) after "
            + (f"{needed} trials" if needed else f"more than {quest_trials} trials")
        )
    if plot:
        _plot_curves(curves, plot)
    return "\n".join(lines + [""] + notes)


def _plot_curves(curves: dict, path: str) -> None:
    import os
    from pathlib import Path

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(curves), figsize=(4.2 * len(curves), 3.0), squeeze=False)
    for ax, (task, (curve, const)) in zip(axes[0], curves.items(), strict=True):
        n, w = zip(*curve, strict=True)
        ax.plot(n, w, "o-", ms=3, label="QUEST+")
        ax.plot([const.trials], [const.median_width], "s", color="k", label="constant stimuli")
        ax.axhline(const.median_width, color="k", lw=0.6, ls="--")
        ax.set_xlabel("trials")
        ax.set_ylabel(f"median 95 % width of {SCENARIOS[task].precision} (ms)")
        ax.set_title(task.upper(), fontsize=9)
        ax.legend(fontsize=7)
    fig.tight_layout()
    tmp = Path(path).with_name(f".{Path(path).name}.tmp.png")
    fig.savefig(tmp, dpi=70)
    plt.close(fig)
    os.replace(tmp, path)
