"""The measuring scripts under benchmarks/ answer --help and refuse bad arguments with one
line and exit code 2 (without running anything)."""

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _run(*args):
    return subprocess.run([sys.executable, *args], cwd=ROOT, capture_output=True, text=True, timeout=120)


@pytest.mark.timeout(300)
@pytest.mark.parametrize(
    "script", ["benchmarks/burr_cpu.py", "benchmarks/cold_compile.py", "benchmarks/kept_ring_variants.py"]
)
def test_help(script):
    done = _run(script, "--help")
    assert done.returncode == 0 and "usage:" in done.stdout


@pytest.mark.timeout(300)
@pytest.mark.parametrize(
    "args, expected",
    [
        (["benchmarks/burr_cpu.py", "."], "two or more checkout"),
        (["benchmarks/burr_cpu.py", ".", "/no/such/tree"], "/no/such/tree: expected a jassy checkout"),
        (["benchmarks/cold_compile.py"], "OUT.txt"),
        (["benchmarks/cold_compile.py", "out.txt"], "expected a jassy command"),
        (["benchmarks/kept_ring_variants.py", "--repeats", "0"], "--repeats: expected a positive count"),
    ],
)
def test_bad_arguments_exit_2_with_one_line(args, expected, tmp_path):
    done = _run(*[a if a != "out.txt" else str(tmp_path / a) for a in args])
    assert done.returncode == 2
    assert expected in done.stderr
    assert "Traceback" not in done.stderr
    assert not (tmp_path / "out.txt").exists()
