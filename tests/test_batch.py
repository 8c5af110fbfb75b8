"""jassy batch: grid expansion and checks, identical files on every backend, resume, failures.

The reference for every output file is an independent render of the same variant: the
patch written out as a TOML file with the variant's values substituted, loaded with
``load_patch`` and rendered by ``OfflineEngine.render_to_file``, as ``jassy render`` does.
"""

from __future__ import annotations

import argparse
import csv
import functools
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
import soundfile

from jassy.apps.cli import main
from jassy.batch import _Lock, add_command, run_batch
from jassy.batch.backends import BlobReader, error_result, make_task, render_task
from jassy.batch.grid import GridError, load_grid
from jassy.engines.offline import OfflineEngine
from jassy.errors import JassyError
from jassy.files import deterministic_npz, deterministic_wav
from jassy.patchfile import load_patch

PATCH = """
[patch]
name = "hit"

[models.plate]
frequencies = [440.0, 1234.5, 2750.0]
decays = [3.0, 5.0, 9.0]
gains = [[1.0, 0.5, 0.25], [0.2, 1.0, 0.7]]
points = ["centre", "edge"]

[nodes.mallet]
type = "ImpactForce"
duration = {mallet}

[nodes.plate]
type = "ModalBank"
model = "plate"
input = "mallet"

[nodes.out]
type = "Gain"
input = "plate"
gain = 20.0

[outputs]
audio = "out"
haptic = "mallet"

[[score]]
time = 0.01
node = "mallet"
impact = {{ impulse = {impulse}, location = "{location}" }}

[[score]]
time = 0.12
node = "mallet"
impact = {{ impulse = 0.005, location = "edge" }}
"""

# The same patch inline in a grid: 2 locations x 2 impulses x 2 mallet durations = 8 variants.
GRID = """
patch = "hit"

[batch]
name = "t"

[render]
duration = 0.2
sample_rate = 16000
format = "{format}"

[patches.hit.models.plate]
frequencies = [440.0, 1234.5, 2750.0]
decays = [3.0, 5.0, 9.0]
gains = [[1.0, 0.5, 0.25], [0.2, 1.0, 0.7]]
points = ["centre", "edge"]

[patches.hit.nodes.mallet]
type = "ImpactForce"
duration = 0.001

[patches.hit.nodes.plate]
type = "ModalBank"
model = "plate"
input = "mallet"

[patches.hit.nodes.out]
type = "Gain"
input = "plate"
gain = 20.0

[patches.hit.outputs]
audio = "out"
haptic = "mallet"

[[patches.hit.score]]
time = 0.01
node = "mallet"
impact = {{ impulse = 0.01, location = "centre" }}

[[patches.hit.score]]
time = 0.12
node = "mallet"
impact = {{ impulse = 0.005, location = "edge" }}

[grid]
"score[0].impact.location" = ["centre", "edge"]
"score[0].impact.impulse" = [0.01, 0.02]
"mallet.duration" = {durations}
"""


def write_grid(tmp_path: Path, fmt: str = "float32", durations=(0.001, 0.0003), name="grid.toml") -> Path:
    path = tmp_path / name
    path.write_text(GRID.format(format=fmt, durations=list(durations)))
    return path


def reference_bytes(tmp_path: Path, row: dict, fmt: str = "float32") -> bytes:
    """Render one manifest row's variant independently (patch file + load_patch + render_to_file)."""
    patch = tmp_path / "ref_patch.toml"
    patch.write_text(
        PATCH.format(
            mallet=row["mallet.duration"],
            impulse=row["score[0].impact.impulse"],
            location=row["score[0].impact.location"],
        )
    )
    p = load_patch(patch)
    out = tmp_path / "ref.wav"
    OfflineEngine(p.graph, p.score, 16000, 64).render_to_file(out, 0.2, fmt)
    data = bytearray(out.read_bytes())
    at = data.find(b"PEAK")  # float WAV: libsndfile writes the time of writing here
    if at >= 0:
        data[at + 12 : at + 16] = b"\0\0\0\0"
    return bytes(data)


