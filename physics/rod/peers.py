"""Optional peer solver as a benchmark reference: Siconos's 2D frictional-contact NSGS.

Siconos numerics (Acary et al.; Debian's ``libsiconos-numerics7``) is reached by ctypes through
its public C API (``frictionContactProblem_new_with_data``, ``solver_options_create``,
``fc2d_nsgs_dense``); ``siconos_solver`` returns None where the library is not installed.
"""

from __future__ import annotations

import ctypes
import ctypes.util
from typing import NamedTuple

import numpy as np

_NM_DENSE = 0  # NumericsMatrix_types
_FRICTION_2D_NSGS = 400  # SICONOS_FRICTION_2D_NSGS
_IPARAM_MAX_ITER, _IPARAM_ITER_DONE = 0, 1
_DPARAM_TOL, _DPARAM_RESIDU = 0, 1


class _SolverOptionsHead(ctypes.Structure):
    """The leading fields of Siconos's ``SolverOptions`` (SolverOptions.h)."""

    _fields_ = [
        ("solverId", ctypes.c_int),
        ("isSet", ctypes.c_bool),
        ("iSize", ctypes.c_int),
        ("iparam", ctypes.POINTER(ctypes.c_int)),
        ("dSize", ctypes.c_int),
        ("dparam", ctypes.POINTER(ctypes.c_double)),
    ]


class SiconosResult(NamedTuple):
    r: np.ndarray  # (c, 2) impulses, N s
    u: np.ndarray  # (c, 2) relative velocities W r + w, m/s
    iterations: int
    error: float  # Siconos's own error measure at the end
    info: int  # 0 when Siconos reports convergence


class SiconosSolver:
    """One DFCP (W, w, mu) set up once in Siconos; ``solve`` runs its NSGS from r = 0."""

    def __init__(self, lib, W: np.ndarray, w: np.ndarray, mu: np.ndarray, tol: float, max_iter: int):
        self._lib = lib
        self.c = mu.size
        # Siconos keeps pointers to these arrays: they live as long as the solver
        self._W = np.asfortranarray(W, dtype=np.float64)
        self._w = np.ascontiguousarray(w, dtype=np.float64)
        self._mu = np.ascontiguousarray(mu, dtype=np.float64)
        n = 2 * self.c
        ptr = ctypes.c_void_p
        self._matrix = lib.NM_create_from_data(_NM_DENSE, n, n, self._W.ctypes.data_as(ptr))
        self._problem = lib.frictionContactProblem_new_with_data(
            2, self.c, self._matrix, self._w.ctypes.data_as(ptr), self._mu.ctypes.data_as(ptr)
        )
        self._options = lib.solver_options_create(_FRICTION_2D_NSGS)
        head = ctypes.cast(self._options, ctypes.POINTER(_SolverOptionsHead)).contents
        head.iparam[_IPARAM_MAX_ITER] = int(max_iter)
        head.dparam[_DPARAM_TOL] = float(tol)
        self._head = head
        self.r, self.u = np.zeros(n), np.zeros(n)
        self._info = ctypes.c_int(0)
        self._args = (
            self._problem, self.r.ctypes.data_as(ptr), self.u.ctypes.data_as(ptr), ctypes.byref(self._info),
            self._options,
        )  # fmt: skip

    def solve(self) -> SiconosResult:
        self.r[:] = 0.0
        self._lib.fc2d_nsgs_dense(*self._args)
        c, head = self.c, self._head
        return SiconosResult(
            self.r.reshape(c, 2).copy(), self.u.reshape(c, 2).copy(), int(head.iparam[_IPARAM_ITER_DONE]),
            float(head.dparam[_DPARAM_RESIDU]), int(self._info.value),
        )  # fmt: skip


def _library():
    name = ctypes.util.find_library("siconos_numerics")
    if name is None:
        return None
    try:
        lib = ctypes.CDLL(name)
    except OSError:
        return None
    vp = ctypes.c_void_p
    lib.NM_create_from_data.restype = vp
    lib.NM_create_from_data.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.c_int, vp]
    lib.frictionContactProblem_new_with_data.restype = vp
    lib.frictionContactProblem_new_with_data.argtypes = [ctypes.c_int, ctypes.c_int, vp, vp, vp]
    lib.solver_options_create.restype = vp
    lib.solver_options_create.argtypes = [ctypes.c_int]
    lib.fc2d_nsgs_dense.restype = None
    lib.fc2d_nsgs_dense.argtypes = [vp, vp, vp, vp, vp]
    return lib


def siconos_solver(W, w, mu, tol: float = 1e-10, max_iter: int = 10000) -> SiconosSolver | None:
    """Siconos's NSGS set up on (W, w, mu), or None where libsiconos-numerics is not installed."""
    lib = _library()
    if lib is None:
        return None
    return SiconosSolver(lib, np.asarray(W), np.asarray(w), np.asarray(mu, dtype=np.float64), tol, max_iter)
