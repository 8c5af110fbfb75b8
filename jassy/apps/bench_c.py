"""A C float32 modal loop compiled at benchmark time: the reference for ``jassy bench modal``.

The source is the two-pole recursion of ugens.modal.resonate in float32, four samples per
pass over the modes, built with the system ``cc`` (-O3 -march=native -ffast-math) into a
temporary shared library and called through ctypes. No binary is shipped.
"""

from __future__ import annotations

import ctypes
import shutil
import subprocess
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np

FLAGS = ("-O3", "-march=native", "-ffast-math", "-fPIC")
# Linked in a second step without -ffast-math: gcc links crtfastmath.o into a -ffast-math link
# (also of a shared library before GCC 13), whose constructor sets flush-to-zero for the whole
# process when the library is loaded: every later float computation would lose subnormals.
LINK_FLAGS = ("-shared",)

SOURCE = r"""
void modal_f32(const float *restrict force, float *restrict out, int n,
               const float *restrict c1, const float *restrict c2, const float *restrict g,
               float *restrict y1, float *restrict y2, int modes, float *restrict last)
{
    float fp = last[0];
    int i = 0;
    for (; i + 4 <= n; i += 4) {
        float f0 = force[i], f1 = force[i + 1], f2 = force[i + 2], f3 = force[i + 3];
        float s0 = 0.f, s1 = 0.f, s2 = 0.f, s3 = 0.f;
        for (int k = 0; k < modes; k++) {
            float p = c1[k], q = c2[k], gk = g[k], u1 = y1[k], u2 = y2[k];
            float v0 = p * u1 - q * u2 + gk * fp;
            float v1 = p * v0 - q * u1 + gk * f0;
            float v2 = p * v1 - q * v0 + gk * f1;
            float v3 = p * v2 - q * v1 + gk * f2;
            y2[k] = v2;
            y1[k] = v3;
            s0 += v0; s1 += v1; s2 += v2; s3 += v3;
        }
        out[i] = s0; out[i + 1] = s1; out[i + 2] = s2; out[i + 3] = s3;
        fp = f3;
    }
    for (; i < n; i++) {
        float s = 0.f;
        for (int k = 0; k < modes; k++) {
            float v = c1[k] * y1[k] - c2[k] * y2[k] + g[k] * fp;
            y2[k] = y1[k];
            y1[k] = v;
            s += v;
        }
        out[i] = s;
        fp = force[i];
    }
    last[0] = fp;
}
"""


def compile_modal_f32() -> tuple[Callable | None, str]:
    """(the compiled function, a description) or (None, why not): no ``cc`` on the path, or
    the compiler failed."""
    cc = shutil.which("cc")
    if cc is None:
        return None, "no C compiler (cc) on PATH: C float32 reference skipped"
    with tempfile.TemporaryDirectory(prefix="jassy-bench-") as tmp:
        src, obj, lib = Path(tmp) / "modal_f32.c", Path(tmp) / "modal_f32.o", Path(tmp) / "modal_f32.so"
        src.write_text(SOURCE)
        for step in (
            [cc, *FLAGS, "-c", "-o", str(obj), str(src)],
            [cc, *LINK_FLAGS, "-o", str(lib), str(obj)],
        ):
            run = subprocess.run(step, capture_output=True, text=True, timeout=60)
            if run.returncode != 0:
                return None, f"cc failed ({run.stderr.strip()[:200]}): C float32 reference skipped"
        fn = ctypes.CDLL(str(lib)).modal_f32  # stays mapped after the file is removed
    ptr = ctypes.POINTER(ctypes.c_float)
    fn.argtypes = [ptr, ptr, ctypes.c_int, ptr, ptr, ptr, ptr, ptr, ctypes.c_int, ptr]
    fn.restype = None
    return fn, f"cc {' '.join(FLAGS[:3])}"


def _line_aligned(values: np.ndarray) -> np.ndarray:
    """A float32 copy of ``values`` starting on a 64-byte cache-line boundary."""
    raw = np.zeros(values.size + 16, np.float32)
    skip = (-raw.ctypes.data % 64) // 4
    copy = raw[skip : skip + values.size]
    copy[:] = values
    return copy


def c_runner(fn: Callable, force: np.ndarray, c1, c2, g) -> Callable[[], None]:
    """A function that runs the compiled loop over ``force`` in one call (fresh state), on
    float32 rows laid out as jassy's float32 bank (ugens.modal_f32.float32_rows: on cache
    lines, 512 bytes apart modulo 4 KiB, so neither side meets 4K aliasing by chance)."""
    from ugens.modal_f32 import float32_rows

    n = len(c1)
    rows = float32_rows(5, -(-n // 32) * 32)[:, :n]
    rows[:3] = np.stack([c1, c2, g])
    c1f, c2f, gf, y1, y2 = rows
    force32 = _line_aligned(force)
    out = _line_aligned(np.zeros(force32.size))
    last = np.zeros(1, np.float32)
    ptr = ctypes.POINTER(ctypes.c_float)

    def p(a):
        return a.ctypes.data_as(ptr)

    args = (p(force32), p(out), force32.size, p(c1f), p(c2f), p(gf), p(y1), p(y2), c1f.size, p(last))

    def run():
        y1[:] = 0.0
        y2[:] = 0.0
        last[0] = 0.0
        fn(*args)

    run.output = out  # for checks
    return run
