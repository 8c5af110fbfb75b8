"""``jassy bench float32``: the float32 modal kernel against a C float32 loop compiled in the
same run, from small banks (where fixed per-sample costs weigh) to large ones.

Both run the random bank of ``jassy bench modal`` (20 Hz-20 kHz, d 0.5-50 /s) over the same
force in one call each, with fresh state: the C loop is the float32 two-pole recursion
(jassy.apps.bench_c), jassy the delta-form kernel of ugens.modal_f32 that
``ModalBank(precision="mixed")`` runs. ``ModalBank`` itself (mixed, calls of 1024 and
of 4096 frames, its Python call, split, direct term and float64 modes included) is timed
beside them. The machine is shared: each
round times the three interleaved, best CPU time of ``repeats`` short calls, and the ratios
of several rounds are reported as their range. Each side's error is measured against the
float64 recursion (scipy.signal.lfilter per mode).
"""

from __future__ import annotations

import statistics
from collections.abc import Callable

import numpy as np

#: Bank sizes of the table.
MODE_COUNTS = (16, 64, 256, 1000, 5000)

#: Mode-samples per timed call (about 0.1 ms at 1e10 mode-samples/s).
CALL_WORK = 2_000_000

#: ModalBank is also timed in calls of this many frames (or of the whole force where it is
#: shorter), to show what its ~0.2-0.3 us per ``process`` call (Python, numba's unboxing
#: of the force, output and handle arrays) costs in calls of 1024 frames.
BIG_BLOCK = 4096


