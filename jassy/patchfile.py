"""TOML patch files: nodes, connections, outputs, models and a score.

Everything is validated before anything runs, and every error names the file, the key and
what was expected. Loading a patch never executes code: TOML is data, model files are
TOML, NPZ (no pickles) or JASS .sy text.

Layout::

    [patch]            name, description, duration (s), sample_rate (Hz)
    [models.NAME]      file = "x.toml" (relative to the patch) or inline frequencies/decays/gains/points
    [nodes.NAME]       type = "ModalBank"; input names map to source nodes (Mixer: inputs = [...]);
                       other keys are parameters; a "model" parameter names a [models] entry
    [outputs]          audio = "node" or ["left", "right"]; haptic = "node" or [...]
    [[score]]          time (s), node, then one action: set = {param = value}, jump = true|false,
                       or an action of the node type, e.g. impact = {impulse = 0.01, location = 2}
    [[generate]]       events at regular or Poisson times with random arguments (jassy/generators.py)
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

from jassy.anytime import ModeBudget
from jassy.errors import JassyError, ModelError, PatchError, suggest
from jassy.events import Event
from jassy.generators import expand
from jassy.graph import Graph
from jassy.inputs import load_toml, number, parse_toml, seconds
from jassy.modal_model import ModalModel
from jassy.registry import ugen_class
from jassy.scheduler import validate_event
from jassy.ugen import UGen

TOP_KEYS = {"patch", "models", "nodes", "outputs", "score", "generate"}
PATCH_KEYS = {"name", "description", "duration", "sample_rate", "mode_budget", "cpu_budget"}


@dataclass
class Patch:
    """A graph with its score and rendering defaults."""

    graph: Graph
    score: list[Event] = field(default_factory=list)
    name: str = "patch"
    description: str = ""
    duration: float | None = None
    sample_rate: float | None = None
    source: str = ""


def builtin_patches() -> dict[str, Path]:
    """Built-in patch names -> TOML paths (the ``patches`` package)."""
    root = resources.files("patches")
    return {
        Path(p.name).stem: Path(str(p))
        for p in root.iterdir()
        if p.name.endswith(".toml") and not p.name.endswith("_model.toml")
    }


def is_model_file(spec: str) -> bool:
    """True for a model file (.npz, .sy, or a .toml holding frequencies) rather than a patch."""
    path = Path(spec)
    if path.suffix in (".npz", ".sy"):
        return True
    if path.suffix == ".toml" and path.is_file():
        try:
            return "frequencies" in load_toml(path, "patch or model file")
        except JassyError:
            return False
    return False


def resolve_patch(spec: str) -> Path:
    """A patch path, or the path of the built-in patch named ``spec``."""
    path = Path(spec)
    if path.suffix == ".toml" or os.sep in spec:
        if not path.exists():
            raise PatchError(f"{spec}: no such patch file")
        return path
    builtins = builtin_patches()
    if spec not in builtins:
        raise PatchError(
            f"{spec}: not a patch file or built-in patch; built-ins are {', '.join(sorted(builtins))}"
            f"{suggest(spec, builtins)}"
        )
    return builtins[spec]


def parse_override(text: str) -> tuple[str, str, Any]:
    """Parse ``node.param=value`` (value in TOML syntax, or a bare string)."""
    key, sep, raw = text.partition("=")
    node, dot, param = key.strip().partition(".")
    if not sep or not dot or not node or not param:
        raise PatchError(f"--set {text!r}: expected node.param=value")
    try:
        value = parse_toml(f"v = {raw.strip()}", "--set")["v"]
    except JassyError:
        value = raw.strip()
    return node, param.strip(), value


def _split_top_level(text: str) -> list[str]:
    """``text`` split at commas outside brackets, braces and quotes."""
    parts, depth, quote, start = [], 0, "", 0
    for i, ch in enumerate(text):
        if quote:
            quote = "" if ch == quote else quote
        elif ch in "\"'":
            quote = ch
        elif ch in "[{":
            depth += 1
        elif ch in "]}":
            depth -= 1
        elif ch == "," and depth == 0:
            parts.append(text[start:i])
            start = i + 1
    parts.append(text[start:])
    return [p.strip() for p in parts if p.strip()]


def parse_event_option(text: str) -> dict:
    """A score entry from ``--event 'time=1.0,node=hit,action=impact,impulse=0.02'``: ``time``,
    ``node``, ``action`` (default ``set``), optional ``jump`` and ``ramp``, and the action's
    arguments; values in TOML syntax (numbers, true/false, "strings", [lists], {tables}) or bare
    strings."""
    where = f"--event {text!r}"
    fields: dict[str, Any] = {}
    for item in _split_top_level(text):
        key, sep, raw = item.partition("=")
        key = key.strip()
        if not sep or not key:
            raise PatchError(f"{where}: expected key=value items separated by commas, got {item!r}")
        if key in fields:
            raise PatchError(f"{where}: {key} given twice")
        try:
            fields[key] = parse_toml(f"v = {raw.strip()}", "--event")["v"]
        except JassyError:
            fields[key] = raw.strip()
    for required in ("time", "node"):
        if required not in fields:
            raise PatchError(f"{where}: {required}: missing")
    action = fields.pop("action", "set")
    if not isinstance(action, str) or action in ("time", "node", "jump", "ramp"):
        raise PatchError(f"{where}: action: expected the name of an action, got {action!r}")
    entry = {key: fields.pop(key) for key in ("time", "node", "jump", "ramp") if key in fields}
    entry[action] = fields
    return entry


def load_patch(
    spec: str | os.PathLike,
    overrides: list[str] | tuple[str, ...] = (),
    events: list[str] | tuple[str, ...] = (),
) -> Patch:
    """Load and validate a patch file (or built-in name), applying ``node.param=value`` overrides
    and adding ``--event`` score entries (see :func:`parse_event_option`)."""
    path = resolve_patch(str(spec))
    try:
        data = load_toml(path, "patch file")
    except JassyError as exc:
        raise PatchError(str(exc)) from None
    patch = build_patch(data, str(path), path.parent, overrides)
    if events:
        entries = [parse_event_option(text) for text in events]
        names = [f"--event {text!r}" for text in events]
        patch.score.extend(_parse_score(entries, patch.graph, str(path), names))
        patch.score.sort(key=lambda event: event.time)
    return patch


def _table(data: dict, key: str, where: str) -> dict:
    value = data.get(key, {})
    if not isinstance(value, dict):
        raise PatchError(f"{where}: {key}: expected a table")
    return value


def _load_models(models: dict, where: str, base: Path) -> dict[str, ModalModel]:
    out = {}
    for name, entry in models.items():
        key = f"{where}: models.{name}"
        if not isinstance(entry, dict):
            raise PatchError(f"{key}: expected a table with 'file' or frequencies/decays/gains")
        try:
            if "file" in entry:
                if set(entry) != {"file"}:
                    raise PatchError(f"{key}: 'file' cannot be combined with other keys")
                file = entry["file"]
                if not isinstance(file, str) or not file.strip() or "\0" in file:
                    raise PatchError(
                        f"{key}.file: expected the name of a .toml, .npz or .sy model file, got {file!r}"
                    )
                model = ModalModel.load(base / file)
            else:
                model = ModalModel.from_dict({"name": name, **entry}, key)
        except ModelError as exc:
            raise PatchError(f"{key}: {exc}") from None
        out[name] = model
    return out


def _reference(nodes: dict[str, UGen], ref: str, key: str) -> UGen:
    """The node named ``ref``, or for ``node.output`` a tap of that node's extra output."""
    name, _, output = ref.partition(".")
    if name not in nodes:
        raise PatchError(f"{key}: unknown node {name!r}; nodes are {', '.join(nodes)}{suggest(name, nodes)}")
    if not output:
        return nodes[name]
    try:
        return nodes[name].tap(output)
    except PatchError as exc:
        raise PatchError(f"{key}: {exc}") from None


