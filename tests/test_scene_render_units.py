"""patches.scene_io.compile_render: the sound kernels a rigid scene's helper compiles before
the physics has run are those its render asks for: the stand-in graph holds the same kinds
of node as the wok's real graph, and its score makes every kind of parameter change the
real score makes (a node's kernels and their argument types follow from its kind and the
changes made to it: the ugens' buffers are their own float64 arrays). compile_events calls
the contact-event kernels with the argument types the wok's real events ask for."""

from __future__ import annotations

import numba
import pytest

from jassy.engines.coldstart import _score_changes
from patches.rigid_sound import contact_locator, scene_graph
from patches.scene_io import _radiated, compile_events, compile_render
from patches.wok import simulate_wok
from physics.rigid import events
from physics.rigid.events import contact_tracks, impacts


def _shapes(graph, score) -> dict[type, set]:
    """Per kind of node of ``graph``: the shapes (keys set, jump, own smoothing) of the
    parameter changes ``score`` makes to it."""
    changes = _score_changes(graph, score)
    kinds = {type(node) for node in graph.order}
    shape = lambda c: (tuple(sorted(c.values)), c.jump, c.ramp is None)  # noqa: E731
    return {kind: {shape(c) for c in changes.get(kind, [])} for kind in kinds}


@pytest.mark.timeout(600)  # the wok's rigid step compiles when the kernel cache is empty
def test_the_stand_in_graph_has_the_real_renders_kinds_and_changes(monkeypatch):
    world, voices, result = simulate_wok(duration=0.6)
    hits = impacts(result, locate=contact_locator(world, voices))
    tracks = contact_tracks(result)
    assert hits and tracks, "the short wok run has impacts and sustained contacts"
    real_graph, real_score = scene_graph(world.bodies, hits, tracks, voices)
    real = _shapes(_radiated(real_graph, 0.18), real_score)

    seen = {}
    monkeypatch.setattr(
        "jassy.engines.coldstart.compile_graph",
        lambda graph, options, score, part: seen.update(graph=graph, options=options, score=score),
    )
    compile_render(world, voices, 48000, 64)
    stand_in = _shapes(seen["graph"], seen["score"])
    assert set(stand_in) == set(real)
    for kind, shapes in real.items():
        assert shapes <= stand_in[kind], (
            f"{kind.__name__}: the render changes {shapes}, the units {stand_in[kind]}"
        )
    assert seen["options"] == {"sample_rate": 48000, "block": 64, "limiter": False}


#: The compiled kernels of physics.rigid.events (those compile_events must reach).
EVENT_KERNELS = ("_impact_groups", "_sustained_columns", "_step_groups", "_rows_on", "_wrench_sums")


def _event_argument_types(monkeypatch, run) -> dict[str, set]:
    """The numba argument types each event kernel is called with while ``run()`` runs."""
    seen = {name: set() for name in EVENT_KERNELS}
    for name in EVENT_KERNELS:
        kernel = getattr(events, name)

        def recording(*args, _name=name, _kernel=kernel):
            seen[_name].add(tuple(numba.typeof(a) for a in args))
            return _kernel(*args)

        monkeypatch.setattr(events, name, recording)
    run()
    monkeypatch.undo()
    return seen


@pytest.mark.timeout(600)  # the wok's rigid step compiles when the kernel cache is empty
def test_compile_events_calls_each_event_kernel_with_the_real_runs_types(monkeypatch):
    from patches.wok import HANDLE, hand_path
    from physics.rigid.spatial import rotation_matrices

    world, voices, result = simulate_wok(duration=0.6)

    def hand(t):
        p, q = hand_path(t)
        return p + rotation_matrices(q) @ HANDLE

    def real_events():
        impacts(result, locate=contact_locator(world, voices))
        contact_tracks(result)
        events.contact_wrench(result, world.index("wok"), hand)

    real = _event_argument_types(monkeypatch, real_events)
    stand_in = _event_argument_types(monkeypatch, lambda: compile_events(world))
    for name in EVENT_KERNELS:
        assert real[name], f"{name}: not called by the wok's events"
        assert real[name] == stand_in[name], f"{name}: the run {real[name]}, compile_events {stand_in[name]}"


def test_the_sound_units_run_each_unit_of_the_graph_once_the_modal_banks_last(monkeypatch):
    """render_units shares the stand-in graph's compile units out one at a time: together
    they run every unit of the graph exactly once, and the last (the helper's first) is the
    modal banks'."""
    from jassy.engines import coldstart
    from patches.scene_io import render_units
    from patches.wok import build_world

    ran: list[str] = []
    monkeypatch.setattr(coldstart, "kernels_cached", lambda: False)
    monkeypatch.setattr(coldstart, "_process_alone", lambda node, *args: ran.append(type(node).__name__))
    monkeypatch.setattr(coldstart, "_compile_strike_records", lambda **options: ran.append("strike records"))
    monkeypatch.setattr(coldstart, "_render_stand_in", lambda *args: ran.append("stand-in render"))
    world, voices = build_world()
    units = render_units(world, voices, 48000, 4096)
    for unit in units[1:]:
        unit()
    every = ran[:]
    ran.clear()
    render_units(world, voices, 48000, 4096)[-1]()
    assert ran == ["ModalBank"]
    ran.clear()
    compile_render(world, voices, 48000, 4096)  # the graph's units, all, in one call
    assert sorted(every) == sorted(ran), "each unit of the graph once"
    assert {"ModalBank", "Scrape", "strike records", "stand-in render"} <= set(ran)
