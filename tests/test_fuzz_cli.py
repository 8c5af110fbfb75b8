"""Hostile input through the whole command line: every shipped patch, model, grid and study
file mutated at the byte level (bytes flipped, cut, inserted, not UTF-8) and at the
structure level (a value replaced by a hostile one: 1e308, a 20-digit integer, NaN, a
boolean, the wrong type, a path outside the folder, deep nesting), and random argument
values. Every run must end with exit 0 and a finite output file, or exit 2 and one line
on stderr, within a time limit, and leave no file under the requested name after a
failure and no temporary beside it.

The CLI's ``main()`` is called in-process (fast); a few signal cases use subprocesses.
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import os
import shutil
import signal
import subprocess
import sys
import time
import tomllib
from pathlib import Path

import numpy as np
import pytest
import soundfile
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from jassy.apps.cli import main

ROOT = Path(__file__).resolve().parent.parent
PATCH_FILES = sorted(p for p in (ROOT / "patches").glob("*.toml") if not p.stem.endswith("_model"))
MODEL_FILES = sorted((ROOT / "patches").glob("*_model.toml"))
GRID_FILES = [ROOT / "examples" / "impact_dataset.toml"]
STUDY_FILES = sorted((ROOT / "examples").glob("*study*.toml"))
#: Seconds one command may take (the slowest valid case renders 0.05 s of a patch).
TIME_LIMIT = 60
EXAMPLES = int(os.environ.get("JASSY_FUZZ_EXAMPLES", "30"))
FUZZ = settings(
    max_examples=EXAMPLES,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)
#: Fewer examples where one example may compute modes or fit a recording.
FUZZ_SLOW = settings(FUZZ, max_examples=max(1, EXAMPLES // 3))

DEEP: list = [1.0]
for _ in range(40):
    DEEP = [DEEP]

HOSTILE = [
    1e308,
    -1e308,
    12345678901234567890,
    -1,
    0,
    0.0,
    -0.0,
    1e-320,
    math.nan,
    math.inf,
    -math.inf,
    True,
    False,
    "",
    "nosuch",
    "../../../../etc/passwd",
    "/dev/zero",
    "x" * 5000,
    "\u00e9\u0000",
    [],
    [1, "a"],
    {},
    {"a": {"b": [1.0]}},
    DEEP,
]


# ------------------------------------------------------------------- TOML writing


def toml_value(value) -> str:
    """``value`` as TOML (inline tables and arrays), including nan and inf."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, list):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{json.dumps(k)} = {toml_value(v)}" for k, v in value.items()) + "}"
    raise TypeError(type(value))


def toml_text(data: dict) -> str:
    return "".join(f"{json.dumps(k)} = {toml_value(v)}\n" for k, v in data.items())


def leaves(value, path=()):
    """Paths of every value in nested dicts/lists (containers included)."""
    yield path
    if isinstance(value, dict):
        for k, v in value.items():
            yield from leaves(v, (*path, k))
    elif isinstance(value, list):
        for i, v in enumerate(value):
            yield from leaves(v, (*path, i))


def replaced(data, path, new):
    if not path:
        return new
    out = dict(data) if isinstance(data, dict) else list(data)
    out[path[0]] = replaced(data[path[0]], path[1:], new)
    return out


@st.composite
def mutated(draw, source: Path) -> bytes:
    """The bytes of ``source`` mutated at the byte or the structure level."""
    raw = source.read_bytes()
    kind = draw(st.sampled_from(["structure", "structure", "structure", "bytes", "cut", "insert"]))
    if kind == "structure":
        data = tomllib.loads(raw.decode())
        paths = [p for p in leaves(data) if p]
        path = draw(st.sampled_from(paths))
        value = draw(st.sampled_from(HOSTILE) | st.floats() | st.integers() | st.text(max_size=20))
        if draw(st.booleans()) and isinstance(path[-1], str):  # or a hostile key
            parent = path[:-1]
            node = data
            for step in parent:
                node = node[step]
            if isinstance(node, dict):
                key = draw(st.sampled_from(["name", "where", "type", "file", "", "a.b", "score[9]"]))
                return toml_text(replaced(data, parent, {**node, key: value})).encode()
        return toml_text(replaced(data, path, value)).encode()
    at = draw(st.integers(0, max(len(raw) - 1, 0)))
    if kind == "bytes":
        junk = draw(st.binary(min_size=1, max_size=8))
        return raw[:at] + junk + raw[at + len(junk) :]
    if kind == "cut":
        return raw[:at]
    return raw[:at] + draw(st.sampled_from([b"\xff\xfe", b"[[[[", b"= = =", b"\x00", b'"\\u']))


