"""Atomic files, NaN/Inf quarantine, the final limiter, and the CLI's exit codes."""

import os
import subprocess
import sys

import numpy as np
import pytest
import soundfile as sf
from helpers import ArraySource, FailingSource, NaNSource

from jassy import Graph, OfflineEngine, RenderError, render
from jassy.apps.cli import main
from jassy.safety import CEILING
from ugens.mix import Gain

FS = 48000


def leftovers(directory):
    return sorted(p.name for p in directory.iterdir())


@pytest.mark.parametrize("error", [RuntimeError("ugen failed"), KeyboardInterrupt()])
def test_failed_render_leaves_no_file_and_keeps_the_old_one(tmp_path, error):
    target = tmp_path / "out.wav"
    target.write_bytes(b"previous")
    graph = Graph(Gain(FailingSource(at=30000, error=error)))
    with pytest.raises(type(error)):
        OfflineEngine(graph, [], FS, 64).render_to_file(target, 1.0)
    assert target.read_bytes() == b"previous"
    assert leftovers(tmp_path) == ["out.wav"]
    target.unlink()
    with pytest.raises(type(error)):
        OfflineEngine(graph, [], FS, 64).render_to_file(target, 1.0)
    assert leftovers(tmp_path) == []


def test_nan_is_replaced_by_silence_reported_and_never_written(tmp_path):
    src = NaNSource(at=10000, name="wild")
    graph = Graph(src)
    summary = OfflineEngine(graph, [], FS, 64).render_to_file(tmp_path / "o.wav", 0.5)
    data, _ = sf.read(tmp_path / "o.wav")
    assert np.all(np.isfinite(data))
    assert any("'wild' produced NaN/Inf" in w for w in summary["warnings"])
    assert len(summary["warnings"]) == 1
    # before the fault the signal is intact
    t = np.arange(8192)
    np.testing.assert_allclose(data[:8192], 0.5 * np.sin(0.05 * t), atol=1e-6)


def test_limiter_keeps_loud_audio_within_the_ceiling():
    rng = np.random.default_rng(0)
    loud = rng.standard_normal(FS) * 50
    r = render(Graph(ArraySource(loud)), [], 1.0, FS)
    assert np.max(np.abs(r.audio)) <= CEILING
    quiet = np.sin(np.arange(FS) * 0.01) * 0.5
    r = render(Graph(ArraySource(quiet)), [], 1.0, FS)
    np.testing.assert_allclose(r.audio[0], quiet, atol=1e-12)


@pytest.mark.parametrize(
    "fmt, subtype, ext",
    [("float32", "FLOAT", "wav"), ("pcm16", "PCM_16", "wav"), ("pcm24", "PCM_24", "flac")],
)
def test_cli_render_formats(tmp_path, fmt, subtype, ext, capsys):
    out = tmp_path / f"bar.{ext}"
    assert main(["render", "bar", "-o", str(out), "--duration", "0.5", "--format", fmt, "-q"]) == 0
    info = sf.info(out)
    assert info.subtype == subtype and info.samplerate == FS and info.frames == FS // 2
    assert leftovers(tmp_path) == [out.name]


def test_cli_render_writes_haptic_track(tmp_path):
    out, hap = tmp_path / "b.wav", tmp_path / "b.csv"
    assert main(["render", "bell", "-o", str(out), "--duration", "0.3", "--haptic", str(hap), "-q"]) == 0
    table = np.loadtxt(hap, delimiter=",", skiprows=1)
    assert table.shape == (int(0.3 * FS), 3)
    # the only impact before 0.3 s: 0.6 N s at 0.05 s
    assert table[:, 2].sum() / FS == pytest.approx(0.6, rel=1e-9)
    assert table[np.flatnonzero(table[:, 2])[0], 0] == int(0.05 * FS) + 1


@pytest.mark.parametrize(
    "args, message",
    [
        (["render", "nosuch", "-o", "{out}"], "nosuch: not a patch file or built-in patch"),
        (["render", "bell", "-o", "{out}", "--set", "bell.freq_scale=-2"], "nodes.bell.freq_scale: expected"),
        (["render", "bell", "-o", "{out}", "--set", "nobody.gain=1"], "--set nobody.gain=1: unknown node"),
        (["render", "bell", "-o", "{out}.mp3"], "expected a .wav or .flac file name"),
        (["render", "bell", "-o", "{out}", "--duration", "-1"], "duration: expected seconds > 0"),
        (["render", "bell", "-o", "{out}", "--sr", "22050"], "below Nyquist"),
        (["render", "bell", "-o", "{out}", "--block", "0"], "--block: expected an integer in [1, "),
        (["render", "bell", "-o", "{dir}/missing/x.wav"], "does not exist"),
    ],
)
def test_cli_bad_input_exits_2_with_one_line_and_no_file(tmp_path, args, message, capsys):
    out = tmp_path / "out.wav"
    out.write_bytes(b"keep me")
    argv = [a.format(out=out, dir=tmp_path) for a in args]
    code = main(argv)
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert message in err
    assert len(err.splitlines()) == 1
    assert out.read_bytes() == b"keep me"
    assert leftovers(tmp_path) == ["out.wav"]


