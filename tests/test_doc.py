"""`jassy doc` / `jassy info`: the reference covers every parameter; patches show values and timeline;
name errors suggest the closest name."""

import tomllib

import pytest

from jassy.apps.cli import main
from jassy.errors import PatchError, suggest
from jassy.params import ParamSpec
from jassy.patchfile import builtin_patches
from jassy.registry import ugen_class, ugen_types
from jassy.ugendoc import describe_ugen, spec_range


def test_every_ugen_parameter_and_action_argument_is_in_the_reference():
    for name, cls in ugen_types().items():
        text = describe_ugen(cls)
        assert text.startswith(name)
        for key, spec in cls.all_specs().items():  # `smooth` included
            line = next((ln for ln in text.splitlines() if ln.startswith(f"  {key} ")), None)
            assert line is not None, f"{name}.{key} missing"
            assert spec_range(spec) in line and (spec.unit or "-") in line
        for action, specs in cls.actions.items():
            assert f"action {action}:" in text
            assert all(any(ln.startswith(f"  {k} ") for ln in text.splitlines()) for k in specs)


def test_ranges_read_as_intervals():
    assert spec_range(ParamSpec("float", 1.0, low=0.0, high=10.0, low_open=True)) == "(0, 10]"
    assert spec_range(ParamSpec("int", 1, low=1)) == "[1, inf)"
    assert spec_range(ParamSpec("float", 0.0)) == "any"
    assert spec_range(ParamSpec("str", "a", choices=("a", "b"))) == "'a' | 'b'"


def test_patch_doc_shows_values_and_the_timeline_in_order(capsys):
    assert main(["doc", "bell"]) == 0
    text = capsys.readouterr().out
    toml = tomllib.loads(builtin_patches()["bell"].read_text())
    assert f"duration = {toml['nodes']['clapper']['duration']:g} s" in text
    timeline = [ln for ln in text.splitlines() if ln.startswith("  ") and " s  " in ln]
    times = [float(ln.split()[0]) for ln in timeline]
    assert times == sorted(float(e["time"]) for e in toml["score"])
    assert any("clapper.impact(impulse=0.6, location=soundbow)" in ln for ln in timeline)


def test_names_get_a_did_you_mean(capsys):
    assert suggest("ModalBnk", ["ModalBank", "Gain"]) == "; did you mean 'ModalBank'?"
    assert suggest("zzz", ["ModalBank", "Gain"]) == ""
    assert main(["doc", "ModalBnk"]) == 2
    assert "did you mean 'ModalBank'?" in capsys.readouterr().err
    with pytest.raises(PatchError, match="did you mean 'freq_scale'"):
        ugen_class("ModalBank")(name="b", model=None, fre_scale=2.0)
    with pytest.raises(PatchError, match="did you mean 'ModalBank'"):
        ugen_class("ModalBnak")


def test_constructors_show_their_parameters_to_help_and_editors():
    import inspect

    for name, cls in ugen_types().items():
        sig = inspect.signature(cls)
        for key, spec in cls.all_specs().items():
            p = sig.parameters[key]
            assert p.kind is inspect.Parameter.KEYWORD_ONLY, f"{name}.{key}"
            assert (p.default is inspect.Parameter.empty) if spec.required else (p.default == spec.default)
            assert f"    {key} (" in cls.__doc__
    bank = inspect.signature(ugen_class("ModalBank"))
    assert list(bank.parameters)[:3] == ["sources", "name", "where"]


def test_list_names_every_parameter_including_smooth(capsys):
    assert main(["list"]) == 0
    text = capsys.readouterr().out
    for name, cls in ugen_types().items():
        line = text.split(f"  {name} ", 1)[1].splitlines()[1]
        assert line.strip().startswith("params: ")
        assert line.split("params: ", 1)[1].split(";")[0].split(", ") == list(cls.all_specs()), name


def test_the_markdown_reference_escapes_choices_inside_table_cells(capsys):
    assert main(["doc", "--markdown"]) == 0
    text = capsys.readouterr().out
    row = next(ln for ln in text.splitlines() if ln.startswith("| `input_kind` |"))
    assert row.count(" | ") == 5  # six cells: the choices' bars are escaped
    assert "'velocity' \\| 'displacement' \\| 'pressure'" in row
