"""Free ringing of a budget's kept modes: the float64 kernel against float32 and explicit-vector variants.

A mode budget's kept modes ring freely for most of a struck object's sound
(ugens.modal_kept.ring: y[n] = c1 y[n-1] - c2 y[n-2], eight samples per pass, summed over
the modes). This times, for 16-64 modes of random frequency (200-8000 Hz) and decay (1-20
/s) at 48 kHz, 2048 samples per call, thread time, best of ``--repeats``, interleaved:

- ``ring``: the float64 kernel (the reference);
- ``held32``: the float32 delta-form kernel of the float32 bank (ugens.modal_f32.resonate_narrow:
  for up to 64 modes its modes held in registers, explicit vectors), with a zero force;
- ``pole32``: the same eight-sample loop as ``ring`` on float32 rows (the two-pole form,
  which float32 rounding detunes for low, lightly damped modes: ugens.modal_f32's docstring);
- ``sums64``: ``ring`` with the eight samples' sums reduced together in explicit LLVM vectors
  (pairs of vectors interleaved, seven adds for eight sums of eight lanes) and stored as
  one vector.

Each line prints ns per sample, the ratio to ``ring`` and the error against it (energy of
the difference over 2048 samples, dB). Run: ``python benchmarks/kept_ring_variants.py``.
"""

from __future__ import annotations

import argparse
import time

import numba as nb
import numpy as np
from llvmlite import ir
from numba.core import cgutils, types
from numba.extending import intrinsic
from numba.np.arrayobj import make_array

from ugens import modal_f32, modal_kept
from ugens.kernels import FASTMATH

SAMPLE_RATE = 48000.0
FRAMES = 2048
LANES = 8  # float64 lanes of one AVX-512 vector
_DOUBLE = ir.DoubleType()
_INDEX = ir.IntType(32)


