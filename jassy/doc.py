"""``jassy doc``: the reference of every ugen, patch and model, generated from the code.

A ugen's entry lists its inputs and outputs, every parameter with kind, unit, range, default,
whether changes are smoothed, and what it does (the ParamSpec's own text), and the event
actions it takes with their arguments. A patch's entry shows its nodes with their parameter
values, its models and its event timeline; a model's entry its named points and modes.
``jassy doc --markdown`` prints the whole ugen reference as Markdown (docs/reference.md is
that output).
"""

from __future__ import annotations

import argparse
import inspect

from jassy.errors import JassyError
from jassy.levels import level_convention
from jassy.params import ParamSpec


def _number(x) -> str:
    return f"{x:g}" if isinstance(x, float) else str(x)


def _value(x) -> str:
    """A parameter or event value as a user would write it."""
    from jassy.modal_model import Location, ModalModel

    if isinstance(x, ModalModel):
        return f"model {x.name or '?'} ({x.n_modes} modes, {x.n_points} location(s))"
    if isinstance(x, Location):
        if len(x.vertices) == 1:
            return str(x.vertices[0])
        return " + ".join(f"{w:g} {v}" for v, w in zip(x.vertices, x.weights, strict=True))
    if isinstance(x, bool):
        return "true" if x else "false"
    if isinstance(x, (int, float)):
        return _number(x)
    return repr(x)


def spec_range(spec: ParamSpec) -> str:
    """The accepted values of a parameter, e.g. ``(0, 1000]`` or ``'a' | 'b'``."""
    if spec.kind == "str":
        return " | ".join(repr(c) for c in spec.choices) or "text"
    if spec.kind in ("float", "int"):
        if spec.low is None and spec.high is None:
            return "any" if spec.kind == "float" else "any integer"
        low = "-inf" if spec.low is None else _number(spec.low)
        high = "inf" if spec.high is None else _number(spec.high)
        opening = "(" if spec.low_open or spec.low is None else "["
        return f"{opening}{low}, {high}{')' if spec.high is None else ']'}"
    return {"bool": "true | false", "location": "vertex, point name or barycentric", "model": "model name",
            "floats": "list of numbers"}.get(spec.kind, spec.kind)  # fmt: skip


def spec_default(spec: ParamSpec) -> str:
    if spec.required:
        return "(required)"
    if spec.default is None:
        return "-"
    return repr(spec.default) if isinstance(spec.default, str) else _number(spec.default)


def _spec_rows(specs: dict[str, ParamSpec]) -> list[tuple[str, ...]]:
    rows = []
    for name, spec in specs.items():
        notes = []
        if spec.smooth:
            notes.append("ramped")
        if spec.fixed:
            notes.append("fixed at start")
        doc = spec.doc + (f" ({', '.join(notes)})" if notes else "")
        rows.append((name, spec.kind, spec.unit or "-", spec_range(spec), spec_default(spec), doc))
    return rows


def _table(rows: list[tuple[str, ...]], heads: tuple[str, ...], markdown: bool) -> list[str]:
    if markdown:
        out = ["| " + " | ".join(heads) + " |", "|" + "---|" * len(heads)]
        return out + [
            "| "
            + " | ".join(f"`{r[0]}`" if i == 0 else c.replace("|", "\\|") for i, c in enumerate(r))
            + " |"
            for r in rows
        ]  # a literal | inside a cell (the choices of a str parameter) would split it
    widths = [max(len(h), *(len(r[i]) for r in rows)) if rows else len(h) for i, h in enumerate(heads)]
    widths[-1] = 0  # the description runs on
    fmt = "  " + "  ".join(f"{{:<{w}}}" for w in widths)
    return [fmt.format(*heads).rstrip()] + [fmt.format(*r).rstrip() for r in rows]


def describe_ugen(cls, markdown: bool = False) -> str:
    """Reference text of one ugen class."""
    doc = inspect.cleandoc(cls.__doc__ or "")
    summary = doc.split("\n\n")[0].replace("\n", " ")
    lines = [f"## {cls.type_name}" if markdown else cls.type_name, "", summary, ""]
    if cls.variadic:
        inputs = "any number (in0, in1, ...), summed"
    else:
        inputs = (
            ", ".join(n + (" (optional)" if n in cls.optional_inputs else "") for n in cls.inputs) or "none"
        )
    outputs = "out" + "".join(f", {n}" for n in cls.outputs)
    lines += [f"inputs: {inputs}", f"outputs: {outputs}"]
    level = level_convention(cls.type_name)
    lines += [f"level: {level}", ""] if level else [""]
    heads = ("parameter", "kind", "unit", "range", "default", "what it does")
    lines += _table(_spec_rows(cls.all_specs()), heads, markdown)
    for action, specs in cls.actions.items():
        lines += ["", f"action `{action}`:" if markdown else f"action {action}:"]
        lines += _table(
            _spec_rows(specs), ("argument", "kind", "unit", "range", "default", "meaning"), markdown
        )
    lines += ["", "any parameter can also change in a `set` event (ramped over `smooth` unless `jump`)."]
    return "\n".join(lines)


_ANNOTATIONS = {"float": "float", "int": "int", "bool": "bool", "str": "str", "location": "int | str | dict",
                "model": "ModalModel | str", "floats": "list[float]"}  # fmt: skip


