"""Reference text of a ugen class, generated from its ParamSpecs: the parameter table in its
docstring and constructor signature (set by ``@register``) and the entries of ``jassy doc``."""

from __future__ import annotations

import inspect

from jassy.levels import level_convention
from jassy.params import ParamSpec


def number_text(x) -> str:
    return f"{x:g}" if isinstance(x, float) else str(x)


def spec_range(spec: ParamSpec) -> str:
    """The accepted values of a parameter, e.g. ``(0, 1000]`` or ``'a' | 'b'``."""
    if spec.kind == "str":
        return " | ".join(repr(c) for c in spec.choices) or "text"
    if spec.kind in ("float", "int"):
        if spec.low is None and spec.high is None:
            return "any" if spec.kind == "float" else "any integer"
        low = "-inf" if spec.low is None else number_text(spec.low)
        high = "inf" if spec.high is None else number_text(spec.high)
        opening = "(" if spec.low_open or spec.low is None else "["
        return f"{opening}{low}, {high}{')' if spec.high is None else ']'}"
    return {"bool": "true | false", "location": "vertex, point name, barycentric or {surface = [u, v]}",
            "model": "model name", "floats": "list of numbers"}.get(spec.kind, spec.kind)  # fmt: skip


def spec_default(spec: ParamSpec) -> str:
    if spec.required:
        return "(required)"
    if spec.default is None:
        return "-"
    return repr(spec.default) if isinstance(spec.default, str) else number_text(spec.default)


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
