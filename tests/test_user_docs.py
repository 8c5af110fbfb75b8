"""User documentation that must stay true: `jassy batch --help` (the grid format and its
example), the model example of docs/formats.md, the README's file-writing snippet, and the
wine glass, mug and pot meshes of the object library (real dimensions, points on the surface)."""

from __future__ import annotations

import math
import os
import re
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from jassy.batch import GRID_HELP
from jassy.batch.grid import load_grid
from jassy.modal_model import ModalModel
from patches.models_vessels import TURN, mug_points, pot_points, wine_glass_points
from patches.objects import OBJECTS
from physics.modal.subdivision import surface_frames
from physics.modal.vessels import (
    GLASS,
    MUG,
    POT,
    handle_centreline,
    mug,
    mug_profile,
    pot,
    wine_glass,
    wine_glass_profile,
)

ROOT = Path(__file__).resolve().parents[1]


def test_batch_help_documents_the_grid_format_without_pointing_to_source_files():
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    text = subprocess.run(
        [sys.executable, "-m", "jassy", "batch", "--help"],
        capture_output=True,
        text=True,
        env=env,
        timeout=60,
    ).stdout
    for key in ("[grid]", "[random]", "[render]", "[[sweep]]", "score[i].ACTION.ARG", "manifest.csv"):
        assert key in text
    assert not re.search(r"\w+\.py\b", text)


def test_the_example_grid_of_batch_help_is_a_valid_grid(tmp_path):
    path = tmp_path / "grid.toml"
    path.write_text(GRID_HELP.split("example:\n")[1])
    grid = load_grid(path)
    assert len(grid.variants) == 2 * 3  # the full product of the two lists


def test_the_model_file_example_of_docs_formats_loads(tmp_path):
    text = (ROOT / "docs" / "formats.md").read_text()
    block = re.search(r"```toml\n(name = \"door\".*?)```", text, re.S).group(1)
    path = tmp_path / "door.toml"
    path.write_text(block)
    model = ModalModel.load(path)
    assert model.points == ("centre", "latch_edge") and model.reference_gain == 52.3


def test_the_readme_snippet_writes_audio_and_force_files(tmp_path):
    text = (ROOT / "README.md").read_text()
    blocks = re.findall(r"```python\n(.*?) *```", text, re.S)
    snippet = next(b for b in blocks if 'path="glass.wav"' in b)  # the one that writes files
    code = textwrap.dedent(snippet).replace('"patches/', f'"{ROOT}/patches/')
    code = code.replace('"glass.wav"', f'"{tmp_path}/glass.wav"').replace(
        '"glass_force.csv"', f'"{tmp_path}/f.csv"'
    )
    scope: dict = {}
    exec(compile(code, "README", "exec"), scope)
    peak = float(np.max(np.abs(scope["result"].audio)))
    assert (tmp_path / "glass.wav").stat().st_size > 0 and (tmp_path / "f.csv").stat().st_size > 0
    assert 10 ** (-30 / 20) < peak < 10 ** (-6 / 20)  # a calibrated strike at the rim


def pappus_volume(profile: np.ndarray, sections: int) -> float:
    """Volume of a closed (r, z) polygon revolved about z: 2 pi x area x centroid radius,
    times the ratio of a regular ``sections``-gon's area to its circle's."""
    r, z = profile[:-1, 0], profile[:-1, 1]
    r1, z1 = np.roll(r, -1), np.roll(z, -1)
    cross = r * z1 - r1 * z
    moment = np.sum((r + r1) * cross) / 6  # area x centroid radius (signed)
    polygon = sections * math.sin(2 * math.pi / sections) / (2 * math.pi)
    return abs(2 * math.pi * moment) * polygon


def test_wine_glass_mug_and_pot_meshes_have_their_stated_dimensions():
    glass = wine_glass()
    assert glass.is_watertight
    assert glass.volume == pytest.approx(pappus_volume(wine_glass_profile(), 72), rel=1e-3)
    assert glass.bounds[1, 2] == pytest.approx(GLASS.height)
    assert np.ptp(glass.vertices[:, :2], axis=0).max() <= 2 * GLASS.bowl_radius + 1e-9
    cup = mug()
    assert cup.is_watertight
    line = handle_centreline()
    handle = math.pi * MUG.handle_radius**2 * np.linalg.norm(np.diff(line, axis=0), axis=1).sum()
    expected = pappus_volume(mug_profile(), 72) + handle
    assert cup.volume == pytest.approx(expected, rel=5e-3)  # the tube's polygonal section
    assert cup.bounds[1, 2] == pytest.approx(MUG.height)
    kettle = pot()
    assert kettle.is_watertight
    assert kettle.volume == pytest.approx(pappus_volume(mug_profile(POT), 96), rel=1e-3)
    assert kettle.bounds[1, 2] == pytest.approx(POT.height)
    assert np.ptp(kettle.vertices[:, :2], axis=0).max() == pytest.approx(2 * POT.radius, rel=1e-3)


@pytest.mark.parametrize(
    "name, mesh, points",
    [("wine_glass", wine_glass, wine_glass_points), ("mug", mug, mug_points), ("pot", pot, pot_points)],
)
def test_named_points_lie_on_the_surface_and_are_described(name, mesh, points):
    surface = mesh(turn=TURN)
    where = points()
    asked = np.array(list(where.values()))
    closest, _ = surface_frames(surface, asked)
    distance = np.linalg.norm(closest - asked, axis=1)
    assert np.all(distance < 1e-3), dict(zip(where, distance, strict=True))
    info = OBJECTS[name]
    assert set(info.points) == set(where)
    model = ModalModel.load(ROOT / "patches" / info.file)
    assert model.points == tuple(where) and model.reference_gain is not None


def test_the_wine_glass_example_strikes_the_resonator_it_rubs():
    from jassy.patchfile import load_patch

    patch = load_patch(ROOT / "examples" / "wine_glass.toml")
    finger = patch.graph.nodes["finger"]
    assert finger.sources["strike"] is patch.graph.nodes["spoon"]
    assert {e.node for e in patch.score} == {"finger", "spoon"}