# ------------------------------------------------------------------- running


class TimeLimit(Exception):
    pass


def run(argv: list[str]) -> tuple[int, str]:
    """main(argv) in-process: (exit code, stderr); fails on a traceback or past TIME_LIMIT."""

    def expire(signum, frame):
        raise TimeLimit

    err = io.StringIO()
    previous = signal.signal(signal.SIGALRM, expire)
    signal.alarm(TIME_LIMIT)
    t0 = time.monotonic()
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            code = main(argv)
    except TimeLimit:
        pytest.fail(f"jassy {' '.join(argv)}: still running after {TIME_LIMIT} s")
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)
    assert time.monotonic() - t0 < TIME_LIMIT
    return code, err.getvalue()


def check_outcome(argv: list[str], code: int, err: str, outputs: list[Path], folder: Path) -> None:
    """Exit 0 with finite outputs, or exit 2 with one line and no outputs; no temporaries."""
    lines = [ln for ln in err.splitlines() if ln.strip() and "warning" not in ln and "\r" not in ln]
    assert code in (0, 2), f"jassy {' '.join(argv)}: exit {code}: {err[-2000:]}"
    if code == 2:
        assert len(lines) == 1 and "error" in lines[0], f"jassy {' '.join(argv)}: {err!r}"
        for out in outputs:
            assert not out.exists(), f"{out} written although the command failed"
    else:
        for out in outputs:
            if out.suffix == ".wav" and out.exists():
                data, _ = soundfile.read(out, always_2d=True)
                assert np.all(np.isfinite(data)), f"{out}: non-finite samples"
    left = [p.name for p in folder.rglob("*.partial")]
    assert not left, f"temporaries left: {left}"


@pytest.fixture(scope="module")
def workdir(tmp_path_factory):
    """A folder with copies of the shipped model files (patch-relative model paths)."""
    folder = tmp_path_factory.mktemp("fuzz")
    for model in MODEL_FILES:
        shutil.copy(model, folder / model.name)
    for extra in (ROOT / "examples").glob("*.csv"):
        shutil.copy(extra, folder / extra.name)
    return folder


@pytest.fixture(autouse=True)
def small_limits(monkeypatch):
    """Renders limited to 0.3 s of audio, so a mutated duration cannot take minutes."""
    monkeypatch.setenv("JASSY_MAX_SECONDS", "0.3")
    monkeypatch.setenv("JASSY_MAX_VARIANTS", "200")


def fresh(folder: Path, name: str) -> Path:
    """A new empty subfolder for one example."""
    sub = folder / f"{name}-{time.monotonic_ns()}"
    sub.mkdir()
    for model in folder.glob("*_model.toml"):
        os.symlink(model, sub / model.name)
    for extra in folder.glob("*.csv"):
        os.symlink(extra, sub / extra.name)
    return sub


# ------------------------------------------------------------------- the fuzz tests


@FUZZ
@given(st.data())
def test_mutated_patches_render_or_fail_in_one_line(workdir, data):
    source = data.draw(st.sampled_from(PATCH_FILES), label="patch")
    folder = fresh(workdir, "patch")
    patch = folder / source.name
    patch.write_bytes(data.draw(mutated(source), label="mutation"))
    out = folder / "out.wav"
    argv = [
        "render",
        str(patch),
        "-o",
        str(out),
        "-q",
        "--duration",
        "0.05",
        "--haptic",
        str(folder / "f.wav"),
    ]
    command = data.draw(st.sampled_from(["render", "render", "info"]))
    if command == "info":
        argv = ["info", str(patch)]
    code, err = run(argv)
    check_outcome(argv, code, err, [out, folder / "f.wav"], folder)


