"""``jassy bench anytime``: error and CPU time of budgeted synthesis against the full bank.

For each scene (the ``bell`` and ``scrape`` patches and the ``wok`` scene's sound graph),
renders the full synthesis and budgets of 10, 25, 50 and 100 % of the graph's modes, at
48 kHz in blocks of 4096 frames, node by node (the budget splits a sub-block where it
decides).

- error: 10 log10 of the energy of (budgeted - full) over the energy of full, on the
  rendered audio (dB; exact synthesis gives about -300 dB);
- CPU: thread CPU time spent rendering the ModalBanks (their ``process``) plus the
  budget's steps (its bookkeeping, its render of the banks and its decisions) plus the
  budget's set-up at the start of the render (:meth:`jassy.anytime.ModeBudget.attach`:
  its tables, the score's impacts listed and loaded; the full render does none of it and
  every budgeted render pays it), divided by the CPU time of the ModalBanks of the full
  render (which skip silent modes); the best of ``repeats`` runs of each, interleaved in
  the same process. Excluded on both sides: the banks' own preparation, a process's
  first load of the compiled entry points, and the per-process caches a one-shot render
  would fill (the periodogram's window and twiddles);
- render: the same without the set-up (the steady state); set-up: the set-up alone;
  "decisions": the share of the decisions taken in Python (importance, ranking, kept
  sets, impacts and periodograms; those the compiled step takes itself count with the
  step);
- mode-samples: the modes computed per sample (active at the end of each span a bank
  renders), summed, over the full render's: the CPU ratio the bank kernel would reach if
  its cost were proportional to the modes it computes;
- kernel: the bank kernel alone with every mode ringing (no force), a compact bank of a
  quarter of the scene's modes (rounded up to whole vectors; it rings freely,
  ugens.modal_kept.ring) against a bank of all of them, thread time per sample.
"""

from __future__ import annotations

import time
from typing import NamedTuple

import numpy as np

FRACTIONS = (0.1, 0.25, 0.5, 1.0)
SAMPLE_RATE = 48000
BLOCK = 4096


def patch_scene(name: str, seconds: float):
    """A builder of (graph, score) for a built-in patch."""
    from jassy.patchfile import load_patch

    def build():
        patch = load_patch(name)
        return patch.graph, patch.score

    return build, seconds


def wok_scene(seconds: float):
    """A builder of the wok scene's sound graph (physics simulated once)."""
    from patches.rigid_sound import contact_locator, scene_graph
    from patches.wok import simulate_wok
    from physics.rigid.events import contact_tracks, impacts

    world, voices, result = simulate_wok(seconds)
    hits, tracks = impacts(result, locate=contact_locator(world, voices)), contact_tracks(result)

    def build():
        return scene_graph(world.bodies, hits, tracks, voices)

    return build, seconds


class Timed(NamedTuple):
    """One render's audio and thread CPU times (s): ``bank`` the ModalBanks' process calls
    and the budget's steps (its decisions in Python apart, ``decide``), ``setup`` the
    budget's attach at the render's start (its tables and impacts; budget-only work);
    ``modes`` of the graph, ``work`` mode-samples."""

    audio: np.ndarray
    bank: float
    decide: float
    modes: int
    work: int
    setup: float


class Intervals(NamedTuple):
    """The clock pairs one render read: around a bank's ``process`` called by the engine
    (``banks``) or by the budget's step (``nested``), around a step, a decision taken in
    Python (inside a step) and the budget's set-up."""

    banks: int
    nested: int
    steps: int
    decisions: int
    attaches: int


def clock_costs(calls: int = 4000) -> tuple[float, float]:
    """What the clocks add to the times measured (ns, calibrated now, median of batches):
    ``outer`` to an interval timed (the reads' own cost between the two samples, about
    one read), ``nested`` to an interval around it for each interval timed inside it
    (two reads and the wrapper). Taken off each side's times per interval, so the full
    render, which reads a pair per bank call (705 for the wok), and the budgeted one, a
    pair per step, are charged alike."""
    clock, spent = time.thread_time_ns, [0]

    def nothing(*args):
        pass

    def timed(*args):  # as the bench's wrappers time a call
        t = clock()
        nothing(*args)
        spent[0] += clock() - t

    outer, nested = [], []
    for _ in range(5):
        spent[0], batch = 0, calls // 5
        for _ in range(batch):  # an interval around nothing
            t = clock()
            spent[0] += clock() - t
        outer.append(spent[0] / batch)
        t = clock()
        for _ in range(batch):
            timed(0, 0, 0)
        wrapped = clock() - t
        t = clock()
        for _ in range(batch):
            nothing(0, 0, 0)
        nested.append((wrapped - (clock() - t)) / batch)
    return float(np.median(outer)), float(np.median(nested))


