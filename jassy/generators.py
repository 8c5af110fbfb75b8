"""Score generators: ``[[generate]]`` tables that expand into score events when a patch loads.

A generator repeats one action of one node at regular or random times between ``start`` and
``stop`` (s), drawing each argument from a distribution: SuperCollider's ``Dust`` and
``Impulse`` as score events, so they reach every ugen action (impacts with their locations,
bubbles, parameter sets) and render the same at any block size. ::

    [[generate]]
    node = "drops"                 # the node that takes the action
    action = "impact"              # any action of the node's type, or "set"
    times = { poisson = 300.0 }    # events/s at exponential intervals; or { every = 0.25 } s
    start = 0.0                    # s (default 0)
    stop = 6.0                     # s (default: the patch's duration)
    seed = 7                       # random draws are seeded: the same patch, the same events
    [generate.args]                # per event: a number, a string, or a distribution:
    impulse = { loguniform = [2e-5, 4e-4] }      # N s, log-uniform between the bounds
    duration = { uniform = [1e-4, 3e-4] }        # s
    location = { random_point = "sheet" }         # a uniformly random location of model "sheet"

Distributions: ``{uniform = [lo, hi]}``, ``{loguniform = [lo, hi]}`` (0 < lo), ``{normal =
[mean, sd]}``, ``{choice = [a, b, ...]}``, ``{random_point = MODEL}`` (a vertex index of that
[models] entry, uniform over its locations), ``{random_on_track = MODEL}`` (a point uniform
in distance along the model's texture track t0, t1, ... (jassy.tracks), anywhere between its
points: the barycentric location of the two track points around it, whose gains are then
interpolated with the track's linear shape functions), ``{random_on_surface = MODEL}`` (a
point uniform over the area of a model with an analytic surface, jassy.surface: the location
``{surface = [u, v]}``, whose gains are the mode shapes there). Poisson times: intervals drawn from
an exponential distribution of mean 1/rate (a homogeneous Poisson process).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from jassy.errors import PatchError, suggest
from jassy.inputs import number, seconds, text_value

#: Most events one generator may produce (a patch with more is refused, not rendered).
MAX_GENERATED = 200_000
GENERATOR_KEYS = {"node", "action", "times", "start", "stop", "seed", "args"}
DISTRIBUTIONS = (
    "uniform", "loguniform", "normal", "choice", "random_point", "random_on_track", "random_on_surface",
)  # fmt: skip


def _model_name(value: Any, models: dict, key: str) -> str:
    """The name of a [models] entry given at ``key``, checked against the patch's models."""
    name = text_value(value, key, "the name of a [models] entry")
    if name not in models:
        raise PatchError(
            f"{key}: unknown model {name!r}; models are {', '.join(models) or 'none'}{suggest(name, models)}"
        )
    return name


def _on_track(value: Any, rng: np.random.Generator, models: dict, where: str):
    """A function drawing a location uniform in distance along a model's track: the two
    track points around a uniform coordinate s, weighted by the linear shape functions."""
    name = _model_name(value, models, f"{where}.random_on_track")
    track = models[name].track
    if track is None:
        raise PatchError(
            f"{where}.random_on_track: model {name!r} has no track (points t0, t1, ... along a line); "
            "random_point draws among its points"
        )
    coords, names = track.coordinates, track.names

    def draw() -> dict:
        i, x = track.segment(float(rng.uniform(coords[0], coords[-1])))
        return {"vertices": [names[i], names[i + 1]], "weights": [1.0 - x, x]}

    return draw


def _on_surface(value: Any, rng: np.random.Generator, models: dict, where: str):
    """A function drawing a point uniform over the area of a model's analytic surface: for a
    rectangle, (u, v) = (x / a, y / b) uniform on the unit square."""
    name = _model_name(value, models, f"{where}.random_on_surface")
    if models[name].surface is None:
        raise PatchError(
            f"{where}.random_on_surface: model {name!r} has no surface (analytic mode shapes, as the "
            "plate builder's models carry); random_point draws among its points"
        )
    return lambda: {"surface": [float(x) for x in rng.uniform(0.0, 1.0, 2)]}