def _merge(builder, x, y, group):
    """x, y: LANES lanes in groups of ``group`` partial sums -> groups of group / 2."""
    half = group // 2
    low = [g * group + j for g in range(2 * LANES // group) for j in range(half)]
    high = [i + half for i in low]

    def pick(lanes):
        return builder.shuffle_vector(x, y, ir.Constant(ir.VectorType(_INDEX, LANES), lanes))

    return builder.fadd(pick(low), pick(high), flags=("fast",))


def _vector_at(builder, data, offset):
    pointer = builder.gep(data, [offset])
    return builder.bitcast(pointer, ir.PointerType(ir.VectorType(_DOUBLE, LANES)))


@intrinsic
def ring_eight(typingctx, width, c1, c2, y1, y2, out, i):
    """Eight free samples of the modes [0, width) (a literal multiple of LANES), their sums
    reduced together and stored to out[i : i + 8] as one vector."""
    if not (isinstance(width, types.IntegerLiteral) and width.literal_value % LANES == 0):
        return None
    chunks = width.literal_value // LANES

    def codegen(context, builder, signature, args):
        data = [
            make_array(t)(context, builder, v).data
            for t, v in zip(signature.args[1:6], args[1:6], strict=True)
        ]
        sums = [None] * 8
        for chunk in range(chunks):
            rows = [_vector_at(builder, d, cgutils.intp_t(chunk * LANES)) for d in data[:4]]
            p, q, a, b = (builder.load(row, align=8) for row in rows)
            for j in range(8):
                v = builder.fsub(
                    builder.fmul(p, a, flags=("fast",)), builder.fmul(q, b, flags=("fast",)), flags=("fast",)
                )
                sums[j] = v if chunk == 0 else builder.fadd(sums[j], v, flags=("fast",))
                a, b = v, a
            builder.store(a, rows[2], align=8)
            builder.store(b, rows[3], align=8)
        group = LANES
        while len(sums) > 1:
            sums = [_merge(builder, sums[j], sums[j + 1], group) for j in range(0, len(sums), 2)]
            group //= 2
        builder.store(sums[0], _vector_at(builder, data[4], args[6]), align=8)
        return context.get_dummy_value()

    return types.none(width, c1, c2, y1, y2, out, i), codegen


@nb.njit(fastmath=FASTMATH, cache=True)
def sums64(out, n, c1, c2, y1, y2, active):
    """``ring`` for 16, 24, 32 or 64 modes with :func:`ring_eight` (n a multiple of 8)."""
    for i in range(0, n, 8):
        if active == 16:
            ring_eight(16, c1, c2, y1, y2, out, i)
        elif active == 24:
            ring_eight(24, c1, c2, y1, y2, out, i)
        elif active == 32:
            ring_eight(32, c1, c2, y1, y2, out, i)
        else:
            ring_eight(64, c1, c2, y1, y2, out, i)


@nb.njit(fastmath=FASTMATH, cache=True)
def pole32(out, n, c1, c2, y1, y2, active):
    """``ring``'s eight-sample loop on float32 rows, sums in float32 (n a multiple of 8)."""
    for i in range(0, n, 8):
        s0 = s1 = s2 = s3 = s4 = s5 = s6 = s7 = np.float32(0.0)
        for k in range(active):
            p, q = c1[k], c2[k]
            v0 = p * y1[k] - q * y2[k]
            v1 = p * v0 - q * y1[k]
            v2 = p * v1 - q * v0
            v3 = p * v2 - q * v1
            v4 = p * v3 - q * v2
            v5 = p * v4 - q * v3
            v6 = p * v5 - q * v4
            v7 = p * v6 - q * v5
            y2[k], y1[k] = v6, v7
            s0, s1, s2, s3 = s0 + v0, s1 + v1, s2 + v2, s3 + v3
            s4, s5, s6, s7 = s4 + v4, s5 + v5, s6 + v6, s7 + v7
        out[i], out[i + 1], out[i + 2], out[i + 3] = s0, s1, s2, s3
        out[i + 4], out[i + 5], out[i + 6], out[i + 7] = s4, s5, s6, s7


def _modes(rng, m):
    f, d = rng.uniform(200, 8000, m), rng.uniform(1, 20, m)
    r, theta = np.exp(-d / SAMPLE_RATE), 2 * np.pi * f / SAMPLE_RATE
    return 2 * r * np.cos(theta), r * r, rng.normal(size=m), rng.normal(size=m)


def bench(m: int, repeats: int, rng) -> dict:
    """ns per sample and error (dB) of each variant for m modes."""
    c1, c2, y1, y2 = _modes(rng, m)
    c0, b2 = modal_f32.delta_coefficients(c1, c2)
    g = np.ones(m)
    coef, state = modal_f32.narrow_rows(c0, b2, g, np.zeros(m), y1, y2, delta_end=0)
    held, zero, last = modal_f32.delta_rows(coef, state), np.zeros(FRAMES), np.zeros(1)
    state0 = state.copy()
    rows64 = [np.empty(m), np.empty(m)]
    rows32 = [np.empty(m, np.float32), np.empty(m, np.float32)]
    c1f, c2f = c1.astype(np.float32), c2.astype(np.float32)
    runs = {
        "ring": lambda out: modal_kept.ring(out, FRAMES, c1, c2, *rows64, m),
        "held32": lambda out: modal_f32.resonate_narrow(zero, out, FRAMES, held, m, None, 0, last, 0),
        "pole32": lambda out: pole32(out, FRAMES, c1f, c2f, *rows32, m),
        "sums64": lambda out: sums64(out, FRAMES, c1, c2, *rows64, m),
    }

    def reset():
        rows64[0][:], rows64[1][:] = y1, y2
        rows32[0][:], rows32[1][:] = y1, y2
        state[:] = state0

    outputs, best = {}, dict.fromkeys(runs, np.inf)
    for name, run in runs.items():
        reset()
        outputs[name] = np.zeros(FRAMES)
        run(outputs[name])
    for r in range(repeats):
        if r % 50 == 0:  # the modes decay: start again from the same state
            reset()
        for name, run in runs.items():
            t = time.thread_time_ns()
            run(outputs[name] if r else np.zeros(FRAMES))
            best[name] = min(best[name], time.thread_time_ns() - t)
    reset()
    modal_kept.ring(reference := np.zeros(FRAMES), FRAMES, c1, c2, *rows64, m)
    result = {}
    for name, run in runs.items():
        reset()
        out = np.zeros(FRAMES)
        run(out)
        error = np.sum((reference - out) ** 2) / np.sum(reference**2)
        result[name] = (best[name] / FRAMES, 10 * np.log10(max(error, 1e-30)))
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=300, help="timed calls per variant (best kept)")
    args = parser.parse_args()
    if args.repeats < 1:
        parser.error(f"--repeats: expected a positive count, got {args.repeats}")
    rng = np.random.default_rng(1)
    for m in (16, 24, 32, 64):
        result = bench(m, args.repeats, rng)
        reference = result["ring"][0]
        cells = [
            f"{name} {ns:.2f} ns ({ns / reference:.2f}x, {db:.0f} dB)" for name, (ns, db) in result.items()
        ]
        print(f"{m:3d} modes: " + "; ".join(cells))


if __name__ == "__main__":
    main()