def _timed_render(build, seconds: float, fraction: float | None) -> Timed:
    """One render of ``build``'s graph for ``seconds``, its banks' and budget's clocks."""
    from jassy.anytime import ModeBudget
    from jassy.engines.offline import OfflineEngine

    graph, score = build()
    banks = [node for node in graph.order if node.supports_budget]
    total = sum(b.model.n_modes for b in banks)
    if fraction is not None:
        graph.budget = ModeBudget(max_modes=max(1, int(round(fraction * total))))
    spent = [0, 0, 0]  # bank ns (the rest of the budget's steps included), decision ns, mode-samples
    intervals = Intervals(0, 0, 0, 0, 0)._asdict()  # the clock pairs read, by kind
    stepping = [False]  # inside the budget's step (which counts the modes of the banks it renders)

    def clocked_bank(bank):
        process = bank.process

        def run(start, n, offset=0):
            t = time.thread_time_ns()
            process(start, n, offset)
            spent[0] += time.thread_time_ns() - t  # (the clock's own cost is the bank's, not the step's)
            if not stepping[0]:
                intervals["banks"] += 1
                spent[2] += n * bank.active_modes()  # modes active at the span's end (after flushing)
            else:
                intervals["nested"] += 1

        return run

    def clocked_decide(decide):  # a decision (importance, ranking, kept sets)
        def run(*args):
            t = time.thread_time_ns()
            decide(*args)
            spent[1] += time.thread_time_ns() - t
            intervals["decisions"] += 1

        return run

    def clocked_step(step):  # the budget's bookkeeping and its render of the banks, and decisions
        def run(start, n):
            t, inside, deciding = time.thread_time_ns(), spent[0], spent[1]
            stepping[0] = True
            step(start, n)
            stepping[0] = False
            spent[0] = inside + time.thread_time_ns() - t - (spent[1] - deciding)
            intervals["steps"] += 1

        return run

    def clocked_attach(attach):  # the budget's set-up for a render (tables, impacts), once per render
        def run(*args, **options):
            t = time.thread_time_ns()
            attach(*args, **options)
            spent[3] += time.thread_time_ns() - t
            intervals["attaches"] += 1

        return run

    for bank in banks:
        bank.process = clocked_bank(bank)
    budget = graph.budget
    spent.append(0)  # the budget's set-up ns
    if budget is not None:
        budget.step, budget._decide = clocked_step(budget.step), clocked_decide(budget._decide)
        budget.attach = clocked_attach(budget.attach)
    engine = OfflineEngine(graph, score, SAMPLE_RATE, BLOCK, limiter=False, program=False)
    audio = engine.render(seconds).audio
    work = spent[2] + (budget.mode_samples if budget is not None else 0)
    n, (outer, nested) = Intervals(**intervals), clock_costs()  # the clocks' own cost, taken off
    bank = spent[0] - outer * (n.banks + n.steps) - nested * (n.nested + n.decisions) + outer * n.decisions
    decide, setup = spent[1] - outer * n.decisions, spent[3] - outer * n.attaches
    return Timed(audio, bank * 1e-9, decide * 1e-9, total, work, setup * 1e-9)


def bench_scene(build, seconds: float, fractions=FRACTIONS, repeats: int = 3) -> dict:
    """Rows (fraction, modes, error dB, CPU ratios with and without set-up, decision share,
    mode-samples, set-up) for one scene; each budget's best run is the one of least CPU
    with its set-up charged."""
    first = _timed_render(build, seconds, None)  # also compiles
    _timed_render(build, seconds, fractions[0])  # the budget's entry points found (excluded, as the full's)
    full_cpu = []
    best: dict[float, Timed | None] = {f: None for f in fractions}

    def charged(run: Timed) -> float:
        return run.bank + run.decide + run.setup

    for _ in range(repeats):
        full_cpu.append(_timed_render(build, seconds, None).bank)
        for f in fractions:
            run = _timed_render(build, seconds, f)
            if best[f] is None or charged(run) < charged(best[f]):
                best[f] = run
    reference = min(full_cpu)
    energy = float(np.sum(first.audio**2))
    rows = []
    for f in fractions:
        run = best[f]
        error = float(np.sum((run.audio - first.audio) ** 2)) / energy
        rows.append(
            {
                "fraction": f,
                "modes": max(1, int(round(f * first.modes))),
                "error_db": round(10 * np.log10(max(error, 1e-30)), 1),
                "cpu_ratio": round(charged(run) / reference, 3),
                "render_ratio": round((run.bank + run.decide) / reference, 3),
                "decisions_ratio": round(run.decide / reference, 3),
                "work_ratio": round(run.work / max(first.work, 1), 3),
                "setup_ratio": round(run.setup / reference, 3),
            }
        )
    return {"modes": first.modes, "seconds": seconds, "full_bank_cpu_s": round(reference, 4), "rows": rows}


