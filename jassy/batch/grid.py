"""Grid files for ``jassy batch``: which patches, which parameters, which values.

A grid file is TOML::

    [batch]                 name, description, manifest = "csv" | "parquet"
    [render]                duration (s), sample_rate (Hz), block, format, container ("wav"|"flac"),
                            haptic ("wav"|"npz"|"csv": also write the force track)
    [patches.NAME]          optional inline patches (the layout of a patch file; model
                            paths relative to the grid file)
    patch = "bar"           one sweep at the top level: patch name(s), then
    [set]                   fixed overrides,
    [grid]                  key -> list of values (the full product), or a factor:
                            [grid.material] metal = {"bar.decay_scale" = 1.0, ...} (named levels)
    [random]                n, seed, key -> {uniform = [lo, hi]} | {loguniform = [lo, hi]} |
                            {choice = [...]} | {randint = [lo, hi]} (n draws per grid point)
    [[sweep]]               or several sweeps, each with patch, set, grid, random, render

Keys: ``node.param`` (a node parameter, like ``jassy render --set``),
``score[i].time`` / ``.jump`` / ``.ramp`` / ``score[i].ACTION.ARG`` (an entry of the patch's
score, e.g. ``score[0].impact.impulse``), ``models.NAME.file`` (a model file, relative to
the grid file) and ``render.duration`` / ``.sample_rate`` / ``.block`` / ``.format``.
Keys are checked against each patch before anything runs; values are checked when each
variant is built, so a bad value fails that variant only (recorded in the manifest).

Every variant has an identity: a SHA-256 of the patch content (patch file and model
files), the overrides and the render options. It names the output file
(``<patch>-<id12>.wav``) and lets a rerun skip variants already rendered.
"""

from __future__ import annotations

import copy
import hashlib
import itertools
import json
import math
import os
import re
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from jassy.errors import JassyError, PatchError, suggest
from jassy.files import AUDIO_SUBTYPES
from jassy.inputs import decode, load_toml, parse_toml, read_bytes, regular_file, seconds
from jassy.limits import check_seconds, check_variants

#: Bumped when the identity scheme or the rendering of a variant changes meaning.
ID_VERSION = 1
GRID_KEYS = {"batch", "render", "patches", "patch", "set", "grid", "random", "sweep"}
SWEEP_KEYS = {"patch", "set", "grid", "random", "render"}
BATCH_KEYS = {"name", "description", "manifest"}
RENDER_KEYS = {"duration", "sample_rate", "block", "format", "container", "haptic"}
SWEEPABLE_RENDER = ("duration", "sample_rate", "block", "format")
DISTRIBUTIONS = ("uniform", "loguniform", "choice", "randint")
HAPTIC_FORMATS = ("wav", "npz", "csv")
#: Manifest columns around the parameter columns (HAPTIC when haptic tracks are written);
#: a factor cannot take one of these names.
HEAD = ["index", "variant", "patch"]
TAIL = [
    "output",
    "status",
    "error",
    "duration",
    "sample_rate",
    "frames",
    "peak",
    "peak_dbfs",
    "sha256",
    "warnings",
    "render_s",
    "worker",
]
HAPTIC = ["haptic_output", "haptic_sha256"]
RESERVED_COLUMNS = [*HEAD, *TAIL, *HAPTIC]
_SCORE_KEY = re.compile(r"^score\[(\d+)\]\.(.+)$")
_SAFE_NAME = re.compile(r"[^A-Za-z0-9_.-]+")


class GridError(JassyError):
    """A grid file is invalid. The message names the grid file and the key."""


@dataclass(frozen=True)
class RenderOptions:
    """How every variant of a sweep is rendered (None: the patch's own default)."""

    duration: float | None = None
    sample_rate: int | None = None
    block: int = 64
    format: str = "float32"
    container: str = "wav"
    haptic: str | None = None

    def as_dict(self) -> dict:
        return {k: getattr(self, k) for k in sorted(RENDER_KEYS)}


