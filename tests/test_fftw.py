"""jassy.fftw: pyfftw imported without dask, with the same transforms, and dask importable after."""

import subprocess
import sys

import numpy as np
import pytest

_CHILD = """
import sys
import numpy as np
from jassy.fftw import import_pyfftw
pyfftw = import_pyfftw()
assert "dask" not in sys.modules and "pandas" not in sys.modules, [m for m in sys.modules if "dask" in m]
assert "dask.array.fft" not in sys.modules  # the stand-in entry is gone
spectrum = np.random.default_rng(3).standard_normal(513) + 1j * np.random.default_rng(4).standard_normal(513)
profile = pyfftw.interfaces.numpy_fft.irfft(spectrum, n=1024)
from ugens.profile import fractal_profile
np.save(sys.argv[1], np.concatenate([profile, fractal_profile(4096, 1.5, 1e-6, seed=7)]))
import dask.array.fft  # dask itself still imports
import pyfftw.interfaces.dask_fft  # and so does pyfftw's dask interface
"""


@pytest.mark.timeout(120)
def test_pyfftw_without_dask_transforms_as_numpy_and_as_pyfftw_imported_plainly(tmp_path):
    pytest.importorskip("dask.array")
    out = tmp_path / "child.npy"
    run = subprocess.run(
        [sys.executable, "-c", _CHILD, str(out)], capture_output=True, text=True, timeout=110
    )
    assert run.returncode == 0, run.stderr
    child = np.load(out)
    import pyfftw.interfaces.numpy_fft  # the plain import (dask's interface included)

    from ugens.profile import fractal_profile

    spectrum = np.random.default_rng(3).standard_normal(513) + 1j * np.random.default_rng(4).standard_normal(
        513
    )
    plain = pyfftw.interfaces.numpy_fft.irfft(spectrum, n=1024)
    np.testing.assert_allclose(child[:1024], np.fft.irfft(spectrum, n=1024), rtol=0, atol=1e-13)
    assert np.array_equal(child, np.concatenate([plain, fractal_profile(4096, 1.5, 1e-6, seed=7)]))
