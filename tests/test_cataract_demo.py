"""The cataract-surgery experiment (physics/deform/cataract.py) and its example script:
checks that follow from the scenario (forceps tear the capsule, the tool eats only along the
cross groove, the cut-through lens falls apart into fragments that hit the bag and each
other), not numbers taken from a run."""

from __future__ import annotations

import importlib.util
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from physics.deform.cataract import cataract_demo
from physics.deform.fragments import lens_mesh

ROOT = Path(__file__).parents[1]
EXAMPLE = ROOT / "examples" / "cataract_demo.py"
H = 1e-3  # s, the demo's step
SPACING = 0.6e-3  # m: coarser lattices leave a crumb-bridged groove that never parts in four
TOOL_RADIUS = 0.7e-3  # m
RHEXIS_STEPS = 250
TEAR_STRAIN = 0.25  # the anterior capsule's springs tear at 25 % stretch
DISC_RADIUS = 4.5e-3  # m
TREMOR = 20e-6  # m per coordinate (normal); 5 sigma bounds every tool position


@pytest.fixture(scope="module")
def run():
    return cataract_demo(
        steps=1300, seed=1, spacing=SPACING, tool_radius=TOOL_RADIUS, rhexis_steps=RHEXIS_STEPS
    )


@pytest.mark.timeout(120)
def test_forceps_tear_the_capsule_only_while_stepped_and_only_overstretched_springs(run):
    tears = run["tear_events"]
    assert run["torn_springs"] == len(tears) > 0
    springs = [t.spring for t in tears]
    assert len(set(springs)) == len(springs)  # a torn spring stays torn
    assert all(0.0 < t.time <= RHEXIS_STEPS * H + 1e-12 for t in tears)
    assert all(t.strain >= TEAR_STRAIN for t in tears)
    assert all(math.hypot(t.position[0], t.position[1]) < DISC_RADIUS for t in tears)


@pytest.mark.timeout(120)
def test_eroded_tets_lie_within_the_tool_sphere_of_the_cross_groove(run):
    """The groove runs along the planes x = 0 and y = 0 through the lens's centre; before the
    split the lens rests as one rigid body, so in its rest frame an eroded tet's centroid is
    within the tool radius (plus the tremor) of one of the two planes."""
    mesh = lens_mesh(spacing=SPACING)
    removed = np.asarray(run["removed_tets"])
    assert removed.size == run["tets_removed"] > 0
    c = mesh.points.mean(0)
    cen = mesh.points[mesh.tets[removed]].mean(1) - c
    off_groove = np.minimum(np.abs(cen[:, 0]), np.abs(cen[:, 1]))
    near = off_groove < TOOL_RADIUS + 5 * TREMOR + 0.25 * SPACING  # + the lens settling
    # crumbs cut loose at the groove's edge move as their own fragments before the tool
    # reaches them: a few tets, never farther than a lattice cell or two
    assert near.mean() > 0.99
    assert off_groove.max() < TOOL_RADIUS + 2 * SPACING
    # both arms were cut, through the full height of the lens
    arm_y, arm_x = np.abs(cen[:, 0]) < TOOL_RADIUS, np.abs(cen[:, 1]) < TOOL_RADIUS
    for arm in (arm_x, arm_y):
        assert cen[arm, 2].min() < -1.0e-3 and cen[arm, 2].max() > 1.0e-3


@pytest.mark.timeout(120)
def test_cut_lens_splits_into_fragments_that_account_for_every_live_particle(run):
    mesh = lens_mesh(spacing=SPACING)
    alive = np.ones(mesh.tets.shape[0], dtype=bool)
    alive[run["removed_tets"]] = False
    live_particles = np.unique(mesh.tets[alive]).size
    assert run["split_time_s"] is not None and run["fragments"] >= 2
    assert len(run["fragment_sizes"]) == len(run["fragment_ids"]) == run["fragments"]
    assert sum(run["fragment_sizes"]) == live_particles
    assert min(run["fragment_sizes"]) > 0
    assert len(set(run["fragment_ids"])) == run["fragments"]


@pytest.mark.timeout(120)
def test_impacts_name_existing_bodies_and_fragments_collide_after_the_split(run):
    impacts = run["impact_events"]
    assert run["impacts"] == len(impacts) == run["impacts_boundary"] + run["impacts_fragment"]
    ids = set(run["fragment_ids"])
    after = [i for i in impacts if i.time > run["split_time_s"] + H / 2]
    assert any(i.bodies[1] >= 0 for i in after), "no fragment-fragment impact after the split"
    for i in impacts:
        a, b = i.bodies
        assert a >= 0 and (b == -1 or b > a)  # the bag is -1; pairs ordered, never self
        assert i.impulse > 0 and i.speed > 0
    for i in after:  # no erosion after the split: the fragments are the final ones
        assert i.bodies[0] in ids and (i.bodies[1] == -1 or i.bodies[1] in ids)


@pytest.mark.timeout(120)
def test_result_has_no_nan(run):
    numbers = [v for k, v in run.items() if isinstance(v, float)]
    numbers += [x for i in run["impact_events"] for x in (i.time, i.impulse, i.speed)]
    numbers += [x for t in run["tear_events"] for x in (t.time, t.strain, *t.position)]
    assert numbers and all(math.isfinite(x) for x in numbers)


def _example(*args):
    return subprocess.run(
        [sys.executable, str(EXAMPLE), *args], capture_output=True, text=True, timeout=120, cwd=ROOT
    )


spec = importlib.util.spec_from_file_location("cataract_example", EXAMPLE)
example = importlib.util.module_from_spec(spec)
spec.loader.exec_module(example)


@pytest.mark.timeout(120)
def test_example_answers_help_and_refuses_bad_arguments_in_one_line(capsys):
    done = _example("--help")
    assert done.returncode == 0 and "--steps" in done.stdout and "--json" in done.stdout
    for bad in (["--steps", "0"], ["--steps", "x"], ["--seed", "-1"], ["--nope"]):
        with pytest.raises(SystemExit) as exit_:
            example.main(bad)
        assert exit_.value.code == 2, bad
        err = capsys.readouterr().err
        assert len(err.strip().splitlines()) == 1 and "cataract_demo" in err, err


@pytest.mark.timeout(120)
def test_example_writes_the_summary_as_json(tmp_path):
    out = tmp_path / "cataract.json"
    done = _example("--steps", "30", "--json", str(out))
    assert done.returncode == 0, done.stderr
    data = json.loads(out.read_text())
    assert data["steps"] == 30 and "torn springs" in done.stdout and "fragments" in done.stdout
    assert not list(tmp_path.glob("*.partial"))


def test_example_refuses_a_json_path_in_a_missing_directory_before_running(tmp_path, capsys):
    assert example.main(["--json", str(tmp_path / "no" / "x.json")]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "--json" in err


@pytest.mark.timeout(60)
def test_moving_forceps_tear_more_springs_than_forceps_held_still():
    """The capsulorhexis is the forceps' doing: the same capsule with the grasp held where it
    is tears fewer springs than with the lift-and-circle script over the same time. (Held
    still, the capsule's own weight hanging from the grasp already tears a few around it.)"""
    from physics.deform.cataract import _anterior_capsule, _forceps

    pts, mem, grasp = _anterior_capsule()
    torn = {}
    for name, script in (("still", lambda t: pts[grasp]), ("moving", _forceps(pts[grasp], RHEXIS_STEPS * H))):
        state = mem.initial_state()
        torn[name] = sum(len(mem.step(state, H, script)) for _ in range(RHEXIS_STEPS))
    assert torn["moving"] > torn["still"]