def kernel_floor(modes: int, fraction: float = 0.25, frames: int = BLOCK, repeats: int = 30) -> dict:
    """Thread time per sample of the bank kernel with every mode sounding: ``modes`` modes
    (ugens.modal.bank_step) against the compact bank of ``fraction`` of them
    (ugens.modal_kept.kept_step, its width rounded up to whole vectors), best of ``repeats``."""
    from ugens.modal import bank_step
    from ugens.modal_budget import BANK_ROWS, COMPACT_ROWS, KEPT_LANES, line_aligned_zeros
    from ugens.modal_kept import kept_step

    rng = np.random.default_rng(0)
    force, out, ring = np.zeros(frames), np.zeros(frames), np.zeros(2048)

    def ringing(rows: int, k: int) -> np.ndarray:
        bank = line_aligned_zeros((rows, k))
        radius = np.exp(-1.0 / SAMPLE_RATE)  # a 1 s decay: no mode falls silent
        bank[0] = 2 * radius * np.cos(rng.uniform(0.01, 3.0, k))
        bank[1], bank[2], bank[4] = radius * radius, 1e-3, rng.normal(size=k)
        return bank

    kept = max(1, round(fraction * modes))
    width = -(-kept // KEPT_LANES) * KEPT_LANES
    full, compact = ringing(6, modes), ringing(COMPACT_ROWS, width)
    best = {"all": np.inf, "kept": np.inf}

    def every_mode():
        bank_step(force, out, 0, frames, full, np.array([modes, 0, modes]), 1e-10, np.zeros(1))

    def kept_modes():
        meta = np.array([width, 0, width])
        kept_step(force, out, 0, frames, compact[:BANK_ROWS], meta, 1e-10, np.zeros(1), ring)

    for _ in range(repeats):
        for name, run in (("all", every_mode), ("kept", kept_modes)):
            t = time.thread_time_ns()
            run()
            best[name] = min(best[name], (time.thread_time_ns() - t) / frames)
    return {"modes": modes, "kept": kept, "all_ns": round(best["all"], 2), "kept_ns": round(best["kept"], 2)}


def bench_anytime(quick: bool = False, names=("bell", "scrape", "wok")) -> dict:
    """Every scene of ``names``; ``quick``: shorter renders and one repeat."""
    scenes = {
        "bell": lambda: patch_scene("bell", 4.0 if quick else 8.0),
        "scrape": lambda: patch_scene("scrape", 3.5 if quick else 7.0),
        "wok": lambda: wok_scene(1.5 if quick else 4.0),
    }
    result = {name: bench_scene(*scenes[name](), repeats=1 if quick else 3) for name in names}
    for scene in result.values():
        scene["kernel"] = kernel_floor(scene["modes"])
    return result


def print_anytime(result: dict) -> None:
    print("anytime synthesis: error and CPU of a mode budget against the full bank (48 kHz, block 4096)")
    for name, scene in result.items():
        full_ms = scene["full_bank_cpu_s"] * 1e3
        print(f"\n{name}: {scene['modes']} modes, {scene['seconds']:g} s, full bank {full_ms:.1f} ms CPU")
        print(
            "  budget   modes   error dB   CPU / full bank   without set-up   (of which decisions)"
            "   set-up / full   mode-samples / full"
        )
        for r in scene["rows"]:
            print(
                f"  {r['fraction']:6.0%}  {r['modes']:6d}  {r['error_db']:9.1f}   {r['cpu_ratio']:15.2f}"
                f"   {r['render_ratio']:14.2f}   {r['decisions_ratio']:20.2f}   {r['setup_ratio']:13.2f}"
                f"   {r['work_ratio']:19.2f}"
            )
        k = scene.get("kernel")
        if k:
            print(
                f"  kernel alone, every mode sounding: {k['kept']} of {k['modes']} modes cost"
                f" {k['kept_ns'] / k['all_ns']:.2f}x ({k['kept_ns']:.1f} vs {k['all_ns']:.1f} ns/sample)"
            )


def plot_anytime(result: dict, path: str) -> None:
    """Error and CPU against budget, one curve per scene, to a PNG (atomically): CPU with
    the set-up charged (solid) and without it (dashed)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from jassy.files import atomic_path

    fig, (error_ax, cpu_ax) = plt.subplots(1, 2, figsize=(10, 4))
    for name, scene in result.items():
        rows = scene["rows"]
        budgets = [100 * r["fraction"] for r in rows]
        cut = [r for r in rows if r["fraction"] < 1.0]
        error_ax.plot([100 * r["fraction"] for r in cut], [r["error_db"] for r in cut], "o-", label=name)
        (line,) = cpu_ax.plot(budgets, [r["cpu_ratio"] for r in rows], "o-", label=f"{name}, set-up charged")
        cpu_ax.plot(
            budgets,
            [r["render_ratio"] for r in rows],
            "o--",
            color=line.get_color(),
            label=f"{name}, without",
        )
    error_ax.axhline(-15, color="grey", lw=0.8, ls="--")
    error_ax.set_xlabel("modes computed (%)")
    error_ax.set_ylabel("error vs full synthesis (dB)")
    cpu_ax.axhline(0.35, color="grey", lw=0.8, ls="--")
    cpu_ax.set_xlabel("modes computed (%)")
    cpu_ax.set_ylabel("CPU / full bank")
    for ax in (error_ax, cpu_ax):
        ax.legend(fontsize=7)
        ax.grid(alpha=0.3)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=100)
    plt.close(fig)