@FUZZ
@given(st.data())
def test_mutated_models_load_or_fail_in_one_line(workdir, data):
    source = data.draw(st.sampled_from(MODEL_FILES), label="model")
    folder = fresh(workdir, "model")
    model = folder / data.draw(st.sampled_from([source.name, "m.npz", "m.sy"]), label="name")
    if model.suffix == ".npz":
        buffer = io.BytesIO()
        loaded = tomllib.loads(source.read_text())
        np.savez(buffer, **{k: np.asarray(v) for k, v in loaded.items() if k != "points"})
        raw = buffer.getvalue()
        at = data.draw(st.integers(0, len(raw) - 1))
        model.write_bytes(raw[:at] + data.draw(st.binary(min_size=1, max_size=16)) + raw[at + 16 :])
    else:
        model.write_bytes(data.draw(mutated(source), label="mutation"))
    patch = folder / "p.toml"
    patch.write_text(
        f'[models.m]\nfile = "{model.name}"\n[nodes.hit]\ntype = "ImpactForce"\n'
        '[nodes.bank]\ntype = "ModalBank"\nmodel = "m"\ninput = "hit"\n[outputs]\naudio = "bank"\n'
        '[[score]]\ntime = 0.0\nnode = "hit"\nimpact = { impulse = 0.1 }\n'
    )
    out = folder / "out.wav"
    for argv in (["info", str(model)], ["render", str(patch), "-o", str(out), "-q", "--duration", "0.05"]):
        code, err = run(argv)
        check_outcome(argv, code, err, [out], folder)


@FUZZ
@given(st.data())
def test_mutated_grids_plan_or_fail_in_one_line(workdir, data):
    source = data.draw(st.sampled_from(GRID_FILES), label="grid")
    folder = fresh(workdir, "grid")
    (folder / "examples").mkdir()
    shutil.copytree(
        ROOT / "patches", folder / "patches", ignore=shutil.ignore_patterns("*.py", "__pycache__")
    )
    grid = folder / "examples" / source.name
    grid.write_bytes(data.draw(mutated(source), label="mutation"))
    argv = ["batch", str(grid), "-o", str(folder / "out"), "--dry-run"]
    code, err = run(argv)
    check_outcome(argv, code, err, [], folder)


@FUZZ
@given(st.data())
def test_mutated_study_designs_run_or_fail_in_one_line(workdir, data):
    source = data.draw(st.sampled_from(STUDY_FILES), label="design")
    folder = fresh(workdir, "study")
    shutil.copytree(
        ROOT / "patches", folder / "patches", ignore=shutil.ignore_patterns("*.py", "__pycache__")
    )
    (folder / "examples").mkdir()
    for extra in (ROOT / "examples").glob("*.csv"):
        shutil.copy(extra, folder / "examples" / extra.name)
    design = folder / "examples" / source.name
    design.write_bytes(data.draw(mutated(source), label="mutation"))
    participant = data.draw(st.sampled_from(["S01", "../../x", "/tmp/EVIL", "a b", ".", "", "x" * 80]))
    out = folder / "r.csv"
    argv = ["study", "run", str(design), "-p", participant, "--responses", "simulated"]
    argv += ["--present", "none", "--max-trials", "2", "-o", str(out)]
    code, err = run(argv)
    check_outcome(argv, code, err, [out], folder)
    outside = [p for p in folder.parent.parent.rglob("EVIL*")] + list(Path("/tmp").glob("EVIL*"))
    assert not outside, f"wrote outside the study folder: {outside}"


NUMBERS = st.sampled_from(
    ["0", "-1", "1", "nan", "inf", "-inf", "1e308", "12345678901234567890", "1e9", "0.5", "abc", "", "2.5"]
)