def manifest(outdir: Path) -> list[dict]:
    with open(outdir / "manifest.csv", newline="") as fh:
        return list(csv.DictReader(fh))


def files(outdir: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(outdir.glob("*.wav"))}


def cli(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="jassy")
    add_command(parser.add_subparsers())
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except JassyError as exc:
        print(f"jassy: error: {exc}", file=sys.stderr)
        return 2


def kill_once(marker: str, index: int, task):
    """Render, except that the first worker to reach variant ``index`` dies on the spot."""
    if task.index == index:
        try:
            fd = os.open(marker, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
        except FileExistsError:
            pass
        else:
            os.write(fd, str(os.getpid()).encode())
            os.close(fd)
            os._exit(17)
    return render_task(task)


def always_kill_3(task):
    """A variant (index 3) that crashes its worker every time."""
    if task.index == 3:
        os._exit(17)
    return render_task(task)


def stop_after(count: int, task):
    """Render, but act as if Ctrl-C was pressed when variant ``count`` starts."""
    if task.index == count:
        raise KeyboardInterrupt
    return render_task(task)


@pytest.fixture(scope="module")
def serial_run(tmp_path_factory):
    """The grid rendered serially in this process: the reference run of the other backends."""
    tmp = tmp_path_factory.mktemp("serial")
    grid = write_grid(tmp)
    result = run_batch(grid, tmp / "out", scheduler="serial")
    return tmp, grid, result


# ---------------------------------------------------------------------------- the grid


def test_grid_expands_product_and_seeded_random(tmp_path):
    path = write_grid(tmp_path)
    text = path.read_text() + textwrap.dedent(
        """
        [random]
        n = 3
        seed = 11
        "plate.decay_scale" = { loguniform = [0.5, 4.0] }
        "plate.freq_scale" = { uniform = [0.9, 1.1] }
        "score[1].impact.location" = { choice = ["centre", "edge"] }
        """
    )
    path.write_text(text)
    grid = load_grid(path)
    assert len(grid.variants) == 8 * 3
    assert grid.columns == [
        "score[0].impact.location",
        "score[0].impact.impulse",
        "mallet.duration",
        "plate.decay_scale",
        "plate.freq_scale",
        "score[1].impact.location",
    ]
    # the full product, in order (last key fastest), each grid point with n random draws
    cells = [tuple(v.overrides[k] for k in grid.columns[:3]) for v in grid.variants[::3]]
    assert cells == [
        (loc, imp, dur) for loc in ("centre", "edge") for imp in (0.01, 0.02) for dur in (0.001, 0.0003)
    ]
    decay = np.array([v.overrides["plate.decay_scale"] for v in grid.variants])
    freq = np.array([v.overrides["plate.freq_scale"] for v in grid.variants])
    assert np.all((decay >= 0.5) & (decay <= 4.0)) and np.all((freq >= 0.9) & (freq <= 1.1))
    assert len(set(decay)) == len(decay)  # independent draws
    assert {v.overrides["score[1].impact.location"] for v in grid.variants} == {"centre", "edge"}
    # seeded: the same file gives the same variants, another seed other values
    again = load_grid(path)
    assert [v.id for v in again.variants] == [v.id for v in grid.variants]
    assert [v.overrides for v in again.variants] == [v.overrides for v in grid.variants]
    path.write_text(text.replace("seed = 11", "seed = 12"))
    other = load_grid(path)
    assert not set(v.id for v in other.variants) & set(v.id for v in grid.variants)
    # ids name the files and are unique
    assert len({v.filename for v in grid.variants}) == 24
    assert all(v.filename == f"hit-{v.id[:12]}.wav" for v in grid.variants)


def test_loguniform_is_uniform_in_log(tmp_path):
    path = write_grid(tmp_path, durations=[0.001])
    path.write_text(path.read_text() + '[random]\nn = 500\n"plate.gain" = { loguniform = [0.01, 100.0] }\n')
    gains = np.array([v.overrides["plate.gain"] for v in load_grid(path).variants])
    logs = np.log10(gains)
    assert logs.min() >= -2 and logs.max() <= 2
    # each decade gets about a quarter of the draws (binomial sd ~ 9.7 of 500 * 4 / 4)
    counts = np.histogram(logs, bins=[-2, -1, 0, 1, 2])[0]
    assert np.all(np.abs(counts - len(gains) / 4) < 45), counts


def test_variant_id_tracks_content(tmp_path):
    base = load_grid(write_grid(tmp_path))
    ids = [v.id for v in base.variants]
    # another render option, another patch content or another value: all new ids
    p = write_grid(tmp_path, name="g2.toml")
    p.write_text(p.read_text().replace("duration = 0.2", "duration = 0.3"))
    assert not set(ids) & {v.id for v in load_grid(p).variants}
    p.write_text(write_grid(tmp_path, name="g3.toml").read_text().replace("gain = 20.0", "gain = 19.0"))
    assert not set(ids) & {v.id for v in load_grid(p).variants}
    # a duplicated value gives the same variant once
    p = write_grid(tmp_path, durations=[0.001, 0.0003, 0.001], name="g4.toml")
    grid = load_grid(p)
    assert [v.id for v in grid.variants] == ids and grid.duplicates == 4


def test_model_files_and_node_overrides_match_jassy_render(tmp_path):
    """A patch file with a model file: each variant equals `jassy render p.toml --set ...`."""
    (tmp_path / "m_model.toml").write_text(
        "frequencies = [500.0, 1300.0]\ndecays = [4.0, 7.0]\ngains = [[1.0, 0.4], [0.3, 1.0]]\n"
        'points = ["a", "b"]\n'
    )
    patch = tmp_path / "p.toml"
    patch.write_text(
        '[patch]\nduration = 0.15\n[models.m]\nfile = "m_model.toml"\n[nodes.h]\ntype = "ImpactForce"\n'
        '[nodes.b]\ntype = "ModalBank"\nmodel = "m"\ninput = "h"\n[outputs]\naudio = "b"\nhaptic = "h"\n'
        '[[score]]\ntime = 0.0\nnode = "h"\nimpact = { impulse = 0.01, location = "a" }\n'
    )
    grid = tmp_path / "g.toml"
    grid.write_text(
        'patch = "p.toml"\n[render]\nsample_rate = 16000\nformat = "pcm24"\ncontainer = "flac"\n'
        'haptic = "npz"\n[grid]\n"b.freq_scale" = [1.0, 1.5]\n"b.location" = ["a", "b"]\n'
    )
    result = run_batch(grid, tmp_path / "out", scheduler="serial")
    assert (result.rendered, result.failed) == (4, 0)
    for row in manifest(tmp_path / "out"):
        ref = load_patch(patch, [f"b.freq_scale={row['b.freq_scale']}", f'b.location="{row["b.location"]}"'])
        OfflineEngine(ref.graph, ref.score, 16000, 64).render_to_file(
            tmp_path / "ref.flac", 0.15, "pcm24", tmp_path / "ref.npz"
        )
        assert (tmp_path / "out" / row["output"]).read_bytes() == (tmp_path / "ref.flac").read_bytes()
        assert row["output"].endswith(".flac") and row["haptic_output"] == row["output"][:-5] + ".force.npz"
        with np.load(tmp_path / "out" / row["haptic_output"]) as got, np.load(tmp_path / "ref.npz") as want:
            assert np.array_equal(got["data"], want["data"]) and float(got["sample_rate"]) == 16000
    again = run_batch(grid, tmp_path / "out", scheduler="serial")
    assert again.skipped == 4
    (tmp_path / "out" / manifest(tmp_path / "out")[0]["haptic_output"]).unlink()
    assert run_batch(grid, tmp_path / "out", scheduler="serial").rendered == 1


def test_npz_time_stamps_are_fixed(tmp_path):
    import io
    import zipfile

    def npz(date):
        buf = io.BytesIO()
        with zipfile.ZipFile(buf, "w") as z:
            z.writestr(zipfile.ZipInfo("data.npy", date_time=date), b"\x93NUMPY-ish payload")
        return buf.getvalue()

    a, b = npz((2024, 5, 1, 12, 0, 0)), npz((2025, 1, 2, 3, 4, 6))
    assert a != b and deterministic_npz(a) == deterministic_npz(b)
    with zipfile.ZipFile(io.BytesIO(deterministic_npz(a))) as z:
        assert z.read("data.npy") == b"\x93NUMPY-ish payload"


def test_model_file_content_is_part_of_the_identity(tmp_path):
    model = tmp_path / "m_model.toml"
    model.write_text("frequencies = [500.0]\ndecays = [4.0]\ngains = [[1.0]]\n")
    patch = tmp_path / "p.toml"
    patch.write_text(
        '[models.m]\nfile = "m_model.toml"\n[nodes.h]\ntype = "ImpactForce"\n'
        '[nodes.b]\ntype = "ModalBank"\nmodel = "m"\ninput = "h"\n[outputs]\naudio = "b"\n'
        '[[score]]\ntime = 0.0\nnode = "h"\nimpact = { impulse = 0.01 }\n'
    )
    grid = tmp_path / "g.toml"
    grid.write_text('patch = "p.toml"\n[render]\nduration = 0.1\n[grid]\n"b.gain" = [1.0, 2.0]\n')
    first = [v.id for v in load_grid(grid).variants]
    model.write_text("frequencies = [510.0]\ndecays = [4.0]\ngains = [[1.0]]\n")
    assert not set(first) & {v.id for v in load_grid(grid).variants}


@pytest.mark.parametrize(
    "section, message",
    [
        ('[grid]\n"hammer.duration" = [0.001]', "unknown node 'hammer'"),
        ('[grid]\n"mallet.hardness" = [0.001]', "ImpactForce has no parameter 'hardness'"),
        ('[grid]\n"mallet.type" = ["Sine"]', "only parameters can vary"),
        ('[grid]\n"score[5].impact.impulse" = [0.1]', "score has 2 entries"),
        ('[grid]\n"score[0].set.gain" = [0.1]', "score[0] is a 'impact' event, not 'set'"),
        ('[grid]\n"score[0].impact.speed" = [0.1]', "impact has no argument 'speed'"),
        ('[grid]\n"models.wood.file" = ["w.toml"]', "unknown model 'wood'"),
        ('[grid]\n"render.container" = ["flac"]', "render option 'container' cannot vary"),
        ('[grid]\n"mallet.duration" = []', "expected a non-empty array"),
        ('[random]\nn = 2\n"mallet.duration" = { gaussian = [0, 1] }', "expected one of {uniform"),
        ('[random]\nn = 2\n"plate.gain" = { loguniform = [0.0, 1.0] }', "expected 0 < lo <= hi"),
        ('[random]\nn = 0\n"plate.gain" = { uniform = [0.0, 1.0] }', "random.n"),
        (
            '[set]\n"plate.gain" = 1.0\n[random]\nn = 1\n"plate.gain" = { uniform = [0, 1] }',
            "appears in both",
        ),
    ],
)
def test_bad_keys_name_the_grid_file_and_key(tmp_path, section, message):
    path = write_grid(tmp_path)
    text = path.read_text().replace("[grid]\n", "[unused]\n", 1).split("[unused]")[0]
    path.write_text(text + section + "\n")
    with pytest.raises(GridError) as err:
        load_grid(path)
    text = str(err.value)
    assert str(path) in text and message in text
    if "n = 0" not in section:
        key = section.split('"')[1]
        assert f'"{key}"' in text


def test_bad_grid_files(tmp_path):
    path = tmp_path / "g.toml"
    (tmp_path / "hit.toml").write_text(PATCH.format(mallet=0.001, impulse=0.01, location="edge"))
    for body, message in [
        ('patch = "nope"\n', "is not an inline patch"),
        ('patch = "bell"\ncolour = 1\n', "unknown top-level key 'colour'"),
        ('patch = "bell"\n[render]\nformat = "float32"\ncontainer = "flac"\n', "FLAC stores integers"),
        ('patch = "bell"\n[render]\nduration = -1\n', "render.duration"),
        ("[[sweep]]\ngrid = {}\n", "sweep[0].patch: missing"),
        ("patch = ", "not valid TOML"),
        ('patch = "hit.toml"\n', "render.duration: patch hit sets no duration"),
        (
            'patch = "bell"\n[grid.status]\nx = { "bell.gain" = 1.0 }\n',
            "'status' is a column of the manifest",
        ),
    ]:
        path.write_text(body)
        with pytest.raises(GridError, match=r".*") as err:
            load_grid(path)
        assert str(path) in str(err.value) and message in str(err.value), str(err.value)
    assert cli(["batch", str(tmp_path / "missing.toml"), "-o", str(tmp_path / "o")]) == 2


# ----------------------------------------------------------------------- rendering


def test_serial_outputs_equal_independent_renders(serial_run):
    tmp, _, result = serial_run
    assert (result.total, result.rendered, result.failed, result.skipped) == (8, 8, 0, 0)
    rows = manifest(tmp / "out")
    assert [r["status"] for r in rows] == ["ok"] * 8
    assert len(files(tmp / "out")) == 8
    for row in rows:
        data = (tmp / "out" / row["output"]).read_bytes()
        assert data == reference_bytes(tmp, row), row["output"]
        audio, rate = soundfile.read(tmp / "out" / row["output"])
        assert rate == 16000 and audio.shape == (3200,) and int(row["frames"]) == 3200
        assert float(row["peak"]) == pytest.approx(np.max(np.abs(audio)), rel=1e-6)
        assert float(row["duration"]) == 0.2
        import hashlib

        assert row["sha256"] == hashlib.sha256(data).hexdigest()
    # the impulse scales the first strike: the harder variant is louder
    by = {
        (r["score[0].impact.location"], r["score[0].impact.impulse"], r["mallet.duration"]): r for r in rows
    }
    assert float(by[("centre", "0.02", "0.001")]["peak"]) > float(by[("centre", "0.01", "0.001")]["peak"])


def test_float_wav_time_stamp_is_zeroed(tmp_path):
    path = tmp_path / "x.wav"
    soundfile.write(path, np.linspace(-0.5, 0.5, 100), 8000, "FLOAT")
    data = bytearray(path.read_bytes())
    at = data.find(b"PEAK")
    assert at > 0, "libsndfile writes a PEAK chunk in float WAV files"
    other = bytearray(data)
    other[at + 12 : at + 16] = b"\x01\x02\x03\x04"  # written at another time
    a, b = deterministic_wav(bytes(data)), deterministic_wav(bytes(other))
    assert a == b and a[at + 12 : at + 16] == b"\0\0\0\0"
    assert len(a) == len(data) and a[: at + 12] == data[: at + 12] and a[at + 16 :] == data[at + 16 :]
    path.write_bytes(a)
    assert np.array_equal(soundfile.read(path)[0], soundfile.read(tmp_path / "x.wav")[0])
    assert deterministic_wav(b"fLaC....") == b"fLaC...."


def test_rerun_skips_everything_and_repairs_what_is_missing(serial_run, tmp_path):
    tmp, grid, _ = serial_run
    out = tmp_path / "out"
    run_batch(grid, out, scheduler="serial")
    mtimes = {p.name: p.stat().st_mtime_ns for p in out.glob("*.wav")}
    again = run_batch(grid, out, scheduler="serial")
    assert (again.skipped, again.rendered, again.failed) == (8, 0, 0)
    assert {p.name: p.stat().st_mtime_ns for p in out.glob("*.wav")} == mtimes
    rows = manifest(out)
    (out / rows[1]["output"]).unlink()  # lost
    damaged = out / rows[5]["output"]
    damaged.write_bytes(damaged.read_bytes()[:-2] + b"\0\0")  # changed
    repair = run_batch(grid, out, scheduler="serial")
    assert (repair.skipped, repair.rendered) == (6, 2)
    assert files(out) == files(tmp / "out")
    forced = run_batch(grid, out, scheduler="serial", force=True)
    assert forced.rendered == 8 and files(out) == files(tmp / "out")


def fail_long_mallet(task):
    """Render, except that variants with the 0.0003 s mallet fail (as a render error would)."""
    if task.data["nodes"]["mallet"]["duration"] == 0.0003:
        return error_result(task, "nodes.mallet.duration: refused by the test")
    return render_task(task)


def test_bad_values_are_refused_before_any_work(tmp_path, capsys):
    grid = write_grid(tmp_path, fmt="pcm16", durations=[0.001, -1.0])
    code = main(["batch", str(grid), "-o", str(tmp_path / "out"), "--scheduler", "serial", "-q"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1
    assert "mallet.duration" in err and "got -1.0" in err
    assert not (tmp_path / "out").exists()


def test_failing_variant_is_recorded_and_others_go_on(tmp_path, capsys):
    grid = write_grid(tmp_path, fmt="pcm16", durations=[0.001, 0.0003])
    result = run_batch(grid, tmp_path / "out", scheduler="serial", render=fail_long_mallet)
    assert (result.rendered, result.failed) == (4, 4)
    rows = manifest(tmp_path / "out")
    bad = [r for r in rows if r["mallet.duration"] == "0.0003"]
    good = [r for r in rows if r["mallet.duration"] == "0.001"]
    assert len(bad) == 4 and len(good) == 4
    assert all(r["status"] == "error" and r["output"] == "" for r in bad)
    assert all("refused by the test" in r["error"] for r in bad)
    assert all(r["status"] == "ok" and (tmp_path / "out" / r["output"]).is_file() for r in good)
    # a rerun tries the failed ones again, and only them
    again = run_batch(grid, tmp_path / "out", scheduler="serial", render=fail_long_mallet)
    assert (again.skipped, again.rendered, again.failed) == (4, 0, 4)


def test_interrupt_keeps_finished_variants(serial_run, tmp_path):
    tmp, grid, _ = serial_run
    out = tmp_path / "out"
    with pytest.raises(KeyboardInterrupt):
        run_batch(grid, out, scheduler="serial", render=functools.partial(stop_after, 3))
    rows = manifest(out)
    assert [r["status"] for r in rows] == ["ok"] * 3 + ["pending"] * 5
    assert not list(out.glob(".*.partial"))
    rest = run_batch(grid, out, scheduler="serial")
    assert (rest.skipped, rest.rendered) == (3, 5)
    assert files(out) == files(tmp / "out")


def test_killed_client_loses_nothing(serial_run, tmp_path):
    """The batch process dies (os._exit) mid-run, after 5 variants and before the manifest
    was rewritten (rewrites are held off here): the journal keeps every finished variant,
    and the rerun renders only the rest."""
    tmp, grid, _ = serial_run
    out = tmp_path / "out"
    code = (
        "import functools, sys; sys.path.insert(0, sys.argv[3]); import test_batch; "
        "import jassy.batch; jassy.batch.FLUSH_SECONDS = 1e9; from jassy.batch import run_batch; "
        "run_batch(sys.argv[1], sys.argv[2], scheduler='serial', "
        "render=functools.partial(test_batch.kill_once, sys.argv[4], 5))"
    )
    marker = tmp_path / "killed"
    proc = subprocess.run(
        [sys.executable, "-c", code, str(grid), str(out), str(Path(__file__).parent), str(marker)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 17, proc.stderr
    assert [r["status"] for r in manifest(out)] == ["pending"] * 8  # not yet rewritten...
    assert len((out / ".manifest.journal").read_text().splitlines()) == 5  # ...but journaled
    rest = run_batch(grid, out, scheduler="serial")
    assert (rest.skipped, rest.rendered) == (5, 3)
    assert files(out) == files(tmp / "out")
    assert not (out / ".manifest.journal").exists()


def test_parquet_manifest(serial_run, tmp_path):
    pq = pytest.importorskip("pyarrow.parquet")
    tmp, grid, _ = serial_run
    result = run_batch(grid, tmp_path / "out", scheduler="serial", parquet=True)
    table = pq.read_table(result.parquet).to_pydict()
    rows = manifest(tmp_path / "out")
    assert table["variant"] == [r["variant"] for r in rows]
    assert table["score[0].impact.impulse"] == [float(r["score[0].impact.impulse"]) for r in rows]
    assert table["peak"] == [float(r["peak"]) for r in rows]


# ---------------------------------------------------------------------- process pool


def test_without_dask_the_pool_gives_identical_files(serial_run, tmp_path, monkeypatch):
    """No Dask: the default falls back to the process pool; a worker killed mid-run is replaced."""
    tmp, grid, _ = serial_run
    monkeypatch.setitem(sys.modules, "distributed", None)  # import distributed -> ImportError
    monkeypatch.setitem(sys.modules, "dask", None)
    with pytest.raises(JassyError, match="needs Dask"):
        run_batch(grid, tmp_path / "o2", scheduler="tcp://127.0.0.1:1")
    marker = tmp_path / "killed"
    render = functools.partial(kill_once, str(marker), 4)
    result = run_batch(grid, tmp_path / "out", workers=2, chunk=2, render=render)
    assert result.backend == "process pool (2 workers)"
    assert marker.exists(), "a worker was killed"
    assert (result.rendered, result.failed) == (8, 0)
    assert files(tmp_path / "out") == files(tmp / "out")
    workers = {r["worker"] for r in manifest(tmp_path / "out")}
    assert manifest(tmp / "out")[0]["worker"] not in workers  # rendered by pool workers
    # the variant whose worker died was rendered again by another one (which worker takes
    # which chunk depends on the machine's load, so no more is asserted)
    assert not manifest(tmp_path / "out")[4]["worker"].endswith(":" + marker.read_text())


def test_pool_fails_a_variant_that_always_kills_its_worker(serial_run, tmp_path):
    tmp, grid, _ = serial_run
    result = run_batch(grid, tmp_path / "out", scheduler="pool", workers=2, chunk=3, render=always_kill_3)
    assert (result.rendered, result.failed) == (7, 1)
    rows = manifest(tmp_path / "out")
    assert rows[3]["status"] == "error" and "worker process died (exit code 17) 3 times" in rows[3]["error"]
    lost = manifest(tmp / "out")[3]["output"]
    assert files(tmp_path / "out") == {k: v for k, v in files(tmp / "out").items() if k != lost}


# ------------------------------------------------------------------------------- dask


@pytest.fixture(scope="module")
def cluster():
    """A LocalCluster of 2 worker processes, started here the way ``jassy batch`` starts one."""
    pytest.importorskip("distributed")
    from jassy.batch.backends import local_cluster

    with local_cluster(2) as cluster:
        yield cluster


def test_dask_cluster_renders_grid_identically(cluster, serial_run, tmp_path, capsys):
    """`--scheduler tcp://...` on a LocalCluster of 2 worker processes started by this test."""
    tmp, grid, _ = serial_run
    out = tmp_path / "out"
    assert cli(["batch", str(grid), "-o", str(out), "--scheduler", cluster.scheduler_address]) == 0
    assert "0 already done, 8 rendered, 0 failed" in capsys.readouterr().out
    assert files(out) == files(tmp / "out")
    rows = manifest(out)
    assert {r["worker"] for r in rows}.isdisjoint({manifest(tmp / "out")[0]["worker"]})
    assert cli(["batch", str(grid), "-o", str(out), "--scheduler", cluster.scheduler_address]) == 0
    assert "8 already done, 0 rendered" in capsys.readouterr().out


def test_dask_killed_worker_loses_no_variant(cluster, serial_run, tmp_path):
    tmp, grid, _ = serial_run
    marker = tmp_path / "killed"
    result = run_batch(
        grid,
        tmp_path / "out",
        scheduler=cluster.scheduler_address,
        chunk=1,
        render=functools.partial(kill_once, str(marker), 2),
    )
    assert marker.exists(), "a worker was killed"
    killed = marker.read_text()
    assert (result.rendered, result.failed) == (8, 0)
    rows = manifest(tmp_path / "out")
    assert all(r["status"] == "ok" for r in rows)
    assert not rows[2]["worker"].endswith(f":{killed}")  # rendered again by another process
    assert files(tmp_path / "out") == files(tmp / "out")


@pytest.mark.slow
def test_default_runs_its_own_local_cluster(serial_run, tmp_path):
    pytest.importorskip("distributed")
    tmp, grid, _ = serial_run
    result = run_batch(grid, tmp_path / "out", workers=2)
    assert result.backend == "dask LocalCluster (2 workers)"
    assert files(tmp_path / "out") == files(tmp / "out")


def test_example_dataset_grid():
    """examples/impact_dataset.toml: 156 variants; a variant of each object renders, unclipped."""
    path = Path(__file__).parents[1] / "examples" / "impact_dataset.toml"
    grid = load_grid(path)
    assert len(grid.variants) == 4 * 5 * 3 * 2 + 4 * 3 * 3
    assert grid.columns[:3] == ["material", "bar.freq_scale", "bar.decay_scale"] and "mallet" in grid.columns
    blobs = BlobReader()
    for variant in (grid.variants[0], grid.variants[-1]):
        result = render_task(make_task(variant, path.parent, blobs))
        assert result["status"] == "ok", result["error"]
        assert 0.05 < result["peak"] < 0.95


def test_cli_dry_run_and_bad_arguments(serial_run, tmp_path, capsys):
    _, grid, _ = serial_run
    assert cli(["batch", str(grid), "-o", str(tmp_path / "never"), "--dry-run"]) == 0
    out = capsys.readouterr().out
    assert "grid t: 8 variants: hit x8" in out and "mallet.duration=0.0003" in out
    assert not (tmp_path / "never").exists()
    assert cli(["batch", str(grid), "-o", str(tmp_path / "o"), "--scheduler", "cloud"]) == 2
    assert "--scheduler: expected tcp://HOST:PORT" in capsys.readouterr().err
    assert cli(["batch", str(grid), "-o", str(tmp_path / "o"), "--workers", "0"]) == 2


def test_manifest_columns_are_the_reserved_names():
    from jassy.batch.grid import RESERVED_COLUMNS
    from jassy.batch.manifest import columns

    assert sorted(columns([], haptic=True)) == sorted(RESERVED_COLUMNS)


def test_two_batches_cannot_share_a_directory(serial_run, tmp_path):
    _, grid, _ = serial_run
    (tmp_path / "out").mkdir()
    lock = _Lock(tmp_path / "out")
    try:
        with pytest.raises(JassyError, match="another jassy batch is writing"):
            run_batch(grid, tmp_path / "out", scheduler="serial")
    finally:
        lock.release()
    assert run_batch(grid, tmp_path / "out", scheduler="serial").rendered == 8