def _names(value: Any, key: str) -> list[str]:
    items = [value] if isinstance(value, str) else value
    if not isinstance(items, list) or not all(isinstance(v, str) for v in items):
        raise PatchError(f"{key}: expected a node name or a list of node names, got {value!r}")
    return items


def _check_keys(data: dict, where: str) -> dict:
    """Refuse unknown top-level and ``[patch]`` keys; return the ``[patch]`` table."""
    for key in data:
        if key not in TOP_KEYS:
            raise PatchError(
                f"{where}: unknown top-level key {key!r}; expected {', '.join(sorted(TOP_KEYS))}"
                f"{suggest(key, TOP_KEYS)}"
            )
    meta = _table(data, "patch", where)
    for key in meta:
        if key not in PATCH_KEYS:
            raise PatchError(
                f"{where}: patch.{key}: unknown key; expected {', '.join(sorted(PATCH_KEYS))}"
                f"{suggest(key, PATCH_KEYS)}"
            )
    return meta


def _node_tables(data: dict, where: str, overrides: list[str] | tuple[str, ...]) -> dict:
    """The ``[nodes.NAME]`` tables (copies) with the ``--set NODE.PARAM=VALUE`` overrides applied."""
    tables = _table(data, "nodes", where)
    if not tables:
        raise PatchError(f"{where}: nodes: expected at least one [nodes.NAME] table")
    tables = {name: dict(t) if isinstance(t, dict) else t for name, t in tables.items()}
    for text in overrides:
        node, param, value = parse_override(text)
        if node not in tables:
            raise PatchError(
                f"--set {text}: unknown node {node!r}; nodes are {', '.join(tables)}{suggest(node, tables)}"
            )
        if param in ("type", "input", "inputs"):
            raise PatchError(f"--set {text}: only parameters can be overridden, not {param!r}")
        tables[node][param] = value
    return tables