@FUZZ
@given(st.data())
def test_random_render_arguments_render_or_fail_in_one_line(workdir, data):
    folder = fresh(workdir, "args")
    out = folder / data.draw(st.sampled_from(["o.wav", "o.flac", "o.mp3", "d", "missing/o.wav"]), label="out")
    if out.name == "d":
        out.mkdir()
    argv = ["render", str(ROOT / "patches" / "wall_tap.toml"), "-o", str(out), "-q"]
    haptic = None
    for option in data.draw(
        st.lists(
            st.sampled_from(
                ["--sr", "--duration", "--block", "--haptic-offset", "--audio-offset", "--max-force",
                 "--max-slew", "--mode-budget", "--set", "--haptic", "--format", "--max-memory"]
            ),
            max_size=4,
            unique=True,
        ),
        label="options",
    ):  # fmt: skip
        if option == "--set":
            node = data.draw(st.sampled_from(["wall", "out", "nosuch", "wall.name", ""]))
            value = data.draw(st.sampled_from(["1e308", "nan", "[]", "true", "-1", '"x"', "{a=1}", "0.5"]))
            argv += [option, f"{node}.gain={value}" if "." not in node else f"{node}={value}"]
        elif option == "--haptic":
            haptic = data.draw(st.sampled_from(["f.wav", "f.csv", "f.npz", "o.wav", "f.txt"]))
            argv += [option, str(folder / haptic)]
        elif option == "--format":
            argv += [option, data.draw(st.sampled_from(["float32", "pcm16", "pcm24", "x"]))]
        elif option == "--max-memory":
            argv += [option, data.draw(st.sampled_from(["1", "1K", "8G", "abc", "-1"]))]
        else:
            argv += [option, data.draw(NUMBERS)]
    if "--duration" not in argv:
        argv += ["--duration", "0.05"]
    code, err = run(argv)
    outputs = [out] + ([folder / haptic] if haptic and haptic != out.name else [])
    check_outcome(argv, code, err, outputs if out.name != "d" else [], folder)


# ------------------------------------------------------------------- named classes


def test_full_disk_fails_in_one_line_and_keeps_the_old_file(tmp_path, monkeypatch):
    out = tmp_path / "o.wav"
    out.write_bytes(b"old")

    def full(self, data):
        raise soundfile.LibsndfileError(9, "Error : No space left on device")

    monkeypatch.setattr(soundfile.SoundFile, "write", full)
    argv = ["render", "wall_tap", "-o", str(out), "--duration", "0.05", "-q"]
    code, err = run(argv)
    assert code == 2 and "o.wav: cannot write" in err and len(err.strip().splitlines()) == 1
    assert out.read_bytes() == b"old" and sorted(p.name for p in tmp_path.iterdir()) == ["o.wav"]


def test_stale_temporaries_of_a_killed_run_are_removed_by_the_next(tmp_path):
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()  # a process id that no longer runs
    stale = tmp_path / f".o.wav.p{dead.pid}.abc123.partial"
    stale.write_bytes(b"half")
    live = tmp_path / f".o.wav.p{os.getpid()}.def456.partial"  # a writer that still runs
    live.write_bytes(b"busy")
    code, err = run(["render", "wall_tap", "-o", str(tmp_path / "o.wav"), "--duration", "0.05", "-q"])
    assert code == 0, err
    assert not stale.exists() and live.exists()


def test_force_beyond_float32_is_clipped_with_a_warning(tmp_path):
    patch = tmp_path / "p.toml"
    patch.write_text(
        '[nodes.hit]\ntype = "ImpactForce"\n[nodes.big]\ntype = "Gain"\ninput = "hit"\ngain = 1e300\n'
        '[outputs]\naudio = "hit"\nhaptic = "big"\n'
        '[[score]]\ntime = 0.0\nnode = "hit"\nimpact = { impulse = 1.0 }\n'
    )
    out, force = tmp_path / "o.wav", tmp_path / "f.wav"
    code, err = run(
        ["render", str(patch), "-o", str(out), "--haptic", str(force), "--duration", "0.01", "-q"]
    )
    assert code == 0, err
    data, _ = soundfile.read(force)
    assert np.all(np.isfinite(data)) and np.max(np.abs(data)) == pytest.approx(np.finfo(np.float32).max)
    assert "float32 range clipped" in err


