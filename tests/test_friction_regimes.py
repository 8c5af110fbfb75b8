"""The Friction regime map of examples/friction_regimes.py: the bowed string sounds its
fundamental (Helmholtz motion) in the middle of Schelleng's range, the rubbed wine glass
sings one of its modes at a slow rub and slides silently above the Stribeck speed."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from jassy import ModalModel

ROOT = Path(__file__).resolve().parents[1]
spec = importlib.util.spec_from_file_location("friction_regimes", ROOT / "examples" / "friction_regimes.py")
regimes = importlib.util.module_from_spec(spec)
spec.loader.exec_module(regimes)

GLASS = {"sigma0": 1e7, "static": 0.6, "dynamic": 0.3, "stribeck": 0.05}
STRING = {"sigma0": 1e5, "static": 0.8, "dynamic": 0.2, "stribeck": 0.1}


def test_the_bowed_string_sounds_its_fundamental_at_a_moderate_force_and_speed():
    model = ModalModel.load(ROOT / "patches" / "bowed_string_model.toml")
    peak, level = regimes.regime(model, "normale", 2.0, 0.2, **STRING)
    assert peak == pytest.approx(model.frequencies[0], rel=0.02)
    assert level > -60


def test_the_glass_sings_a_mode_when_rubbed_slowly_and_is_silent_when_rubbed_fast():
    model = ModalModel.load(ROOT / "patches" / "wine_glass_model.toml")
    peak, level = regimes.regime(model, "rim", 2.0, 0.05, **GLASS)
    # one of the glass's modes, raised a little by the stiffness of the sticking contact
    assert np.min(np.abs(model.frequencies / peak - 1)) < 0.01
    assert level > -40
    _, fast = regimes.regime(model, "rim", 2.0, 0.5, **GLASS)
    assert fast < -80
