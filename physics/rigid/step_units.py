"""The rigid step's first compile shared by two cores.

On an empty numba cache the first :func:`physics.rigid.world.simulate` compiles
``stepper.run_steps`` and every kernel it calls. Its large callees, the narrow and impact
stages (``stepper.narrow_stage`` and ``impact_stage``, each with ``narrow.pair_contacts``
linked in) and the contact model (``stepper.impulse_response`` or ``penalty_response``), are
called apart (jassy.unlinked: through their entry points, not linked into run_steps), so
run_steps compiles without their code and they without its: :func:`step_units` lists them
and run_steps as compile units for the exact argument types of this run (taken from its own
Model, Options and Data records), and :func:`compile_step_ahead` hands them to
:func:`jassy.forked_compile.compile_on_two_cores` (a forked helper takes units from the back
of the list while this process works from the front). numba's cache carries each from one
process to the other; the run then loads them.

The split: this process takes the narrow and impact stages (one unit: both need the narrow
phase, compiled once; ~35 s of CPU on the wok), the helper the contact model (~20 s) and
run_steps. A unit compiled for other types than the run asks for would only cost time (the
run would compile its own): tests/test_rigid_step_units.py checks that they agree.
"""

from __future__ import annotations

import contextlib
from functools import partial

from numba.core import config

from jassy.forked_compile import cache_holds, compile_on_two_cores
from jassy.jit import specialise
from physics.rigid import stepper as st
from physics.rigid.model import Model, Options


def step_units(m: Model, opt: Options, d: st.Data) -> list[list[st.KernelCall]]:
    """Compile units for a run of ``m``, ``opt``, ``d``, each a list of kernel calls to
    compile (not run): the narrow phase first (this process), then the impact-time search,
    run_steps and the contact model (the helper works from the back)."""
    calls = st.step_calls(m, opt, d)
    no_entry = st.Entry(0, 0)
    entries = st.StepEntries(no_entry, no_entry, no_entry)
    steps = st.KernelCall(st.run_steps, (m, opt, d, 0, 0, 0, entries, st.step_models(opt)[1]))
    return [[calls.narrow, calls.impact], [steps], [calls.response]]


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


def _compile(unit: list[st.KernelCall]) -> None:
    """Compile a unit's kernels for their calls' types, ignoring errors (run_steps then
    compiles what it needs itself: only this unit's time is lost)."""
    for call in unit:
        with contextlib.suppress(Exception):
            specialise(call.kernel, *call.args)