@pytest.mark.parametrize("signum, code", [(signal.SIGTERM, 143), (signal.SIGHUP, 129)])
def test_signals_stop_a_render_cleanly(tmp_path, signum, code):
    out = tmp_path / "long.wav"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen(
        [sys.executable, "-m", "jassy", "render", "bell", "-o", str(out), "--duration", "3000", "-q",
         "--max-seconds", "4000"],
        env=env, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    deadline = time.monotonic() + 120
    while not any(p.suffix == ".partial" for p in tmp_path.iterdir()):  # rendering has begun
        assert proc.poll() is None and time.monotonic() < deadline, proc.stderr.read()
        time.sleep(0.05)
    proc.send_signal(signum)
    try:
        _, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == code, err
    assert list(tmp_path.iterdir()) == []


# ------------------------------------------------------------------- every command's options

#: Commands fuzzed with random option values (not the live ones, benchmarks or long experiments).
COMMANDS = {
    "info": ["bell", "{dir}/p.toml", "{dir}/m.toml", "{dir}/x.npz", "nosuch"],
    "render": ["wall_tap", "{dir}/p.toml", "nosuch"],
    "modes": ["bar", "{dir}/x.stl", "nosuch.stl"],
    "fit": ["{dir}/r.wav", "{dir}/p.toml"],
    "batch": ["{dir}/g.toml"],
    "analyze": ["{dir}/r.wav", "{dir}/p.toml"],
    "check-audio": ["{dir}/r.wav", "{dir}/p.toml"],
}
VALUES = st.sampled_from(
    ["0", "-1", "1", "3", "nan", "inf", "1e308", "12345678901234567890", "1e9", "0.5", "abc", "", "-",
     "{dir}", "{dir}/o.wav", "{dir}/o.toml", "{dir}/o.csv", "{dir}/o.png", "/dev/null", "x=1", "a.b=nan"]
)  # fmt: skip


def command_options(command: str) -> list[tuple[str, bool]]:
    """(option string, takes a value) of a command's optional arguments."""
    import argparse

    from jassy.apps.cli import build_parser

    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    out = []
    for action in sub.choices[command]._actions:
        if action.option_strings and action.dest != "help":
            out.append((action.option_strings[-1], action.nargs != 0))
    return out


@FUZZ_SLOW
@given(st.data())
def test_random_options_of_every_command_end_in_exit_0_or_one_line(workdir, monkeypatch, data):
    monkeypatch.setenv("JASSY_MAX_MEMORY", "300M")  # FEM and fits stay small
    folder = fresh(workdir, "opts")
    monkeypatch.chdir(folder)  # relative names drawn for -o and others land here
    (folder / "p.toml").write_text((ROOT / "patches" / "wall_tap.toml").read_text())
    (folder / "m.toml").write_text(MODEL_FILES[0].read_text())
    (folder / "x.npz").write_bytes(b"PK\x03\x04 not a zip")
    (folder / "x.stl").write_bytes(b"solid x\nendsolid x\n")
    (folder / "g.toml").write_text(
        'patch = "wall_tap"\n[render]\nduration = 0.05\n[grid]\n"out.gain" = [0.1, 0.2]\n'
    )
    t = np.arange(4800) / 48000
    soundfile.write(folder / "r.wav", np.exp(-30 * t) * np.sin(2 * np.pi * 880 * t), 48000)
    command = data.draw(st.sampled_from(sorted(COMMANDS)), label="command")
    argv = [command, data.draw(st.sampled_from(COMMANDS[command])).format(dir=folder)]
    if command in ("modes", "fit", "batch", "render"):
        argv += [
            "-o",
            str(folder / {"modes": "o.toml", "fit": "o.toml", "batch": "out", "render": "o.wav"}[command]),
        ]
    options = command_options(command)
    for option, takes_value in data.draw(
        st.lists(st.sampled_from(options), max_size=3, unique=True), label="opts"
    ):
        argv.append(option)
        if takes_value:
            argv.append(data.draw(VALUES).format(dir=folder))
    if command == "modes":
        argv += ["--elements", "300", "--modes", "4", "--subdivide", "0"]  # small unless overridden above
    code, err = run(argv)
    check_outcome(argv, code, err, [], folder)


def test_missing_mesh_is_reported_before_heavy_imports(tmp_path):
    code = (
        "import sys\nfrom jassy.apps.cli import main\n"
        f"assert main(['modes', {str(tmp_path / 'part.stl')!r}, '-o', {str(tmp_path / 'p.toml')!r}]) == 2\n"
        "heavy = ('trimesh', 'physics.modal.fem', 'physics.modal.meshes')\n"
        "print(sorted(m for m in heavy if m in sys.modules))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code],
        env={**os.environ, "PYTHONPATH": str(ROOT)},
        capture_output=True,
        text=True,
    )
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]" and "part.stl: no such mesh file" in out.stderr


def test_scene_summary_is_readable_lines():
    from jassy.apps.cli import _summary_lines

    text = _summary_lines({"frames": 48000, "peak": 0.123456, "stats": {"steps": 10}, "warnings": ["w"]})
    assert text.splitlines() == ["  frames: 48000", "  peak: 0.1235", "  stats:", "    steps: 10"]