def test_console_script_runs_in_a_subprocess(tmp_path):
    out = tmp_path / "bell.wav"
    proc = subprocess.run(
        [sys.executable, "-m", "jassy", "render", "bell", "-o", str(out), "--duration", "0.2"],
        capture_output=True,
        text=True,
        env={**os.environ, "PYTHONPATH": os.getcwd()},
    )
    assert proc.returncode == 0, proc.stderr
    assert "wrote" in proc.stdout
    bad = subprocess.run(
        [sys.executable, "-m", "jassy", "info", "missing.toml"], capture_output=True, text=True
    )
    assert bad.returncode == 2
    assert bad.stderr.strip() == "jassy: error: missing.toml: no such patch file"


def test_writing_non_finite_data_is_refused(tmp_path):
    from jassy.files import write_signal

    with pytest.raises(RenderError, match="non-finite"):
        write_signal(tmp_path / "h.npz", np.array([[0.0, np.nan]]), FS)
    assert leftovers(tmp_path) == []


def test_offline_rendering_never_loads_audio_device_libraries(tmp_path):
    code = (
        "import sys; from jassy.apps.cli import main; "
        f"main(['render', 'bell', '-o', r'{tmp_path / 'b.wav'}', '--duration', '0.1', '-q']); "
        "print('sounddevice' in sys.modules or 'jassy.engines.portaudio' in sys.modules)"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert proc.stdout.strip() == "False"


def test_stereo_patch_writes_two_channels(tmp_path):
    from jassy.patchfile import build_patch

    patch = build_patch(
        {
            "nodes": {
                "hit": {"type": "ImpactForce"},
                "left": {"type": "Gain", "input": "hit", "gain": 0.001},
                "right": {"type": "Gain", "input": "hit", "gain": -0.002},
            },
            "outputs": {"audio": ["left", "right"]},
            "score": [{"time": 0.01, "node": "hit", "impact": {"impulse": 1.0}}],
        }
    )
    out = tmp_path / "s.wav"
    OfflineEngine(patch.graph, patch.score, FS, 64).render_to_file(out, 0.05)
    data, _ = sf.read(out)
    assert data.shape == (int(0.05 * FS), 2)
    np.testing.assert_allclose(data[:, 1], -2 * data[:, 0], atol=1e-6)


def test_examples_run(tmp_path):
    root = os.path.dirname(os.path.dirname(__file__))
    out = tmp_path / "c.wav"
    subprocess.run(
        [sys.executable, os.path.join(root, "examples", "compose_patch.py"), str(out)],
        check=True,
        capture_output=True,
    )
    assert sf.info(out).frames == 3 * FS


def test_cli_list_names_every_patch_scene_and_ugen(capsys):
    from jassy.patchfile import builtin_patches
    from jassy.registry import ugen_types

    assert main(["list"]) == 0
    out = capsys.readouterr().out
    for name in [*builtin_patches(), "drill", *ugen_types()]:
        assert name in out


def reference_limiter(x, ceiling, release):
    """The limiter sample by sample in plain Python: gain drops to ceiling/peak, recovers
    as g = 1 - (1 - g) * release; NaN/Inf become 0; output clipped to the ceiling."""
    y = np.where(np.isfinite(x), x, 0.0)
    g = 1.0
    for i in range(y.shape[1]):
        peak = float(np.max(np.abs(y[:, i])))
        g = 1.0 - (1.0 - g) * release
        if peak * g > ceiling:
            g = ceiling / peak
        y[:, i] = np.clip(y[:, i] * g, -ceiling, ceiling)
    return y


def test_limiter_passes_quiet_stretches_untouched_and_matches_the_reference_bit_for_bit():
    from jassy.safety import limit, release_coefficient

    rng = np.random.default_rng(7)
    x = rng.standard_normal((2, 6000)) * 0.2  # quiet, with loud bursts and a NaN
    x[:, 1000:1010] *= 8.0
    x[0, 3000] = np.nan
    x[1, 4500:4503] = 3.0
    release = release_coefficient(0.0005, 48000)
    expected = reference_limiter(x, CEILING, release)
    for block in (1, 64, 6000):
        y, state = x.copy(), np.ones(1)
        for start in range(0, y.shape[1], block):
            piece = y[:, start : start + block]  # a view: limited in place
            limit(piece, piece.shape[1], state, CEILING, release)
        np.testing.assert_array_equal(y, expected)
    np.testing.assert_array_equal(expected[:, :1000], x[:, :1000])  # before the first burst: as it was


def test_engine_limiter_over_chunks_matches_the_reference_and_meters_the_longest_run():
    """The engine skips limiting chunks that are quiet and fully released; the audio must
    still equal the plain limiter bit for bit, and the meter's longest held run must be the
    longest over the whole render (a later, shorter run must not replace it)."""
    from jassy.engines.offline import CHUNK_FRAMES
    from jassy.safety import release_coefficient

    rng = np.random.default_rng(3)
    x = rng.standard_normal(4 * CHUNK_FRAMES) * 0.1
    x[100:400] = 5.0  # a long run at the ceiling in the first chunk
    x[2 * CHUNK_FRAMES + 50 : 2 * CHUNK_FRAMES + 60] = -5.0  # a short one two chunks later
    engine = OfflineEngine(Graph(ArraySource(x)), [], FS, 64)
    r = engine.render(x.size / FS)
    expected = reference_limiter(x[None, :], CEILING, release_coefficient(0.05, FS))
    np.testing.assert_array_equal(r.audio, expected)
    held = np.abs(expected[0]) >= CEILING * (1 - 1e-9)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], held.astype(int), [0]])))
    runs = edges[1::2] - edges[::2]
    assert engine.limiter_meter.longest == runs.max() >= 300
    assert engine.limiter_meter.pinned == held.sum()
