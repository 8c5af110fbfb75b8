"""pyfftw imported without its dask interface.

``import pyfftw`` imports ``pyfftw.interfaces``, which builds a dask version of its FFT
functions whenever dask is installed: importing ``dask.array`` pulls in pandas and xarray,
about 1.3 s of CPU (~0.6 s for pyfftw without it), paid by every process that first builds
a node with a surface profile or a spectral analysis. jassy uses pyfftw's FFTW plans
(``pyfftw.builders``) and its numpy-like functions (``pyfftw.interfaces.numpy_fft``), never
the dask ones. :func:`import_pyfftw` imports pyfftw while ``dask.array.fft`` reads as not
installed (a ``None`` entry in ``sys.modules``, which Python's import system documents as
making that import raise ImportError; pyfftw 0.15's ``interfaces/__init__.py`` then leaves
its dask interface out), and removes the entry again: a later ``import dask.array.fft``, or
``import pyfftw.interfaces.dask_fft``, works as usual. The transforms are the same FFTW
calls either way.
"""

from __future__ import annotations

import sys
from types import ModuleType

#: The module pyfftw's interfaces import to offer their dask functions.
DASK_FFT = "dask.array.fft"


def import_pyfftw() -> ModuleType:
    """``pyfftw``, with ``pyfftw.interfaces.numpy_fft`` and ``pyfftw.builders`` imported, without
    importing dask (unless dask's FFT module was imported before: then as pyfftw does)."""
    if "pyfftw.interfaces.numpy_fft" in sys.modules:
        return sys.modules["pyfftw"]
    blocked = DASK_FFT not in sys.modules
    if blocked:
        sys.modules[DASK_FFT] = None  # import dask.array.fft raises ImportError
    try:
        import pyfftw
        import pyfftw.builders
        import pyfftw.interfaces.numpy_fft  # noqa: F401 (imported for the caller)
    finally:
        if blocked and DASK_FFT in sys.modules and sys.modules[DASK_FFT] is None:
            del sys.modules[DASK_FFT]
    return pyfftw