def _build_node(name: str, table: Any, models: dict, key: str) -> tuple[UGen, dict[str, str]]:
    """One node from its table (``key`` names it in errors): the ugen and its input wiring
    (input name -> source node name)."""
    if not isinstance(table, dict) or not isinstance(table.get("type"), str):
        raise PatchError(f"{key}.type: expected the name of a ugen type")
    cls = ugen_class(table["type"], f"{key}.type")
    params = {k: v for k, v in table.items() if k != "type"}
    allowed = set(cls.all_specs()) | set(cls.inputs) | ({"inputs"} if cls.variadic else set())
    for pkey in params:
        if pkey not in allowed:
            raise PatchError(
                f"{key}: unknown parameter {pkey!r}; "
                f"expected one of {', '.join(sorted(allowed))}{suggest(pkey, allowed)}"
            )
    connect = {}
    if cls.variadic:
        if "inputs" not in params:
            raise PatchError(
                f"{key}.inputs: expected a list of node names ({cls.type_name} mixes any number)"
            )
        connect = {f"in{i}": n for i, n in enumerate(_names(params.pop("inputs"), f"{key}.inputs"))}
    else:
        for inp in cls.inputs:
            if inp in params:
                value = params.pop(inp)
                if not isinstance(value, str):
                    raise PatchError(f"{key}.{inp}: expected the name of the source node, got {value!r}")
                connect[inp] = value
    for pkey, spec in cls.all_specs().items():
        if spec.kind == "model" and pkey in params:
            ref = params[pkey]
            if not isinstance(ref, str) or ref not in models:
                known = ", ".join(models) or "none (add [models.NAME])"
                raise PatchError(
                    f"{key}.{pkey}: unknown model {ref!r}; models are {known}{suggest(ref, models)}"
                )
            params[pkey] = models[ref]
    return cls(name=name, where=key, **params), connect


def _build_nodes(tables: dict, models: dict, where: str) -> dict[str, UGen]:
    """Every node of the patch, connected to its inputs."""
    nodes, wiring = {}, {}
    for name, table in tables.items():
        nodes[name], wiring[name] = _build_node(name, table, models, f"{where}: nodes.{name}")
    for name, connect in wiring.items():
        for inp, src in connect.items():
            label = "inputs" if nodes[name].variadic else inp
            nodes[name].connect(_reference(nodes, src, f"{where}: nodes.{name}.{label}"), inp)
    return nodes


