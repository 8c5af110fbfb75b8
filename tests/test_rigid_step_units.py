"""The rigid step's compile units (physics.rigid.step_units) are compiled for exactly the
argument types run_steps calls those kernels with: otherwise run_steps would compile each of
them again after the two cores had (a cold render would only lose time, so nothing else shows
it)."""

import numba as nb
import numpy as np
import pytest

from physics.rigid import stepper as st
from physics.rigid.impulses import new_warm_start, resolve
from physics.rigid.narrow import pair_contacts
from physics.rigid.shapes import Plane, Sphere
from physics.rigid.step_units import step_units
from physics.rigid.world import Body, Material, Placement, StepParams, World, simulate


def _cached_signatures(kernel) -> list:
    """The argument types of every specialisation numba's cache holds for ``kernel`` (those
    compiled here, or by the units, and those of run_steps' compile, which loads them)."""
    return [key[0] for key in kernel._cache._cache_file._load_index()]


@pytest.mark.timeout(600)  # compiles the whole rigid step when the kernel cache is empty
def test_units_compile_the_types_run_steps_asks_for():
    world = World(StepParams(h=1e-3))
    world.add(Body("ground", Plane(), Material("g", 1000, 0.5, 0.3), kind="static"))
    world.add(Body("ball", Sphere(0.05), Material("b", 1000, 0.5, 0.3)), Placement(position=(0, 0, 0.2)))
    simulate(world, 0.01)  # run_steps compiled (its callees with it) or loaded
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
    calls = [call for unit in step_units(model, opt, data) for call in unit]
    kernels = {call.kernel for call in calls}
    assert kernels >= {pair_contacts, st._time_of_impact, resolve, st._move_semi_implicit}
    for call in calls:
        wanted = tuple(nb.typeof(a) for a in call.args)
        cached = _cached_signatures(call.kernel)
        name = call.kernel.py_func.__name__
        # whoever compiled them (the units, or run_steps alone), one type signature each
        assert cached == [wanted], f"{name}: units compile {wanted}, the cache holds {cached}"
