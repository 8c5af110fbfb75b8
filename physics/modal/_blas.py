"""Run a block of code with single-threaded OpenBLAS (numpy's and scipy's libraries).

numpy and scipy wheels each bundle their own OpenBLAS with its own thread pool. The
multifrontal factorisation alternates thousands of small LAPACK/BLAS calls; with two pools on
a 2-core machine their spinning threads contend and the factorisation runs 5-10x slower than
on one thread (measured: 9.4 s vs 1.05 s for a 30k-unknown bowl). :func:`single_threaded`
sets every loaded OpenBLAS to one thread and restores the previous counts afterwards (what
threadpoolctl does, without the dependency). If no OpenBLAS is found it does nothing.
"""

from __future__ import annotations

import contextlib
import ctypes
import sys

_GET = ("openblas_get_num_threads", "scipy_openblas_get_num_threads", "scipy_openblas_get_num_threads64_")
_SET = ("openblas_set_num_threads", "scipy_openblas_set_num_threads", "scipy_openblas_set_num_threads64_")


def _openblas_libs() -> list[tuple]:
    """(get, set) function pairs of the OpenBLAS libraries mapped into this process."""
    if not sys.platform.startswith("linux"):
        return []
    try:
        with open("/proc/self/maps") as fh:
            paths = {line.split()[-1] for line in fh if "openblas" in line.lower() and "/" in line}
    except OSError:
        return []
    out = []
    for path in sorted(paths):
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        get = next((getattr(lib, n) for n in _GET if hasattr(lib, n)), None)
        put = next((getattr(lib, n) for n in _SET if hasattr(lib, n)), None)
        if get is not None and put is not None:
            get.restype = ctypes.c_int
            put.argtypes = [ctypes.c_int]
            out.append((get, put))
    return out


@contextlib.contextmanager
def single_threaded():
    """Context manager: every loaded OpenBLAS uses one thread inside the block."""
    import numpy  # noqa: F401  (make sure both libraries are loaded before looking)
    import scipy.linalg  # noqa: F401

    libs = _openblas_libs()
    saved = []
    for get, put in libs:
        try:
            saved.append((put, int(get())))
            put(1)
        except Exception:  # pragma: no cover - an exotic build; leave it alone
            continue
    try:
        yield
    finally:
        for put, n in saved:
            put(n)
