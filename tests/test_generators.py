"""Score generators ([[generate]]): Poisson and regular times, seeded argument distributions."""

import numpy as np
import pytest

from jassy.errors import JassyError
from jassy.generators import MAX_GENERATED, expand
from jassy.modal_model import ModalModel
from jassy.patchfile import load_patch

MODEL = ModalModel(np.array([440.0]), np.array([3.0]), np.ones((7, 1)), (), "m")


def _events(times, args=None, start=0.0, stop=100.0, seed=3):
    table = {"node": "hit", "action": "impact", "times": times, "start": start, "stop": stop, "seed": seed}
    if args is not None:
        table["args"] = args
    return [entry for _, entry in expand([table], {"m": MODEL}, None, "p.toml")]


def test_poisson_times_have_the_rate_and_exponential_gaps():
    rate, span = 50.0, 100.0
    t = np.array([e["time"] for e in _events({"poisson": rate}, stop=span)])
    assert abs(t.size - rate * span) < 4 * np.sqrt(rate * span)
    gaps = np.diff(t)
    assert gaps.mean() == pytest.approx(1 / rate, rel=0.05)
    assert gaps.std() / gaps.mean() == pytest.approx(1.0, abs=0.05)  # exponential: CV = 1
    assert np.all(t >= 0) and np.all(t < span) and np.all(np.diff(t) > 0)


def test_regular_times_and_seeded_draws():
    t = [e["time"] for e in _events({"every": 0.25}, start=1.0, stop=3.0)]
    assert t == pytest.approx([1.0 + 0.25 * k for k in range(8)])
    args = {"impulse": {"loguniform": [1e-4, 1e-2]}, "location": {"random_point": "m"}, "duration": 0.001}
    a = _events({"poisson": 20.0}, args)
    assert a == _events({"poisson": 20.0}, args)  # same seed, same events
    assert a != _events({"poisson": 20.0}, args, seed=4)
    imp = np.array([e["impact"]["impulse"] for e in a])
    assert imp.min() >= 1e-4 and imp.max() <= 1e-2
    assert np.mean(np.log10(imp)) == pytest.approx(-3.0, abs=0.1)  # log-uniform: mean of log at the middle
    assert {e["impact"]["location"] for e in a} == set(range(7))
    assert all(e["impact"]["duration"] == 0.001 for e in a)


@pytest.mark.parametrize(
    ("times", "args", "match"),
    [
        ({"poisson": -1.0}, None, r"generate\[0\]\.times\.poisson"),
        ({"sometimes": 1.0}, None, r"generate\[0\]\.times: expected"),
        (
            {"poisson": 1.0},
            {"impulse": {"gaussian": [1, 2]}},
            r"args\.impulse: unknown distribution 'gaussian'",
        ),
        ({"poisson": 1.0}, {"impulse": {"loguniform": [0.0, 1.0]}}, r"loguniform: expected 0 < lo"),
        ({"poisson": 1.0}, {"location": {"random_point": "nope"}}, r"unknown model 'nope'"),
        ({"poisson": 1e9}, None, f"at most {MAX_GENERATED}"),
    ],
)
def test_bad_generators_name_the_key(times, args, match):
    with pytest.raises(JassyError, match=match):
        _events(times, args)


def test_rain_patch_generates_drops_over_the_whole_sheet():
    patch = load_patch("rain")
    impacts = [e for e in patch.score if e.action == "impact"]
    assert 400 < len(impacts) < 1400  # 40/s for 3.5 s and 180/s for 5 s
    assert [e.time for e in patch.score] == sorted(e.time for e in patch.score)
    uv = np.array([(e.args["location"].u, e.args["location"].v) for e in impacts])  # anywhere on it
    assert np.unique(uv, axis=0).shape[0] == len(impacts)
    quarters = np.histogram2d(uv[:, 0], uv[:, 1], bins=2, range=[[0, 1], [0, 1]])[0]
    assert quarters.min() > len(impacts) / 4 - 4 * np.sqrt(len(impacts) / 4)


def test_door_knock_example_knocks_when_it_says():
    from pathlib import Path

    from jassy.engines.offline import render

    patch = load_patch(Path(__file__).parent.parent / "examples" / "door_knock.toml")
    out = render(patch.graph, patch.score, patch.duration)
    force = out.haptic[0] > 0  # the knuckle's contact force, on the audio clock
    onsets = np.flatnonzero(force[1:] & ~force[:-1]) + 1
    np.testing.assert_allclose(onsets / out.sample_rate, [0.1, 0.27, 0.44, 1.3, 1.52], atol=1e-4)
    assert 10 ** (-30 / 20) < np.abs(out.audio).max() < 10 ** (-6 / 20)


