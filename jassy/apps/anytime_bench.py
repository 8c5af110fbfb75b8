"""``jassy bench anytime``: error and CPU time of budgeted synthesis against the full bank.

For each scene (the ``bell`` and ``scrape`` patches and the ``wok`` scene's sound graph),
renders the full synthesis and budgets of 10, 25, 50 and 100 % of the graph's modes, at
48 kHz in blocks of 4096 frames, node by node (the budget splits a sub-block where it
decides).

- error: 10 log10 of the energy of (budgeted - full) over the energy of full, on the
  rendered audio (dB; exact synthesis gives about -300 dB);
- CPU: thread CPU time spent rendering the ModalBanks (their ``process``) plus the
  budget's steps (its bookkeeping, its render of the banks and its decisions), divided by
  the CPU time of the ModalBanks of the full render (which skip silent modes); the best of
  ``repeats`` runs of each, interleaved in the same process; "decisions": the share of
  the decisions taken in Python (importance, ranking, kept sets, impacts and
  periodograms; those the compiled step takes itself count with the step);
- set-up: the thread CPU time of the budget's set-up at the start of a render
  (:meth:`jassy.anytime.ModeBudget.attach`: its tables), once per render, over the same
  full-bank time; not in the CPU ratio, as neither render's preparation of its banks is;
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
    budget's attach at the render's start (its tables; outside ``bank``, as the banks'
    own preparation is in both renders); ``modes`` of the graph, ``work`` mode-samples."""

    audio: np.ndarray
    bank: float
    decide: float
    modes: int
    work: int
    setup: float


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
    stepping = [False]  # inside the budget's step (which counts the modes of the banks it renders)

    def clocked_bank(bank):
        process = bank.process

        def run(start, n, offset=0):
            t = time.thread_time_ns()
            process(start, n, offset)
            spent[0] += time.thread_time_ns() - t  # (the clock's own cost is the bank's, not the step's)
            if not stepping[0]:
                spent[2] += n * bank.active_modes()  # modes active at the span's end (after flushing)

        return run

    def clocked_decide(decide):  # a decision (importance, ranking, kept sets)
        def run(*args):
            t = time.thread_time_ns()
            decide(*args)
            spent[1] += time.thread_time_ns() - t

        return run

    def clocked_step(step):  # the budget's bookkeeping and its render of the banks, and decisions
        def run(start, n):
            t, inside, deciding = time.thread_time_ns(), spent[0], spent[1]
            stepping[0] = True
            step(start, n)
            stepping[0] = False
            spent[0] = inside + time.thread_time_ns() - t - (spent[1] - deciding)

        return run

    def clocked_attach(attach):  # the budget's set-up for a render (its tables), once per render
        def run(*args, **options):
            t = time.thread_time_ns()
            attach(*args, **options)
            spent[3] += time.thread_time_ns() - t

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
    return Timed(audio, spent[0] * 1e-9, spent[1] * 1e-9, total, work, spent[3] * 1e-9)


def bench_scene(build, seconds: float, fractions=FRACTIONS, repeats: int = 3) -> dict:
    """Rows (fraction, modes, error dB, bank CPU ratio, decision share) for one scene."""
    full_audio, _, _, total, full_work, _ = _timed_render(build, seconds, None)  # also compiles
    full_cpu = []
    best = {f: None for f in fractions}
    setup = {f: np.inf for f in fractions}  # the least: a process's first budget loads its kernels
    for _ in range(repeats):
        full_cpu.append(_timed_render(build, seconds, None).bank)
        for f in fractions:
            run = _timed_render(build, seconds, f)
            setup[f] = min(setup[f], run.setup)
            if best[f] is None or run.bank + run.decide < best[f].bank + best[f].decide:
                best[f] = run
    reference = min(full_cpu)
    energy = float(np.sum(full_audio**2))
    rows = []
    for f in fractions:
        audio, bank, decide, _, work, _ = best[f]
        error = float(np.sum((audio - full_audio) ** 2)) / energy
        rows.append(
            {
                "fraction": f,
                "modes": max(1, int(round(f * total))),
                "error_db": round(10 * np.log10(max(error, 1e-30)), 1),
                "cpu_ratio": round((bank + decide) / reference, 3),
                "decisions_ratio": round(decide / reference, 3),
                "work_ratio": round(work / max(full_work, 1), 3),
                "setup_ratio": round(setup[f] / reference, 3),
            }
        )
    return {"modes": total, "seconds": seconds, "full_bank_cpu_s": round(reference, 4), "rows": rows}


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
            "  budget   modes   error dB   CPU / full bank   (of which decisions)   mode-samples / full"
            "   set-up / full"
        )
        for r in scene["rows"]:
            cpu, share, work = r["cpu_ratio"], r["decisions_ratio"], r["work_ratio"]
            print(
                f"  {r['fraction']:6.0%}  {r['modes']:6d}  {r['error_db']:9.1f}   {cpu:15.2f}"
                f"   {share:20.2f}   {work:19.2f}   {r['setup_ratio']:13.2f}"
            )
        k = scene.get("kernel")
        if k:
            print(
                f"  kernel alone, every mode sounding: {k['kept']} of {k['modes']} modes cost"
                f" {k['kept_ns'] / k['all_ns']:.2f}x ({k['kept_ns']:.1f} vs {k['all_ns']:.1f} ns/sample)"
            )


def plot_anytime(result: dict, path: str) -> None:
    """Error against budget, one curve per scene, to a PNG (atomically)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from jassy.files import atomic_path

    fig, ax = plt.subplots(figsize=(6, 4))
    for name, scene in result.items():
        rows = [r for r in scene["rows"] if r["fraction"] < 1.0]
        ax.plot([100 * r["fraction"] for r in rows], [r["error_db"] for r in rows], "o-", label=name)
    ax.axhline(-15, color="grey", lw=0.8, ls="--")
    ax.set_xlabel("modes computed (%)")
    ax.set_ylabel("error vs full synthesis (dB)")
    ax.legend()
    ax.grid(alpha=0.3)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=100)
    plt.close(fig)
