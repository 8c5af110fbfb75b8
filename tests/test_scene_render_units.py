"""patches.scene_io.compile_render: the sound kernels a rigid scene's helper compiles before
the physics has run are those its render asks for: the stand-in graph holds the same kinds
of node as the wok's real graph, and its score makes every kind of parameter change the
real score makes (a node's kernels and their argument types follow from its kind and the
changes made to it: the ugens' buffers are their own float64 arrays)."""

from __future__ import annotations

import pytest

from jassy.engines.coldstart import _score_changes
from patches.rigid_sound import contact_locator, scene_graph
from patches.scene_io import _radiated, compile_render
from patches.wok import simulate_wok
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
        lambda graph, options, score: seen.update(graph=graph, options=options, score=score),
    )
    compile_render(world, voices, 48000, 64)
    stand_in = _shapes(seen["graph"], seen["score"])
    assert set(stand_in) == set(real)
    for kind, shapes in real.items():
        assert shapes <= stand_in[kind], (
            f"{kind.__name__}: the render changes {shapes}, the units {stand_in[kind]}"
        )
    assert seen["options"] == {"sample_rate": 48000, "block": 64, "limiter": False}
