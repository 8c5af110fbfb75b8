"""jassy.jit: specialise (the typed entry point, remembered by a cheap key of the argument
types) and the process-wide changes to numba it installs (flag comparisons, plain error text,
the BLAS check when used)."""

import subprocess
import sys

import numba as nb
import numpy as np
import pytest
from numba.core import errors, targetconfig

from jassy.jit import FlagComparison, flag_comparisons_agree, flag_variants, specialise


@nb.njit(cache=True)
def _total(x, scale, parts):
    return x.sum() * scale + parts[0].sum()


def _numba_entry(*args):
    return _total.overloads[tuple(nb.typeof(a) for a in args)].entry_point


def test_each_argument_type_gets_numbas_own_entry_point():
    a = np.arange(6.0)
    cases = [
        (a, 2.0, (a,)),  # C-contiguous float64, float, tuple of one array
        (a[::2], 2.0, (a,)),  # strided: layout A
        (a.reshape(2, 3).T.copy().T, 2.0, (a,)),  # 2-D F-contiguous
        (np.arange(6), 3, (a,)),  # int64 array, int
        (a, 2.0, (a[::3],)),  # the tuple's array strided
    ]
    read_only = a.copy()
    read_only.flags.writeable = False
    cases.append((read_only, 2.0, (a,)))
    entries = []
    for args in cases:
        entry = specialise(_total, *args)
        assert entry is _numba_entry(*args)  # found by numba's typing on first use
        assert specialise(_total, *args) is entry  # remembered
        assert entry(*args) == _total.py_func(*args)
        entries.append(entry)
    assert len({id(e) for e in entries}) == len(cases)  # every type its own entry point


def test_arguments_without_a_cheap_key_still_get_their_entry_point():
    a = np.arange(4.0)
    entry = specialise(_total, a, np.float64(2.0), (a,))  # a numpy scalar: typed by numba each time
    assert entry(a, np.float64(2.0), (a,)) == 18.0  # 6 * 2 + 6


def _numbas_values(flags):
    return {name: getattr(flags, name) for name in type(flags).options}  # through the properties


def _numbas_equal(flags, other):
    if not isinstance(other, targetconfig.TargetConfig):
        return NotImplemented
    return _numbas_values(flags) == _numbas_values(other)


#: numba's own TargetConfig definitions (numba/core/targetconfig.py), written out here.
NUMBAS = FlagComparison(
    _numbas_values, _numbas_equal, lambda flags: hash(tuple(sorted(_numbas_values(flags))))
)


def test_installed_flag_comparison_agrees_with_numbas():
    config = targetconfig.TargetConfig
    assert config.values.overlays_defaults  # installed on this numba version
    installed = FlagComparison(config.values, config.__eq__, config.__hash__)
    variants = flag_variants()
    assert flag_comparisons_agree(NUMBAS, installed, variants)
    default, fast, _, nrt, nrt_default, _ = variants
    assert default == nrt_default and hash(default) == hash(nrt_default)  # set to its default
    assert default != fast and default != nrt and {default, fast, nrt} == {nrt_default, fast, nrt}


def test_flag_check_rejects_a_comparison_that_differs():
    def defaults_only(flags):
        return {name: option.default for name, option in type(flags).options.items()}

    def reordered(flags):
        return dict(reversed(_numbas_values(flags).items()))

    variants = flag_variants()
    ignores_set_options = NUMBAS._replace(values=defaults_only, equal=lambda a, b: True)
    assert not flag_comparisons_agree(NUMBAS, ignores_set_options, variants)
    assert not flag_comparisons_agree(NUMBAS, NUMBAS._replace(values=reordered), variants)
    assert not flag_comparisons_agree(NUMBAS, NUMBAS._replace(hashed=lambda flags: 0), variants)


def test_numba_error_text_is_plain_in_every_module():
    schemes = [errors.termcolor()]
    schemes += [
        module._termcolor
        for name, module in sys.modules.items()
        if name.startswith("numba.") and hasattr(module, "_termcolor")
    ]
    assert len(schemes) > 1
    for scheme in schemes:
        for part in ("code", "errmsg", "filename", "indicate", "highlight", "reset"):
            assert getattr(scheme, part)("text") == "text"

    @nb.njit
    def no_such_attribute(x):
        return x.no_such_attribute

    with pytest.raises(errors.TypingError) as raised:
        no_such_attribute(1.0)
    assert "no_such_attribute" in str(raised.value) and "\x1b" not in str(raised.value)


#: A fresh process: numba's first compile without scipy.linalg, then a kernel calling BLAS.
BLAS_WHEN_USED = """
import sys
import numba as nb
import numpy as np
import jassy

nb.njit(lambda x: x + 1.0)(1.0)
from numba.np import arraymath
print("scipy.linalg" in sys.modules, arraymath._HAVE_BLAS)
print(nb.njit(lambda a, b: np.dot(a, b))(np.arange(3.0), np.arange(3.0)), "scipy.linalg" in sys.modules)
"""


def test_numba_offers_blas_without_importing_scipy_linalg_until_a_kernel_uses_it():
    out = subprocess.run([sys.executable, "-c", BLAS_WHEN_USED], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.split() == ["False", "True", "5.0", "True"]