def document_class(cls) -> None:
    """Give a ugen class the constructor signature ``(*sources, name=None, where=None,
    <every parameter with its default>)`` and append its parameter table to its docstring."""
    P = inspect.Parameter
    params = [
        P("sources", P.VAR_POSITIONAL, annotation="UGen"),
        P("name", P.KEYWORD_ONLY, default=None, annotation="str | None"),
        P("where", P.KEYWORD_ONLY, default=None, annotation="str | None"),
    ]
    for key, spec in cls.all_specs().items():
        default = P.empty if spec.required else spec.default
        params.append(P(key, P.KEYWORD_ONLY, default=default, annotation=_ANNOTATIONS[spec.kind]))
    cls.__signature__ = inspect.Signature(params)
    lines = ["", "Parameters (keyword arguments, patch keys and `set` events):"]
    for name, kind, unit, accepted, default, what in _spec_rows(cls.all_specs()):
        lines.append(
            f"    {name} ({kind}{', ' + unit if unit != '-' else ''}; {accepted}; default {default}): {what}"
        )
    for action, specs in cls.actions.items():
        lines.append(
            f"Action ``{action}``: " + ", ".join(f"{k} ({s.unit or s.kind})" for k, s in specs.items())
        )
    cls.__doc__ = inspect.cleandoc(cls.__doc__ or cls.type_name) + "\n" + "\n".join(lines)


def describe_patch(patch) -> str:
    """A patch's nodes with their parameter values, its models and its event timeline."""
    from jassy.cli import DEFAULT_RATE

    lines = [f"patch {patch.name}: {patch.description}", f"source: {patch.source}"]
    rate = f"{patch.sample_rate:g} Hz" if patch.sample_rate else f"default ({DEFAULT_RATE} Hz)"
    lines.append(f"duration: {patch.duration} s; sample rate: {rate}")
    lines.append("nodes (in processing order):")
    for node in patch.graph.order:
        inputs = ", ".join(f"{k} <- {v.name}" for k, v in node.sources.items())
        lines.append(f"  {node.name} ({node.type_name})" + (f": {inputs}" if inputs else ""))
        for key, value in node.values.items():
            spec = node.all_specs().get(key)
            unit = f" {spec.unit}" if spec is not None and spec.unit else ""
            lines.append(f"      {key} = {_value(value)}{unit}")
    lines.append(f"score ({len(patch.score)} events):")
    for ev in sorted(patch.score, key=lambda e: e.time):
        args = ", ".join(f"{k}={_value(v)}" for k, v in ev.args.items())
        how = " (jump)" if ev.jump else (f" (ramp {ev.ramp:g} s)" if ev.ramp is not None else "")
        lines.append(f"  {ev.time:9.4f} s  {ev.node}.{ev.action}({args}){how}")
    return "\n".join(lines)


def describe_model_points(model) -> str:
    """The named points of a model (its strike locations), described where the model is one
    of the object library's (``patches.objects``)."""
    from patches.objects import object_for_model

    if not model.points:
        return f"  {model.n_points} location(s), unnamed (vertex indices 0..{model.n_points - 1})"
    info = object_for_model(model.name)
    described = info.points if info is not None else {}
    return "\n".join(f"  {name}: {described.get(name, '')}".rstrip().rstrip(":") for name in model.points)


def reference_markdown() -> str:
    """Every ugen's reference as one Markdown page."""
    from jassy.registry import ugen_types

    parts = [
        "# Ugen reference",
        "",
        "Generated by `jassy doc --markdown` from the ParamSpecs in the code.",
        "",
    ]
    parts += [describe_ugen(cls, markdown=True) + "\n" for cls in ugen_types().values()]
    return "\n".join(parts)


def _cmd_doc(args: argparse.Namespace) -> int:
    from jassy.registry import ugen_types

    types = ugen_types()
    if args.markdown:
        print(reference_markdown())
        return 0
    if args.name is None:
        print("\n\n".join(describe_ugen(cls) for cls in types.values()))
        return 0
    if args.name in types:
        print(describe_ugen(types[args.name]))
        return 0
    from jassy.patchfile import builtin_patches, is_model_file, load_patch

    if is_model_file(args.name):
        from jassy.modal_model import ModalModel
        from physics.modal.cli import describe_model

        print(describe_model(args.name))
        print("points:\n" + describe_model_points(ModalModel.load(args.name)))
        return 0
    if args.name in builtin_patches() or args.name.endswith(".toml"):
        print(describe_patch(load_patch(args.name)))
        return 0
    from jassy.errors import suggest

    hint = suggest(args.name, [*types, *builtin_patches()])
    raise JassyError(f"doc: {args.name!r} is no ugen type, patch or model file{hint}")


def add_command(sub) -> None:
    """Register ``jassy doc``."""
    p = sub.add_parser("doc", help="reference of a ugen type, a patch or a model (all ugens if none given)")
    p.add_argument("name", nargs="?", help="ugen type (e.g. ModalBank), patch name or file, or model file")
    p.add_argument("--markdown", action="store_true", help="the whole ugen reference as Markdown")
    p.set_defaults(func=_cmd_doc)
