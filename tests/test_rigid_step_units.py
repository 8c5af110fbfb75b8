"""The rigid step's compile units (physics.rigid.step_units) are compiled for exactly the
argument types run_steps calls those kernels with: otherwise run_steps would compile each of
them again after the two cores had (a cold render would only lose time, so nothing else shows
it). Checked for the wok's models (semi-implicit integrator, impulse contacts) and for the
other pair of units (RK4 through the any-integrator motion, a penalty contact model). With
numba's JIT off the step runs as plain Python (no units, the models picked in Python)."""

import math
import os
import subprocess
import sys
import time

import numba as nb
import numpy as np
import pytest

from physics.rigid import stepper as st
from physics.rigid.impulses import new_warm_start, resolve
from physics.rigid.narrow import pair_contacts_by_ref
from physics.rigid.penalty import penalty
from physics.rigid.shapes import Plane, Sphere
from physics.rigid.step_units import _await_helper, step_units
from physics.rigid.world import Body, Material, Placement, StepParams, World, simulate

#: The types of run_steps' ``contact`` and ``motion`` arguments (stepper.step_models).
TAGS = (st.ImpulseContacts, st.PenaltyContacts, st.SemiImplicitMotion, st.AnyMotion)


def _cached_signatures(kernel) -> list:
    """The argument types of every specialisation numba's cache holds for ``kernel`` (compiled
    in any process: by the units, by run_steps' compile, or by other runs and tests)."""
    try:
        return [key[0] for key in kernel._cache._cache_file._load_index()]
    except FileNotFoundError:
        return []


def _tags(signature) -> tuple:
    """The run_steps tag types among a signature's argument types."""
    return tuple(t for t in signature if getattr(t, "instance_class", None) in TAGS)


def _world(integrator: str, contact: str) -> World:
    world = World(StepParams(h=1e-3, integrator=integrator, contact=contact))
    world.add(Body("ground", Plane(), Material("g", 1000, 0.5, 0.3), kind="static"))
    world.add(Body("ball", Sphere(0.05), Material("b", 1000, 0.5, 0.3)), Placement(position=(0, 0, 0.2)))
    return world


def _unit_calls(world: World) -> list:
    model, opt, state = world.model(), world.params.options(), world.initial_state()
    n = len(world.bodies)
    data = st.new_data(
        model,
        opt,
        state.pos,
        state.quat,
        state.phi,
        np.zeros((2, 0, 3)),
        np.zeros((2, 0, 4)),
        np.empty((16, st.REC_WIDTH)),
        st.new_stats(),
        np.zeros((1, n, 13)),
        1,
        0,
        new_warm_start(16),
    )
    return [call for unit in step_units(model, opt, data) for call in unit]


@pytest.mark.timeout(600)  # compiles the whole rigid step when the kernel cache is empty
@pytest.mark.parametrize(
    ("integrator", "contact", "solve", "move"),
    [
        ("semi-implicit", "impulse", resolve, st._move_semi_implicit),
        ("rk4", "linear", penalty, st._move),
    ],
)
def test_units_compile_the_types_run_steps_asks_for(integrator, contact, solve, move):
    world = _world(integrator, contact)
    calls = _unit_calls(world)
    stages = {st.narrow_stage, st.contact_stage, st.impact_stage}
    assert {call.kernel for call in calls} >= {pair_contacts_by_ref, *stages, solve, move}
    before = {call.kernel: set(_cached_signatures(call.kernel)) for call in calls}
    known = len(st.run_steps.signatures)
    simulate(world, 0.01)  # run_steps compiled (after the units, on an empty cache) or loaded
    # one run_steps specialisation more: the one compiled ahead (on an empty cache) is the one
    # the run calls (one for other types would leave two)
    assert len(st.run_steps.signatures) <= known + 1
    for call in calls:
        wanted = tuple(nb.typeof(a) for a in call.args)
        cached = _cached_signatures(call.kernel)
        name = call.kernel.py_func.__name__
        assert wanted in cached, f"{name}: units compile {wanted}, the cache holds {cached}"
        # this run added no other specialisation (a unit of other types than run_steps'
        # would leave two: the unit's and run_steps' own)
        added = set(cached) - before[call.kernel]
        assert added <= {wanted}, f"{name}: units compile {wanted}, this run added {added}"
        # the cache keeps every specialisation of earlier runs too (other integrators and
        # contact models): of those with this run's tag types there is one
        if _tags(wanted):
            same_run = [s for s in cached if _tags(s) == _tags(wanted)]
            assert same_run == [wanted], f"{name}: units compile {wanted}, the cache holds {same_run}"


#: A ball dropped 5 mm onto the ground, run with numba's JIT off: its first impact time.
NO_JIT_DROP = """
from physics.rigid.events import impacts
from physics.rigid.shapes import Plane, Sphere
from physics.rigid.world import Body, Material, Placement, StepParams, World, simulate
world = World(StepParams(h=1e-3, bounce_threshold=0.05))
world.add(Body("ground", Plane(), Material("g", 1000, 0.5, 0.0), kind="static"))
world.add(Body("ball", Sphere(0.05), Material("b", 1000, 0.5, 0.0)), Placement(position=(0, 0, 0.055)))
print(repr(impacts(simulate(world, 0.05, sample_every=0))[0].time))
"""


@pytest.mark.timeout(120)
def test_the_step_runs_with_the_jit_off():
    """NUMBA_DISABLE_JIT=1 (kernels as Python, for debugging): no compile units are started and
    the contact model and integrator are dispatched in Python; the drop's first impact is at
    the closed form sqrt(2 h / g) (the default integrator's flight is exact)."""
    env = dict(os.environ, NUMBA_DISABLE_JIT="1")
    out = subprocess.run(
        [sys.executable, "-c", NO_JIT_DROP], env=env, capture_output=True, text=True, timeout=110
    )
    assert out.returncode == 0, out.stderr[-2000:]
    assert abs(float(out.stdout.split()[-1]) - math.sqrt(2 * 0.005 / 9.81)) < 1e-9


@pytest.mark.timeout(60)
def test_the_wait_for_the_helpers_unit_ends_when_the_helper_gives_it_up(forking_alone):
    """step_units._await_helper: at once with no helper; with a helper that gives up its
    first unit at once (as when its compile fails) and then works 3 s on another, when the
    first unit is given up, not when the helper ends."""
    from jassy.forked_compile import compile_on_two_cores

    start = time.monotonic()
    _await_helper(-1, seconds=30.0)
    assert time.monotonic() - start < 1.0
    if not forking_alone:
        return
    waited = []

    def mine():
        start = time.monotonic()
        _await_helper(-1, seconds=30.0)
        waited.append(time.monotonic() - start)

    assert compile_on_two_cores([mine, lambda: time.sleep(3.0), lambda: None])
    assert waited[0] < 1.5