def _draw(spec: Any, rng: np.random.Generator, models: dict, where: str):
    """A function of no arguments drawing one value of ``spec`` (validated now)."""
    if not isinstance(spec, dict):
        return lambda: spec
    if len(spec) != 1:
        raise PatchError(f"{where}: expected one distribution ({{uniform = [lo, hi]}}, ...), got {spec!r}")
    ((kind, value),) = spec.items()
    if kind == "random_point":
        n = models[_model_name(value, models, f"{where}.random_point")].n_points
        return lambda: int(rng.integers(n))
    if kind == "random_on_track":
        return _on_track(value, rng, models, where)
    if kind == "random_on_surface":
        return _on_surface(value, rng, models, where)
    if kind == "choice":
        if not isinstance(value, list) or not value:
            raise PatchError(f"{where}.choice: expected a non-empty list")
        return lambda: value[int(rng.integers(len(value)))]
    if kind not in ("uniform", "loguniform", "normal"):
        raise PatchError(
            f"{where}: unknown distribution {kind!r}; expected one of {', '.join(DISTRIBUTIONS)}"
            f"{suggest(kind, DISTRIBUTIONS)}"
        )
    if not isinstance(value, list) or len(value) != 2:
        raise PatchError(f"{where}.{kind}: expected two numbers, got {value!r}")
    a, b = (number(v, f"{where}.{kind}") for v in value)
    if kind == "uniform":
        if not a <= b:
            raise PatchError(f"{where}.uniform: expected lo <= hi, got {value!r}")
        return lambda: float(rng.uniform(a, b))
    if kind == "loguniform":
        if not 0 < a <= b:
            raise PatchError(f"{where}.loguniform: expected 0 < lo <= hi, got {value!r}")
        return lambda: float(np.exp(rng.uniform(np.log(a), np.log(b))))
    if b < 0:
        raise PatchError(f"{where}.normal: expected a standard deviation >= 0, got {b}")
    return lambda: float(rng.normal(a, b))


def _times(spec: Any, start: float, stop: float, rng: np.random.Generator, where: str) -> np.ndarray:
    if not isinstance(spec, dict) or len(spec) != 1 or next(iter(spec)) not in ("poisson", "every"):
        raise PatchError(
            f"{where}: expected {{poisson = events per second}} or {{every = seconds}}, got {spec!r}"
        )
    ((kind, value),) = spec.items()
    if kind == "every":
        period = seconds(value, f"{where}.every")
        count = int(np.floor((stop - start) / period + 1e-9)) + 1
        if count > MAX_GENERATED:
            raise PatchError(f"{where}: {count} events; at most {MAX_GENERATED} per generator")
        times = start + period * np.arange(count)
        return times[times < stop] if stop > start else times[:0]
    rate = number(value, f"{where}.poisson", 0.0, None, low_open=True)
    expected = rate * (stop - start)
    if expected > MAX_GENERATED:
        raise PatchError(f"{where}: about {expected:.0f} events; at most {MAX_GENERATED} per generator")
    n = int(expected + 10 * np.sqrt(expected) + 10)
    times = start + np.cumsum(rng.exponential(1.0 / rate, n))
    return times[times < stop]


def expand(entries: Any, models: dict, duration: float | None, where: str) -> list[tuple[str, dict]]:
    """(name for errors, score entry as a [[score]] table) of every event that the
    ``[[generate]]`` tables ``entries`` generate."""
    if not isinstance(entries, list):
        raise PatchError(f"{where}: generate: expected an array of tables ([[generate]])")
    out: list[tuple[str, dict]] = []
    for i, table in enumerate(entries):
        key = f"{where}: generate[{i}]"
        if not isinstance(table, dict):
            raise PatchError(f"{key}: expected a table")
        for name in table:
            if name not in GENERATOR_KEYS:
                raise PatchError(
                    f"{key}.{name}: unknown key; expected one of {', '.join(sorted(GENERATOR_KEYS))}"
                    f"{suggest(name, GENERATOR_KEYS)}"
                )
        for name in ("node", "action", "times"):
            if name not in table:
                raise PatchError(f"{key}.{name}: missing")
        node = text_value(table["node"], f"{key}.node", "the name of a node")
        action = text_value(table["action"], f"{key}.action", "the name of an action")
        start = seconds(table.get("start", 0.0), f"{key}.start", allow_zero=True)
        if "stop" in table:
            stop = seconds(table["stop"], f"{key}.stop")
        elif duration is not None:
            stop = float(duration)
        else:
            raise PatchError(f"{key}.stop: missing (the patch sets no duration)")
        seed = int(number(table.get("seed", 0), f"{key}.seed", 0, 2**63 - 1, integer=True))
        rng = np.random.default_rng(seed)
        args = table.get("args", {})
        if not isinstance(args, dict):
            raise PatchError(f"{key}.args: expected a table of arguments")
        draws = {name: _draw(spec, rng, models, f"{key}.args.{name}") for name, spec in args.items()}
        for t in _times(table["times"], start, stop, rng, f"{key}.times"):
            entry = {"time": float(t), "node": node, action: {name: draw() for name, draw in draws.items()}}
            out.append((f"{key} (event at {t:.4f} s)", entry))
    return out