@dataclass
class PatchSource:
    """One patch of a grid: its parsed TOML, where it came from and a digest of its content."""

    name: str
    source: str
    data: dict
    base: Path
    digest: str
    param_nodes: dict[str, Any] = field(default_factory=dict)  # node name -> built UGen (for checks)


@dataclass
class Variant:
    """One rendering: a patch, its overrides (key -> value) and render options."""

    index: int
    patch: PatchSource
    overrides: dict[str, Any]
    labels: dict[str, Any]
    render: RenderOptions
    id: str = ""
    filename: str = ""
    haptic_filename: str = ""
    model_files: dict[str, Path] = field(default_factory=dict)  # [models] name -> file
    model_digests: dict[str, str] = field(default_factory=dict)  # [models] name -> SHA-256


@dataclass
class Grid:
    """A parsed grid file: its variants in order, and the columns of their manifest."""

    path: Path
    name: str
    description: str
    manifest: str
    variants: list[Variant]
    columns: list[str]
    duplicates: int = 0


def canonical(value: Any) -> str:
    """Canonical JSON (sorted keys, no spaces, floats by repr) for hashing and manifests."""
    return json.dumps(value, sort_keys=True, separators=(",", ":"), ensure_ascii=True, allow_nan=False)


def sha256_bytes(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def sha256_file(path: str | os.PathLike) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


# ---------------------------------------------------------------------------- parsing


def _quoted(section: str, key: str) -> str:
    return f'{section}."{key}"'


def _check_value_type(value: Any, where: str) -> None:
    """Only TOML data that JSON can hold (no dates, no NaN or Inf) can be a parameter value."""
    try:
        canonical(value)
    except (TypeError, ValueError):
        key, bad = _unstorable(value, where)
        raise GridError(
            f"{key}: expected a finite number, string, boolean, array or table, got {bad!r}"
        ) from None


def _unstorable(value: Any, where: str) -> tuple[str, Any]:
    """(key, value) of the first item JSON cannot hold (NaN, Inf, a date) in ``value``."""
    stack = [(value, where)]
    while stack:
        item, key = stack.pop()
        if isinstance(item, dict):
            stack.extend((v, f"{key}.{k}") for k, v in item.items())
        elif isinstance(item, list):
            stack.extend((v, f"{key}[{i}]") for i, v in enumerate(item))
        elif not isinstance(item, (str, int, float, bool)) or (
            isinstance(item, float) and not math.isfinite(item)
        ):
            return key, item
    return where, value


def _render_options(table: Any, where: str, base: RenderOptions | None = None) -> RenderOptions:
    if not isinstance(table, dict):
        raise GridError(f"{where}: expected a table")
    for key in table:
        if key not in RENDER_KEYS:
            raise GridError(
                f"{where}.{key}: unknown key; expected {', '.join(sorted(RENDER_KEYS))}"
                f"{suggest(key, RENDER_KEYS)}"
            )
    values = (base or RenderOptions()).as_dict()
    values.update(table)
    opts = RenderOptions(**values)
    _check_render(opts, where)
    return opts


def _check_render(opts: RenderOptions, where: str) -> None:
    if opts.duration is not None:
        try:
            check_seconds(seconds(opts.duration, f"{where}.duration"), f"{where}.duration")
        except JassyError as exc:
            raise GridError(str(exc)) from None
    r = opts.sample_rate
    if r is not None and (isinstance(r, bool) or not isinstance(r, int) or not 1000 <= r <= 768000):
        raise GridError(f"{where}.sample_rate: expected an integer rate in [1000, 768000] Hz, got {r!r}")
    b = opts.block
    if isinstance(b, bool) or not isinstance(b, int) or not 1 <= b <= 2**20:
        raise GridError(f"{where}.block: expected an integer in [1, {2**20}], got {b!r}")
    if opts.format not in AUDIO_SUBTYPES:
        raise GridError(
            f"{where}.format: expected one of {', '.join(AUDIO_SUBTYPES)}, got {opts.format!r}"
            f"{suggest(opts.format, AUDIO_SUBTYPES)}"
        )
    if opts.container not in ("wav", "flac"):
        raise GridError(f"{where}.container: expected 'wav' or 'flac', got {opts.container!r}")
    if opts.container == "flac" and opts.format == "float32":
        raise GridError(f"{where}.format: FLAC stores integers; use 'pcm16' or 'pcm24'")
    if opts.haptic is not None and opts.haptic not in HAPTIC_FORMATS:
        raise GridError(
            f"{where}.haptic: expected one of {', '.join(HAPTIC_FORMATS)}, got {opts.haptic!r}"
            f"{suggest(opts.haptic, HAPTIC_FORMATS)}"
        )


def _load_patch_source(spec: Any, inline: dict, grid_path: Path, where: str) -> PatchSource:
    """Resolve a sweep's ``patch`` entry: inline [patches.NAME], a file (relative to the grid) or built-in."""
    from jassy.patchfile import builtin_patches

    if not isinstance(spec, str) or not spec:
        raise GridError(f"{where}: expected a patch name or path, got {spec!r}")
    if spec in inline:
        table = inline[spec]
        if not isinstance(table, dict):
            raise GridError(f"{grid_path}: patches.{spec}: expected a table (the layout of a patch file)")
        _check_value_type(table, f"{grid_path}: patches.{spec}")
        digest = sha256_bytes(canonical(table).encode())
        return PatchSource(spec, f"{grid_path}: patches.{spec}", table, grid_path.parent, digest)
    path = Path(spec)
    if path.suffix == ".toml" or os.sep in spec or "/" in spec:
        path = path if path.is_absolute() else grid_path.parent / path
        if not path.is_file():
            raise GridError(f"{where}: {spec}: no such patch file (paths are relative to the grid file)")
    else:
        builtins = builtin_patches()
        if spec not in builtins:
            names = sorted(set(builtins) | set(inline))
            raise GridError(
                f"{where}: {spec!r} is not an inline patch ([patches.NAME]), a patch file or a built-in "
                f"patch; known: {', '.join(names)}"
            )
        path = builtins[spec]
    try:
        raw = read_bytes(path, "patch file")
        data = parse_toml(decode(raw, str(path)), str(path))
    except JassyError as exc:
        raise GridError(str(exc)) from None
    return PatchSource(path.stem, str(path), data, path.parent, sha256_bytes(raw))


def _check_patch(patch: PatchSource) -> None:
    """Build the patch once as given: a broken base patch is an input error, not 3000 failed variants."""
    from jassy.patchfile import build_patch

    built = build_patch(copy.deepcopy(patch.data), patch.source, patch.base)
    patch.param_nodes = dict(built.graph.nodes)


def _score_action(entry: dict) -> str | None:
    actions = [k for k in entry if k not in ("time", "node", "jump", "ramp")]
    return actions[0] if len(actions) == 1 else None


def check_key(key: str, patch: PatchSource, where: str) -> None:
    """Raise GridError unless ``key`` names something that can be overridden in ``patch``."""
    at = f"{where} (patch {patch.name})"
    if key.startswith("render."):
        opt = key[len("render.") :]
        if opt not in SWEEPABLE_RENDER:
            raise GridError(
                f"{where}: render option {opt!r} cannot vary; expected {', '.join(SWEEPABLE_RENDER)}"
            )
        return
    if key.startswith("models."):
        parts = key.split(".")
        models = patch.data.get("models", {})
        if len(parts) != 3 or parts[2] != "file":
            raise GridError(f"{where}: expected models.NAME.file (a model file, relative to the grid file)")
        if parts[1] not in models:
            known = ", ".join(models) or "none"
            raise GridError(
                f"{at}: unknown model {parts[1]!r}; models are {known}{suggest(parts[1], models)}"
            )
        return
    match = _SCORE_KEY.match(key)
    if match:
        index, rest = int(match.group(1)), match.group(2)
        score = patch.data.get("score", [])
        if index >= len(score):
            raise GridError(
                f"{at}: the patch's score has {len(score)} entries (score[0] .. score[{len(score) - 1}])"
            )
        entry = score[index]
        if rest in ("time", "jump", "ramp"):
            return
        action = _score_action(entry)
        act, dot, arg = rest.partition(".")
        if not dot or "." in arg:
            raise GridError(f"{at}: expected score[{index}].time, .jump, .ramp or .{action}.ARGUMENT")
        if act != action:
            raise GridError(f"{at}: score[{index}] is a {action!r} event, not {act!r}")
        node = patch.param_nodes.get(entry.get("node"))
        specs = node.all_specs() if act == "set" else node.actions.get(act, {})
        if arg not in specs:
            raise GridError(
                f"{at}: {node.type_name} {act} has no argument {arg!r}; expected {', '.join(specs)}"
            )
        return
    node_name, dot, param = key.partition(".")
    if not dot or not node_name or not param or "." in param or "[" in key:
        raise GridError(
            f"{where}: expected node.param, score[i].ACTION.ARG, score[i].time, models.NAME.file or "
            "render.OPTION"
        )
    nodes = patch.data.get("nodes", {})
    if node_name not in nodes:
        raise GridError(
            f"{at}: unknown node {node_name!r}; nodes are {', '.join(nodes)}{suggest(node_name, nodes)}"
        )
    node = patch.param_nodes[node_name]
    if param in ("type", "input", "inputs") or param in node.inputs:
        raise GridError(f"{at}: only parameters can vary, not {param!r}")
    specs = node.all_specs()
    if param not in specs:
        raise GridError(f"{at}: {node.type_name} has no parameter {param!r}; expected {', '.join(specs)}")


def check_value(key: str, value: Any, patch: PatchSource, where: str) -> None:
    """Raise GridError unless ``value`` is acceptable for ``key`` (already checked by
    :func:`check_key`) in ``patch``: the parameter's type and range, a time in seconds, a
    boolean jump, a model file name. Checked for every variant before anything renders."""
    at = f"{where} (patch {patch.name})"
    try:
        if key.startswith("render."):
            return
        if key.startswith("models."):
            if not isinstance(value, str) or not value.strip():
                raise GridError(f"{at}: expected a model file name, got {value!r}")
            return
        match = _SCORE_KEY.match(key)
        if match:
            index, rest = int(match.group(1)), match.group(2)
            entry = patch.data["score"][index]
            if rest in ("time", "ramp"):
                seconds(value, at, allow_zero=True)
            elif rest == "jump":
                if not isinstance(value, bool):
                    raise GridError(f"{at}: expected true or false, got {value!r}")
            else:
                node = patch.param_nodes[entry["node"]]
                act, _, arg = rest.partition(".")
                if act == "set":
                    node.check_param(arg, value, at)
                else:
                    node.check_value(node.actions[act][arg], value, at)
            return
        node_name, _, param = key.partition(".")
        patch.param_nodes[node_name].check_param(param, value, at)
    except GridError:
        raise
    except JassyError as exc:
        raise GridError(str(exc)) from None


def apply_overrides(data: dict, overrides: dict[str, Any], grid_dir: Path) -> dict:
    """A copy of patch ``data`` with ``overrides`` applied (keys already checked).

    ``render.*`` keys are ignored here; ``models.NAME.file`` values become absolute paths.
    """
    data = copy.deepcopy(data)
    for key, value in overrides.items():
        if key.startswith("render."):
            continue
        if key.startswith("models."):
            _, name, _ = key.split(".")
            path = Path(value) if isinstance(value, str) else None
            if path is None:
                raise PatchError(f"{key}: expected a model file name, got {value!r}")
            data["models"][name] = {"file": str(path if path.is_absolute() else (grid_dir / path).resolve())}
            continue
        match = _SCORE_KEY.match(key)
        if match:
            entry = data["score"][int(match.group(1))]
            rest = match.group(2)
            if rest in ("time", "jump", "ramp"):
                entry[rest] = copy.deepcopy(value)
            else:
                act, _, arg = rest.partition(".")
                entry[act] = dict(entry[act])
                entry[act][arg] = copy.deepcopy(value)
            continue
        node, _, param = key.partition(".")
        data["nodes"][node] = dict(data["nodes"][node])
        data["nodes"][node][param] = copy.deepcopy(value)
    return data


def _check_distribution(spec: Any, where: str) -> tuple[str, Any]:
    if not isinstance(spec, dict) or len(spec) != 1 or next(iter(spec)) not in DISTRIBUTIONS:
        raise GridError(
            f"{where}: expected one of {{uniform = [lo, hi]}}, {{loguniform = [lo, hi]}}, "
            f"{{choice = [...]}} or {{randint = [lo, hi]}}, got {spec!r}"
        )
    kind, arg = next(iter(spec.items()))
    if kind == "choice":
        if not isinstance(arg, list) or not arg:
            raise GridError(f"{where}.choice: expected a non-empty array of values")
        for i, v in enumerate(arg):
            _check_value_type(v, f"{where}.choice[{i}]")
        return kind, arg
    number = int if kind == "randint" else (int, float)
    if (
        not isinstance(arg, list)
        or len(arg) != 2
        or not all(isinstance(v, number) and not isinstance(v, bool) for v in arg)
        or not all(math.isfinite(v) for v in arg)
        or arg[0] > arg[1]
    ):
        what = "integers" if kind == "randint" else "numbers"
        raise GridError(f"{where}.{kind}: expected [lo, hi], two {what} with lo <= hi, got {arg!r}")
    if kind == "loguniform" and arg[0] <= 0:
        raise GridError(f"{where}.loguniform: expected 0 < lo <= hi, got {arg!r}")
    return kind, arg


def draw(kind: str, arg: Any, seed_material: Any) -> Any:
    """One value of a seeded distribution; the same ``seed_material`` gives the same value anywhere."""
    seed = int.from_bytes(hashlib.sha256(canonical(seed_material).encode()).digest()[:16], "little")
    rng = np.random.Generator(np.random.PCG64(seed))
    if kind == "choice":
        return copy.deepcopy(arg[int(rng.integers(len(arg)))])
    if kind == "randint":
        return int(rng.integers(arg[0], arg[1], endpoint=True))
    u = float(rng.random())
    if kind == "uniform":
        return float(arg[0] + (arg[1] - arg[0]) * u)
    lo, hi = math.log(arg[0]), math.log(arg[1])
    return float(min(max(math.exp(lo + (hi - lo) * u), arg[0]), arg[1]))


@dataclass
class _Factor:
    """One axis of the product: a key with its values, or a named factor with levels."""

    name: str
    levels: list[tuple[Any, dict[str, Any]]]  # (label, overrides)
    keys: list[str]


@dataclass
class _Sweep:
    where: str
    patches: list[PatchSource]
    fixed: dict[str, Any]
    factors: list[_Factor]
    random: dict[str, tuple[str, Any]]
    n_random: int
    seed: int
    render: RenderOptions


def _parse_sweep(table: dict, where: str, grid_path: Path, inline: dict, render: RenderOptions) -> _Sweep:
    if "patch" not in table:
        raise GridError(f"{where}.patch: missing (the patch or patches to render)")
    specs = table["patch"] if isinstance(table["patch"], list) else [table["patch"]]
    if not specs:
        raise GridError(f"{where}.patch: expected at least one patch")
    patches = [_load_patch_source(s, inline, grid_path, f"{where}.patch") for s in specs]
    for patch in patches:
        _check_patch(patch)
    if "render" in table:
        render = _render_options(table["render"], f"{where}.render", render)

    seen: dict[str, str] = {}

    def claim(key: str, section: str) -> None:
        if key in seen:
            raise GridError(f'{where}: "{key}" appears in both [{seen[key]}] and [{section}]; give it once')
        seen[key] = section
        for patch in patches:
            check_key(key, patch, f"{where}: {_quoted(section, key)}")

    fixed = table.get("set", {})
    if not isinstance(fixed, dict):
        raise GridError(f"{where}.set: expected a table of key = value")
    for key, value in fixed.items():
        claim(key, "set")
        _check_value_type(value, f"{where}: {_quoted('set', key)}")

    grid = table.get("grid", {})
    if not isinstance(grid, dict):
        raise GridError(f"{where}.grid: expected a table of key = [values]")
    factors = []
    for key, values in grid.items():
        at = f"{where}: {_quoted('grid', key)}"
        if isinstance(values, dict) and "." not in key and "[" not in key:
            if key in RESERVED_COLUMNS:
                raise GridError(f"{at}: {key!r} is a column of the manifest; give the factor another name")
            if not values:
                raise GridError(f"{at}: expected at least one level (name = {{key = value, ...}})")
            levels, keys = [], []
            for level, overrides in values.items():
                if not isinstance(overrides, dict) or not overrides:
                    raise GridError(f"{at}.{level}: expected a table of key = value for this level")
                for k, v in overrides.items():
                    if k not in keys:
                        claim(k, f"grid.{key}")
                        keys.append(k)
                    _check_value_type(v, f'{at}.{level}."{k}"')
                levels.append((level, dict(overrides)))
            factors.append(_Factor(key, levels, keys))
            continue
        if not isinstance(values, list) or not values:
            raise GridError(f"{at}: expected a non-empty array of values (or a table of named levels)")
        claim(key, "grid")
        for i, v in enumerate(values):
            _check_value_type(v, f"{at}[{i}]")
        factors.append(_Factor(key, [(v, {key: v}) for v in values], [key]))

    rand = table.get("random", {})
    if not isinstance(rand, dict):
        raise GridError(f"{where}.random: expected a table: n, seed and key = {{distribution}}")
    n_random, seed, dists = 0, 0, {}
    if rand:
        n_random = rand.get("n")
        if isinstance(n_random, bool) or not isinstance(n_random, int) or n_random < 1:
            raise GridError(f"{where}.random.n: expected the number of random variants (integer >= 1)")
        seed = rand.get("seed", 0)
        if isinstance(seed, bool) or not isinstance(seed, int):
            raise GridError(f"{where}.random.seed: expected an integer, got {seed!r}")
        for key, spec in rand.items():
            if key in ("n", "seed"):
                continue
            claim(key, "random")
            dists[key] = _check_distribution(spec, f"{where}: {_quoted('random', key)}")
    if render.duration is None and "render.duration" not in seen:
        for patch in patches:
            meta = patch.data.get("patch", {})
            if not isinstance(meta, dict) or meta.get("duration") is None:
                raise GridError(
                    f"{where}: render.duration: patch {patch.name} sets no duration; give one in [render]"
                )
            try:
                check_seconds(
                    seconds(meta["duration"], f"{patch.source}: patch.duration"),
                    f"{where}: patch {patch.name}",
                )
            except JassyError as exc:
                raise GridError(str(exc)) from None
    return _Sweep(where, patches, dict(fixed), factors, dists, n_random, seed, render)


def _apply_render(opts: RenderOptions, overrides: dict[str, Any], where: str) -> RenderOptions:
    values = {k[len("render.") :]: v for k, v in overrides.items() if k.startswith("render.")}
    if not values:
        return opts
    merged = RenderOptions(**{**opts.as_dict(), **values})
    _check_render(merged, where)
    return merged


def _safe(name: str) -> str:
    return _SAFE_NAME.sub("_", name).strip("._") or "patch"


def _model_files(data: dict, base: Path) -> dict[str, Path]:
    out = {}
    for name, entry in data.get("models", {}).items():
        if isinstance(entry, dict) and isinstance(entry.get("file"), str):
            path = Path(entry["file"])
            out[name] = path if path.is_absolute() else (base / path)
    return out


class _Digests:
    """SHA-256 of model files, read once per file per plan."""

    def __init__(self):
        self.cache: dict[Path, str] = {}

    def __call__(self, path: Path, where: str) -> str:
        key = path.resolve()
        if key not in self.cache:
            if not key.is_file():
                raise GridError(f"{where}: model file {path} does not exist")
            try:
                regular_file(key, "model file")
            except JassyError as exc:
                raise GridError(f"{where}: {exc}") from None
            self.cache[key] = sha256_file(key)
        return self.cache[key]


def variant_id(variant: Variant, model_digests: dict[str, str]) -> str:
    """SHA-256 over (patch content, model files, overrides, render options)."""
    payload = {
        "id_version": ID_VERSION,
        "patch": variant.patch.name,
        "content": variant.patch.digest,
        "models": model_digests,
        "overrides": {k: v for k, v in variant.overrides.items() if not k.startswith("models.")},
        "render": variant.render.as_dict(),
    }
    return sha256_bytes(canonical(payload).encode())


def _grid_meta(data: dict, where: str) -> dict:
    """Refuse unknown top-level and ``[batch]`` keys; return the ``[batch]`` table."""
    for key in data:
        if key not in GRID_KEYS:
            raise GridError(
                f"{where}: unknown top-level key {key!r}; expected {', '.join(sorted(GRID_KEYS))}"
                f"{suggest(key, GRID_KEYS)}"
            )
    meta = data.get("batch", {})
    if not isinstance(meta, dict):
        raise GridError(f"{where}: batch: expected a table")
    for key in meta:
        if key not in BATCH_KEYS:
            raise GridError(
                f"{where}: batch.{key}: unknown key; expected {', '.join(sorted(BATCH_KEYS))}"
                f"{suggest(key, BATCH_KEYS)}"
            )
    return meta


def _parse_sweeps(
    data: dict, where: str, grid_path: Path, inline: dict, render: RenderOptions
) -> list[_Sweep]:
    """The ``[[sweep]]`` tables, or the one sweep given at the top level."""
    top = [k for k in ("patch", "set", "grid", "random") if k in data]
    if "sweep" not in data:
        return [_parse_sweep(data, where, grid_path, inline, render)]
    if top:
        raise GridError(f"{where}: {top[0]}: give either [[sweep]] tables or a top-level sweep, not both")
    tables = data["sweep"]
    if not isinstance(tables, list) or not all(isinstance(t, dict) for t in tables):
        raise GridError(f"{where}: sweep: expected an array of tables ([[sweep]])")
    sweeps = []
    for i, table in enumerate(tables):
        for key in table:
            if key not in SWEEP_KEYS:
                raise GridError(
                    f"{where}: sweep[{i}].{key}: unknown key; expected {', '.join(sorted(SWEEP_KEYS))}"
                    f"{suggest(key, SWEEP_KEYS)}"
                )
        sweeps.append(_parse_sweep(table, f"{where}: sweep[{i}]", grid_path, inline, render))
    return sweeps


def _grid_columns(sweeps: list[_Sweep]) -> list[str]:
    """The manifest's parameter columns: every fixed, factor and random key, first seen first."""
    columns: list[str] = []
    for sweep in sweeps:
        names = list(sweep.fixed)
        for factor in sweep.factors:
            names += ([factor.name] if factor.keys != [factor.name] else []) + factor.keys
        names += list(sweep.random)
        columns += [name for name in dict.fromkeys(names) if name not in columns]
    return columns


def _sweep_cells(sweep: _Sweep) -> Iterator[tuple[dict[str, Any], dict[str, Any]]]:
    """Each combination of the sweep's factor levels: (overrides, manifest labels)."""
    for combo in itertools.product(*(f.levels for f in sweep.factors)):
        cell: dict[str, Any] = dict(sweep.fixed)
        labels: dict[str, Any] = dict(sweep.fixed)
        for factor, (label, overrides) in zip(sweep.factors, combo, strict=True):
            cell.update(overrides)
            if factor.keys != [factor.name]:
                labels[factor.name] = label
            labels.update(overrides)
        yield cell, labels


def _make_variant(
    sweep: _Sweep,
    patch: PatchSource,
    overrides: dict,
    labels: dict,
    index: int,
    grid_path: Path,
    digests: _Digests,
) -> Variant:
    """One checked variant with its model files, their digests and its id."""
    for key, value in overrides.items():
        check_value(key, value, patch, f'{sweep.where}: "{key}" = {value!r}')
    opts = _apply_render(sweep.render, overrides, sweep.where)
    variant = Variant(index, patch, overrides, {**labels, **overrides}, opts)
    model_data = apply_overrides(
        {"models": patch.data.get("models", {})},
        {k: v for k, v in overrides.items() if k.startswith("models.")},
        grid_path.parent,
    )
    variant.model_files = _model_files(model_data, patch.base)
    model_digests = {
        name: digests(p, f"{sweep.where} (patch {patch.name}, models.{name})")
        for name, p in variant.model_files.items()
    }
    variant.model_digests = model_digests
    variant.id = variant_id(variant, model_digests)
    return variant


def _expand(sweeps: list[_Sweep], grid_path: Path, digests: _Digests) -> tuple[list[Variant], int]:
    """Every sweep's variants (patches x factor levels x random draws), duplicates merged:
    (variants, how many duplicates were dropped)."""
    variants: list[Variant] = []
    seen_ids: set[str] = set()
    duplicates = 0
    for sweep in sweeps:
        for patch in sweep.patches:
            for cell, labels in _sweep_cells(sweep):
                for j in range(max(sweep.n_random, 1)):
                    overrides = dict(cell)
                    for key, (kind, arg) in sweep.random.items():
                        overrides[key] = draw(kind, arg, [sweep.seed, patch.name, cell, j, key])
                    variant = _make_variant(
                        sweep, patch, overrides, labels, len(variants), grid_path, digests
                    )
                    if variant.id in seen_ids:
                        duplicates += 1
                        continue
                    seen_ids.add(variant.id)
                    stem = f"{_safe(patch.name)}-{variant.id[:12]}"
                    variant.filename = f"{stem}.{variant.render.container}"
                    haptic = variant.render.haptic
                    variant.haptic_filename = f"{stem}.force.{haptic}" if haptic else ""
                    variants.append(variant)
    return variants, duplicates


def load_grid(path: str | os.PathLike) -> Grid:
    """Parse and check a grid file; expand it into variants (duplicates merged)."""
    grid_path = Path(path)
    try:
        data = load_toml(grid_path, "grid file")
    except JassyError as exc:
        raise GridError(str(exc)) from None
    where = str(grid_path)
    meta = _grid_meta(data, where)
    manifest = meta.get("manifest", "csv")
    if manifest not in ("csv", "parquet"):
        raise GridError(f"{where}: batch.manifest: expected 'csv' or 'parquet', got {manifest!r}")
    render = _render_options(data.get("render", {}), f"{where}: render")
    inline = data.get("patches", {})
    if not isinstance(inline, dict):
        raise GridError(f"{where}: patches: expected tables [patches.NAME] (inline patches)")
    sweeps = _parse_sweeps(data, where, grid_path, inline, render)
    planned = sum(
        len(sw.patches) * math.prod(len(f.levels) for f in sw.factors) * max(sw.n_random, 1) for sw in sweeps
    )
    try:
        check_variants(planned, where)
    except JassyError as exc:
        raise GridError(str(exc)) from None
    digests = _Digests()
    variants, duplicates = _expand(sweeps, grid_path, digests)
    _check_models(digests)
    return Grid(
        grid_path,
        str(meta.get("name", grid_path.stem)),
        str(meta.get("description", "")),
        manifest,
        variants,
        _grid_columns(sweeps),
        duplicates,
    )


def _check_models(digests: _Digests) -> None:
    """Load every model file of the plan once: a broken model file is an input error."""
    from jassy.errors import ModelError
    from jassy.modal_model import ModalModel

    for path in digests.cache:
        try:
            ModalModel.load(path)
        except ModelError as exc:
            raise GridError(str(exc)) from None
