"""The rigid step's first compile shared by two cores.

On an empty numba cache the first :func:`physics.rigid.world.simulate` compiles
``stepper.run_steps`` and the stages it calls apart (stepper.StepEntries) with every kernel
they call (about 45 s of CPU for the wok, one process, one function at a time). Kernels
compiled on their own are carried from one process to another by numba's cache
(``cache=True``), so the large subtrees can compile side by side: :func:`step_units` lists
them as compile units for the exact argument types the step passes (taken from the run's
own Model, Options and Data records), and :func:`compile_step_ahead` hands them to
:func:`jassy.forked_compile.compile_on_two_cores` (a forked helper takes units from the
back of the list while this process works from the front), with run_steps (which links
none of the stages) and the caller's own units (a scene's sound kernels, which otherwise
this process would compile after the run) in the middle, for whichever process gets there
first.

The split (CPU of each subtree's first compile on the wok, one cold run): the helper first
takes the mesh contacts (``narrow._against_mesh`` with its grid search, ~4.5 s), then the
free motion with the advance stage and the contact model (``impulses.resolve``, ~10 s, or
``penalty.penalty``) with the contact stage; this process the polytope pairs
(``narrow._polytopes``, ~5 s, and ``_spheres_polytope``), then the rest of the narrow phase
(``narrow.pair_contacts`` and ``_with_compound``, which call the larger methods apart:
narrow.NarrowEntries), the narrow stage and the impact stage (with the impact-time search;
both call the narrow phase apart, the impact stage links the free motion), the sweep with
the broad stage. A unit compiled for other types than the step
asks for would only cost time (the step would compile its own):
tests/test_rigid_step_units.py checks that they agree.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable, Sequence
from functools import partial
from typing import NamedTuple

import numpy as np
from numba.core import config

from jassy.forked_compile import cache_holds, compile_on_two_cores, helper_busy_with
from jassy.jit import specialise
from jassy.unlinked import unset
from physics.rigid import stepper as st
from physics.rigid.broad import sweep_pairs
from physics.rigid.impulses import resolve
from physics.rigid.model import Model, Options
from physics.rigid.penalty import penalty

#: At most this long (s) this process waits for a unit the helper compiles (_await_helper): a
#: bound for a helper that hangs. The unit waited for (the mesh contacts) takes 7-12 s of CPU
#: on the wok; 60 s leaves room for a machine shared with other work.
HELPER_WAIT = 60.0


class KernelCall(NamedTuple):
    """A kernel and example arguments of the types run_steps calls it with; ``after``: a
    kernel of a unit the helper compiles first, waited for (_await_helper) before this one
    compiles."""

    kernel: Callable
    args: tuple
    after: Callable | None = None


def step_units(m: Model, opt: Options, d: st.Data) -> list[list[KernelCall]]:
    """Compile units of the step's kernels for a run of ``m``, ``opt``, ``d``, each a list of
    kernel calls to compile (not run): the polytope pairs, the rest of the narrow phase, the
    narrow and impact stages, the sweep with the broad stage first (this process); the mesh
    contacts, the free motion with the advance stage and the contact model with the contact
    stage from the back (the helper: the last BACK_UNITS)."""
    whole, count, dt = np.int64(0), np.int64(0), 0.0
    calls = st.step_calls(m, opt, d)
    contact, motion = st.step_models(opt)
    if isinstance(contact, st.ImpulseContacts):
        bodies = st.SolveBodies(m.kind, m.inv_mass, m.inv_inertia, m.restitution, m.friction, m.rolling)
        state = st.SolveData(d.contacts, d.warm, d.pos, d.rot, d.phi, d.kin_v, d.kin_w, d.rec, d.stats)
        solve = KernelCall(resolve, (bodies, opt, state, d.solver, count, dt, dt, whole, whole))
    else:
        solve = KernelCall(penalty, (m, opt, d, d.solver, count, dt, dt, whole, whole))
    move = st._move_semi_implicit if isinstance(motion, st.SemiImplicitMotion) else st._move
    free = st._free_motion.py_func(m, opt, d)
    moved = (d.new_pos, d.new_quat, d.new_phi)
    pair = calls["pair"]
    return [
        [KernelCall(*pair["polytopes"])],
        [KernelCall(*pair["spheres_polytope"])],
        [KernelCall(*pair["contacts"]), KernelCall(*pair["with_compound"])],
        [KernelCall(*calls["narrow"]), KernelCall(*calls["impact"], after=move)],
        [KernelCall(sweep_pairs, (d.lo, d.hi, d.movable, d.sweep)), KernelCall(*calls["broad"])],
        [solve, KernelCall(*calls["response"])],
        [KernelCall(move, (free, whole, dt, *moved)), KernelCall(*calls["advance"])],
        [KernelCall(*pair["against_mesh"])],
    ]


#: The last this many units of step_units are the helper's (it starts with the last).
BACK_UNITS = 3


def compile_step_ahead(
    m: Model, opt: Options, d: st.Data, extra: Sequence[Callable[[], object]] = ()
) -> bool:
    """Compile the step's kernels for this run on two cores (:func:`step_units`) when
    numba's cache holds no run_steps yet (a fresh install) and this process has not compiled
    it: run_steps and ``extra`` (compile units of the caller's, e.g. a scene's sound and
    contact-event kernels, which the caller would otherwise compile after the run) in the
    middle of the list; True if the units ran. False with numba's JIT off
    (NUMBA_DISABLE_JIT=1: the kernels are plain Python functions, nothing to compile)."""
    if config.DISABLE_JIT or not hasattr(st.run_steps, "signatures"):
        return False
    if st.run_steps.signatures or cache_holds(st.run_steps):
        return False
    rigid = step_units(m, opt, d)
    front, back = rigid[:-BACK_UNITS], rigid[-BACK_UNITS:]
    first_back = len(front) + 1 + len(extra)
    at = {id(u[0].kernel): i for i, u in enumerate(front)}
    at.update({id(u[0].kernel): first_back + i for i, u in enumerate(back)})
    contact, motion = st.step_models(opt)
    entries = unset(st.StepEntries, pair=unset(st.NarrowEntries))
    run_args = (m, opt, d, 0, 0, 0, contact, motion, entries)  # the types stepper.run passes
    whole_step = partial(_compile, [KernelCall(st.run_steps, run_args)], at)
    units = [
        *(partial(_compile, unit, at) for unit in front),
        whole_step,
        *extra,
        *(partial(_compile, unit, at) for unit in back),
    ]
    return compile_on_two_cores(units)


def _compile(unit: list[KernelCall], at: dict[int, int]) -> None:
    """Compile a unit's kernels for their calls' types, ignoring errors (run_steps then
    compiles what it needs itself: only this unit's time is lost); ``at``: the position of
    each kernel's unit in the list (by the id of the unit's first kernel)."""
    for call in unit:
        if call.after is not None:
            _await_helper(at[id(call.after)])
        with contextlib.suppress(Exception):
            specialise(call.kernel, *call.args)


def _await_helper(unit: int, seconds: float = HELPER_WAIT) -> None:
    """Wait while the helper works on unit ``unit`` of the list (it starts with it), at most
    ``seconds``: until it has finished it (compiled, or given up) or has ended; at once with
    no helper. This process then compiles whatever is still missing."""
    deadline = time.monotonic() + seconds
    while helper_busy_with(unit) and time.monotonic() < deadline:
        time.sleep(0.02)
