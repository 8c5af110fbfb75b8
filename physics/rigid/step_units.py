"""The rigid step's first compile shared by two cores.

On an empty numba cache the first :func:`physics.rigid.world.simulate` compiles
``stepper.run_steps`` with every kernel it calls (about 150 s of CPU for the wok, one
process, one function at a time). The kernels it calls without inlining compile on their own
and numba's cache (``cache=True``) carries them from one process to another, so the large
subtrees can compile side by side: :func:`step_units` lists them as compile units for the
exact argument types run_steps passes (taken from the run's own Model, Options and Data
records), and :func:`compile_step_ahead` hands them to
:func:`jassy.forked_compile.compile_on_two_cores` (a forked helper takes units from the
back of the list while this process works from the front). run_steps then compiles here,
loading its callees from the cache instead of compiling them.

The split (CPU of each subtree's first compile on the wok, one cold run): this process takes
the narrow phase (``pair_contacts``, ~33 s) and then the impact-time search
(``_time_of_impact``, which reaches the narrow phase again through the gap probe), the helper
first the free motion (called from both run_steps and the impact-time search), then the
run's contact model (``impulses.resolve``, ~20 s, or ``penalty.penalty``) and the small stage
kernels. A unit compiled for other types than run_steps asks for would only cost time
(run_steps would compile its own): tests/test_rigid_step_units.py checks that they agree.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable
from functools import partial
from typing import NamedTuple

import numpy as np
from numba.core import config

from jassy.forked_compile import cache_holds, compile_on_two_cores
from jassy.jit import specialise
from physics.rigid import stepper as st
from physics.rigid.broad import sweep_pairs
from physics.rigid.impulses import resolve
from physics.rigid.model import Model, Options
from physics.rigid.narrow import pair_contacts
from physics.rigid.penalty import penalty


class KernelCall(NamedTuple):
    """A kernel and example arguments of the types run_steps calls it with."""

    kernel: Callable
    args: tuple


def step_units(m: Model, opt: Options, d: st.Data) -> list[list[KernelCall]]:
    """Compile units of run_steps' callees for a run of ``m``, ``opt``, ``d``, each a list of
    kernel calls to compile (not run): the narrow phase and impact times first (this
    process), the free motion, solves and stage kernels from the back (the helper)."""
    whole, count, dt, when = np.int64(0), np.int64(0), 0.0, 0.0
    contact, motion = st.step_models(opt)
    if isinstance(contact, st.ImpulseContacts):
        bodies = st.SolveBodies(m.kind, m.inv_mass, m.inv_inertia, m.restitution, m.friction, m.rolling)
        state = st.SolveData(d.contacts, d.warm, d.pos, d.rot, d.phi, d.kin_v, d.kin_w, d.rec, d.stats)
        solve = KernelCall(resolve, (bodies, opt, state, d.solver, count, dt, when, whole, whole))
    else:
        solve = KernelCall(penalty, (m, opt, d, d.solver, count, dt, when, whole, whole))
    move = st._move_semi_implicit if isinstance(motion, st.SemiImplicitMotion) else st._move
    free = st._free_motion.py_func(m, opt, d)
    return [
        [
            KernelCall(pair_contacts, (whole, whole, d.pos, d.rot, m.geometry, dt, d.contacts, count)),
            KernelCall(st._time_of_impact, (m, opt, d, whole, whole, dt, dt, dt, dt, motion)),
        ],
        [KernelCall(st._boxes, (m, d, opt.slop))],
        [KernelCall(sweep_pairs, (d.lo, d.hi, d.movable, d.sweep))],
        [KernelCall(st.sample_stage, (d, whole))],
        [KernelCall(st._commit, (d,))],
        [solve],
        [KernelCall(move, (free, whole, dt, d.new_pos, d.new_quat, d.new_phi))],
    ]


def compile_step_ahead(m: Model, opt: Options, d: st.Data) -> bool:
    """Compile run_steps' large callees for this run on two cores (:func:`step_units`) when
    numba's cache holds no run_steps yet (a fresh install) and this process has not compiled
    it; True if the units ran. False with numba's JIT off (NUMBA_DISABLE_JIT=1: the kernels
    are plain Python functions, nothing to compile)."""
    if config.DISABLE_JIT or not hasattr(st.run_steps, "signatures"):
        return False
    if st.run_steps.signatures or cache_holds(st.run_steps):
        return False
    return compile_on_two_cores([partial(_compile, unit) for unit in step_units(m, opt, d)])


def _compile(unit: list[KernelCall]) -> None:
    """Compile a unit's kernels for their calls' types, ignoring errors (run_steps then
    compiles what it needs itself: only this unit's time is lost)."""
    for call in unit:
        with contextlib.suppress(Exception):
            specialise(call.kernel, *call.args)