def _build_graph(data: dict, meta: dict, nodes: dict[str, UGen], where: str) -> Graph:
    """The graph from the ``[outputs]`` table and the ``[patch]`` mode/CPU budget; every node
    must reach an output."""
    outputs = _table(data, "outputs", where)
    for key in outputs:
        if key not in ("audio", "haptic"):
            raise PatchError(
                f"{where}: outputs.{key}: unknown output; expected audio or haptic"
                f"{suggest(key, ('audio', 'haptic'))}"
            )
    if "audio" not in outputs:
        raise PatchError(f"{where}: outputs.audio: missing (name the node(s) to hear)")
    picked = {}
    for key in ("audio", "haptic"):
        names = _names(outputs.get(key, []), f"{where}: outputs.{key}")
        picked[key] = [_reference(nodes, n, f"{where}: outputs.{key}") for n in names]
    budget = None
    if "mode_budget" in meta or "cpu_budget" in meta:
        try:
            budget = ModeBudget(max_modes=meta.get("mode_budget"), cpu_fraction=meta.get("cpu_budget"))
        except PatchError as exc:
            raise PatchError(f"{where}: patch.{exc}") from None
    try:
        graph = Graph(picked["audio"], picked["haptic"], budget)
    except PatchError as exc:
        raise PatchError(f"{where}: {exc}") from None
    unused = sorted(set(nodes) - set(graph.nodes))
    if unused:
        raise PatchError(f"{where}: nodes.{unused[0]}: not connected to any output")
    return graph


def build_patch(
    data: dict, source: str = "patch", base: Path = Path("."), overrides: list[str] | tuple[str, ...] = ()
) -> Patch:
    """Build a validated :class:`Patch` from parsed TOML data."""
    where = source
    meta = _check_keys(data, where)
    models = _load_models(_table(data, "models", where), where, base)
    nodes = _build_nodes(_node_tables(data, where, overrides), models, where)
    graph = _build_graph(data, meta, nodes, where)
    duration = meta.get("duration")
    rate = meta.get("sample_rate")
    try:
        if duration is not None:
            duration = seconds(duration, f"{where}: patch.duration")
        if rate is not None:
            rate = number(rate, f"{where}: patch.sample_rate", 1000, 768000, integer=True)
        generated = expand(data.get("generate", []), models, duration, where)
    except JassyError as exc:
        raise PatchError(str(exc)) from None
    score = _parse_score(data.get("score", []), graph, where)
    if generated:
        names, entries = zip(*generated, strict=True)
        score += _parse_score(list(entries), graph, where, list(names))
        score.sort(key=lambda event: event.time)
    for key in ("name", "description"):
        if not isinstance(meta.get(key, ""), str):
            raise PatchError(f"{where}: patch.{key}: expected a string, got {meta[key]!r}")
    return Patch(
        graph,
        score,
        str(meta.get("name", Path(source).stem)),
        str(meta.get("description", "")),
        duration,
        rate,
        source,
    )


def _parse_score(entries: Any, graph: Graph, where: str, names: list[str] | None = None) -> list[Event]:
    """Validated events of a score; ``names`` name the entries in errors (default score[i])."""
    if not isinstance(entries, list):
        raise PatchError(f"{where}: score: expected an array of tables ([[score]])")
    events = []
    for i, entry in enumerate(entries):
        key = names[i] if names else f"{where}: score[{i}]"
        if not isinstance(entry, dict):
            raise PatchError(f"{key}: expected a table")
        for req in ("time", "node"):
            if req not in entry:
                raise PatchError(f"{key}.{req}: missing")
        actions = [k for k in entry if k not in ("time", "node", "jump", "ramp")]
        if len(actions) != 1:
            raise PatchError(
                f"{key}: expected exactly one action (set = {{...}} or e.g. impact = {{...}}), got {actions}"
            )
        action = actions[0]
        args = entry[action]
        if not isinstance(args, dict):
            raise PatchError(f"{key}.{action}: expected a table of arguments")
        jump = entry.get("jump", False)
        if not isinstance(jump, bool):
            raise PatchError(f"{key}.jump: expected true or false")
        if not isinstance(entry["node"], str):
            raise PatchError(f"{key}.node: expected the name of a node, got {entry['node']!r}")
        try:
            seconds(entry["time"], f"{key}.time", allow_zero=True)
            if entry.get("ramp") is not None:
                seconds(entry["ramp"], f"{key}.ramp", allow_zero=True)
        except JassyError as exc:
            raise PatchError(str(exc)) from None
        event = Event(entry["time"], entry["node"], action, args, jump, entry.get("ramp"))
        events.append(validate_event(graph, event, key))
    return events