def test_object_library_points_are_the_models_points():
    import os

    import patches
    from patches.objects import OBJECTS

    for name, info in OBJECTS.items():
        model = ModalModel.load(os.path.join(os.path.dirname(patches.__file__), info.file))
        assert list(model.points) == list(info.points), name


#: A model with a track t0 .. t2 and three points between t0 and t1 (t0_1 .. t0_3 at s = 0.25,
#: 0.5, 0.75), stored out of order; its gains are linear in the track coordinate s, so the
#: track's linear shape functions reproduce them exactly anywhere along it.
TRACK_S = {"t0": 0.0, "t2": 2.0, "t0_2": 0.5, "t1": 1.0, "t0_1": 0.25, "t0_3": 0.75}
SLOPES = np.array([1.0, -2.0, 0.5])


def linear_gains(s):
    return 3.0 + np.multiply.outer(s, SLOPES)


TRACKED = ModalModel(
    np.array([300.0, 500.0, 900.0]), np.full(3, 5.0), linear_gains(np.array(list(TRACK_S.values()))),
    tuple(TRACK_S), "plank",
)  # fmt: skip


def test_random_on_track_draws_points_uniform_along_the_track_with_interpolated_gains():
    from scipy.stats import kstest

    table = {"node": "hit", "action": "impact", "times": {"every": 0.001}, "stop": 3.0, "seed": 5,
             "args": {"location": {"random_on_track": "plank"}}}  # fmt: skip
    locations = [e["impact"]["location"] for _, e in expand([table], {"plank": TRACKED}, None, "p.toml")]
    assert len(locations) == 3000
    s = np.array(
        [
            sum(w * TRACK_S[v] for v, w in zip(loc["vertices"], loc["weights"], strict=True))
            for loc in locations
        ]
    )
    assert kstest(s / 2.0, "uniform").pvalue > 1e-3  # uniform in distance over the whole track
    hit = {tuple(loc["vertices"]) for loc in locations}
    assert hit == {("t0", "t0_1"), ("t0_1", "t0_2"), ("t0_2", "t0_3"), ("t0_3", "t1"), ("t1", "t2")}
    for loc, at in zip(locations[:200], s[:200], strict=True):
        assert min(loc["weights"]) >= 0 and sum(loc["weights"]) == pytest.approx(1.0)
        np.testing.assert_allclose(TRACKED.gains_at(loc), linear_gains(at), rtol=1e-12)


def test_random_on_track_needs_a_model_with_a_track():
    table = {"node": "hit", "action": "impact", "times": {"every": 0.5}, "stop": 1.0,
             "args": {"location": {"random_on_track": "m"}}}  # fmt: skip
    with pytest.raises(JassyError, match=r"args\.location\.random_on_track: model 'm' has no track"):
        expand([table], {"m": MODEL}, None, "p.toml")


def test_a_patch_scatters_hail_along_the_steel_plate_track():
    from pathlib import Path

    from jassy import render
    from jassy.patchfile import build_patch

    data = {
        "patch": {"name": "hail", "duration": 0.3},
        "models": {"plate": {"file": "steel_plate_model.toml"}},
        "nodes": {"stones": {"type": "ImpactForce"},
                  "plate": {"type": "ModalBank", "model": "plate", "input": "stones"}},
        "outputs": {"audio": "plate"},
        "generate": [{"node": "stones", "action": "impact", "times": {"poisson": 100.0}, "seed": 3,
                      "args": {"impulse": 1e-4, "location": {"random_on_track": "plate"}}}],
    }  # fmt: skip
    patch = build_patch(data, "hail.toml", Path(__file__).resolve().parents[1] / "patches")
    impacts = [e for e in patch.score if e.action == "impact"]
    assert len(impacts) > 10
    plate = patch.graph.nodes["plate"].values["model"]
    on_track = set(plate.track.names)
    assert all(
        len(e.args["location"].vertices) == 2 and set(e.args["location"].vertices) <= on_track
        for e in impacts
    )
    between = {v for e in impacts for v in e.args["location"].vertices if "_" in v}
    assert between  # the points between the named ones are reached, not only t0 .. t8
    audio = render(patch.graph, patch.score, 0.3, limiter=False).audio[0]
    assert np.all(np.isfinite(audio)) and np.abs(audio).max() > 0
