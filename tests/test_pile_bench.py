"""The penetration measure of the pile benchmark against depths worked out by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest

from physics.rigid.pile_bench import BOX_HALF, SPHERE_RADIUS, pile_depths

IDENTITY = (1.0, 0.0, 0.0, 0.0)


def _depth(positions, quaternions=None, side=1.0):
    pos = np.array(positions, float)
    quat = np.array(quaternions or [IDENTITY] * len(pos), float)
    return pile_depths(pos, quat, side).max()


def test_bodies_clear_of_each_other_and_the_pen_have_no_depth():
    assert _depth([(0, 0, 0.5), (0.3, 0, 0.5)]) == 0.0


def test_a_sphere_and_a_cube_sunk_into_the_floor_and_a_wall():
    assert _depth([(0, 0, SPHERE_RADIUS - 1e-3), (0.5, 0, 0.5)]) == pytest.approx(1e-3)
    assert _depth([(0, 0, 0.5), (0.5, 0, BOX_HALF - 2e-3)]) == pytest.approx(2e-3)
    # a cube turned 45 degrees about x reaches BOX_HALF * sqrt(2) below its centre
    turned = (math.cos(math.pi / 8), math.sin(math.pi / 8), 0.0, 0.0)
    z = BOX_HALF * math.sqrt(2) - 3e-4
    assert _depth([(0, 0, 0.5), (0, 0, z)], [IDENTITY, turned]) == pytest.approx(3e-4)
    assert _depth([(-1.0 + SPHERE_RADIUS - 5e-4, 0, 0.5), (0.5, 0, 0.5)], side=1.0) == pytest.approx(5e-4)


def test_overlapping_pairs():
    assert _depth([(0, 0, 0.5), (0.2, 0.2, 0.5), (2 * SPHERE_RADIUS - 1e-3, 0, 0.5)]) == pytest.approx(1e-3)
    # sphere (even index) against cube (odd index), face on
    assert _depth([(0, 0, 0.5), (SPHERE_RADIUS + BOX_HALF - 7e-4, 0, 0.5)]) == pytest.approx(7e-4)
    # a corner of cube 3 (turned 45 degrees about z, raised 5 mm) 1 mm into cube 1's face
    turned = (math.cos(math.pi / 8), 0.0, 0.0, math.sin(math.pi / 8))
    x = BOX_HALF + BOX_HALF * math.sqrt(2) - 1e-3
    pos = [(0.3, 0.3, 0.5), (0, 0, 0.5), (-0.3, 0.3, 0.5), (x, 0, 0.505)]
    assert _depth(pos, [IDENTITY, IDENTITY, IDENTITY, turned]) == pytest.approx(1e-3)