def _frames(modes: int) -> int:
    """Frames per call: about CALL_WORK mode-samples, 1024-48000, whole BIG_BLOCK blocks
    when longer than one (else one 1024-frame block)."""
    frames = int(np.clip(CALL_WORK // modes, 1024, 48000))
    return frames // BIG_BLOCK * BIG_BLOCK if frames >= BIG_BLOCK else 1024


def _error_db(y: np.ndarray, ref: np.ndarray) -> float:
    """Peak |y - ref| in dB of the peak |ref| (outputs in the bank's output units)."""
    return float(20 * np.log10(np.max(np.abs(y - ref)) / np.max(np.abs(ref))))


def _float64_reference(force: np.ndarray, c1: np.ndarray, c2: np.ndarray, g: np.ndarray) -> np.ndarray:
    """sum_k y_k with y[n] = c1 y[n-1] - c2 y[n-2] + g F[n-1], in float64."""
    from scipy.signal import lfilter

    out = np.zeros(force.size)
    for a1, a2, gk in zip(c1, c2, g, strict=True):
        out += lfilter([0.0, gk], [1.0, -a1, a2], force)
    return out


def _kernel_runner(
    force: np.ndarray, c1: np.ndarray, c2: np.ndarray, g: np.ndarray, order: np.ndarray, delta_end: int
) -> Callable[[], None]:
    """ugens.modal_f32.resonate_narrow (the kernel ModalBank runs) over ``force`` in one
    call, fresh state, no direct term (the C loop has none), every mode in float32: the
    modes in ``order`` (ModalBank's float32 modes in its order, then its float64 ones), the
    first ``delta_end`` in the delta form as ModalBank runs them, on rows laid out as
    ModalBank's (:func:`narrow_rows`); it writes ``out`` as the C loop does."""
    from ugens.modal_f32 import DeltaRows, delta_coefficients, narrow_rows, resonate_narrow

    c1, c2, g = c1[order], c2[order], g[order]
    c0, b2 = delta_coefficients(c1, c2)
    zeros = np.zeros_like(g)
    coef, state = narrow_rows(c0, b2, g, zeros, zeros, zeros, delta_end)
    out, last = np.zeros(force.size), np.zeros(1)
    rows = DeltaRows(coef[0], coef[1], coef[2], coef[3], state[0], state[1])

    def run():
        state[:] = 0.0
        last[0] = 0.0
        resonate_narrow(force, out, force.size, rows, g.size, None, 0, last, delta_end)

    run.output = out
    return run


def _form(delta_end: int, modes: int) -> str:
    """The float32 modes' form: "decay factor", "delta", or how many run in the delta form."""
    if delta_end == 0:
        return "decay factor"
    return "delta" if delta_end >= modes else f"{delta_end} delta"


def float32_bench(mode_counts=MODE_COUNTS, rounds: int = 5, repeats: int = 40) -> list[dict]:
    """Per bank size: the C loop's mode-samples/s (median of the rounds), the kernel's and
    ModalBank's ratios to it (min, median, max over ``rounds``), each side's error against
    float64 (dB of the peak), the share of modes the mixed split runs in float32 and its
    form.
    Without a C compiler the rows carry ``c_note`` and no ratios."""
    from jassy.apps.bench import SAMPLE_RATE, _bank_runner, _best_times, random_model
    from jassy.apps.bench_c import c_runner, compile_modal_f32
    from ugens.modal import design, split_by_precision
    from ugens.modal_meta import DELTA_END, NARROW_ALL

    c_loop, note = compile_modal_f32()
    rows = []
    for k in mode_counts:
        model = random_model(k)
        frames = _frames(k)
        force = np.random.default_rng(1).standard_normal(frames)
        c1, c2, s = design(model.frequencies, model.decays, SAMPLE_RATE)
        g = s * model.gains[0] / SAMPLE_RATE
        split = split_by_precision(np.stack([c1, c2, g, 0 * g, 0 * g, 0 * g]), SAMPLE_RATE)
        delta_end = int(split.rows.narrow_meta[DELTA_END])
        kernel = _kernel_runner(force, c1, c2, g, np.concatenate([split.narrow, split.wide]), delta_end)
        bank = _bank_runner(model, force, 1024, "mixed")
        big_bank = _bank_runner(model, force, min(BIG_BLOCK, frames), "mixed")
        row = {
            "modes": k,
            "frames": frames,
            "float32_share": split.narrow.size / k,
            "form": _form(*split.rows.narrow_meta[[DELTA_END, NARROW_ALL]]),
            "c_note": note,
        }
        ref = _float64_reference(force, c1, c2, g)
        kernel()
        row["kernel_error_db"] = _error_db(kernel.output, ref)
        if c_loop is None:
            rows.append(row)
            continue
        c = c_runner(c_loop, force, c1, c2, g)
        c()
        row["c_error_db"] = _error_db(c.output.astype(np.float64), ref)
        kernel_ratio, bank_ratio, big_ratio, c_rate = [], [], [], []
        for _ in range(rounds):
            t_kernel, t_c, t_bank, t_big = _best_times([kernel, c, bank, big_bank], repeats=repeats)
            kernel_ratio.append(t_c / t_kernel)
            bank_ratio.append(t_c / t_bank)
            big_ratio.append(t_c / t_big)
            c_rate.append(k * frames / t_c)
        row["c_rate"] = statistics.median(c_rate)
        for key, ratios in (
            ("kernel_vs_c", kernel_ratio),
            ("bank_vs_c", bank_ratio),
            ("big_bank_vs_c", big_ratio),
        ):
            row[key] = (min(ratios), statistics.median(ratios), max(ratios))
        rows.append(row)
    return rows


def print_float32(rows: list[dict]) -> None:
    """Print :func:`float32_bench`'s rows: rates in mode-samples/s, speed ratios to C, errors in dB."""
    print(
        "float32 modal bank vs a C float32 loop compiled now "
        f"({rows[0]['c_note']}); ratios min / median / max over interleaved rounds"
    )
    print(
        f"{'modes':>6} {'frames':>6} {'float32 %':>9} {'form':>12} {'C float32':>10} {'kernel/C':>20} "
        f"{'ModalBank b1024/C':>20} {'ModalBank b4096/C':>20} {'err jassy':>10} {'err C':>7}"
    )
    for r in rows:
        if "kernel_vs_c" not in r:
            print(
                f"{r['modes']:>6} {r['frames']:>6} {100 * r['float32_share']:>8.0f}% {r['form']:>12}"
                "  (no C reference)"
            )
            continue
        kr, br, bb = (
            "{:.2f} / {:.2f} / {:.2f}".format(*r[key])
            for key in ("kernel_vs_c", "bank_vs_c", "big_bank_vs_c")
        )
        print(
            f"{r['modes']:>6} {r['frames']:>6} {100 * r['float32_share']:>8.0f}% {r['form']:>12} "
            f"{r['c_rate']:>10.3g} "
            f"{kr:>20} {br:>20} {bb:>20} {r['kernel_error_db']:>8.0f}dB {r['c_error_db']:>5.0f}dB"
        )
