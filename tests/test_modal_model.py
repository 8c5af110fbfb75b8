"""ModalModel: validation, barycentric gains, TOML/NPZ round trips, JASS .sy import."""

import numpy as np
import pytest

from jassy import ModalModel, ModelError, PatchError
from jassy.modal_model import parse_location, t60_to_decay


def model():
    return ModalModel(
        [100.0, 250.0, 700.0],
        [1.0, 2.0, 5.0],
        [[1.0, 0.5, 0.1], [0.0, 1.0, -1.0], [2.0, 2.0, 2.0]],
        ("a", "b", "c"),
        "m",
    )


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(frequencies=[0.0], decays=[1.0], gains=[[1.0]]), r"frequencies\[0\]: expected > 0 Hz"),
        (dict(frequencies=[10.0], decays=[-1.0], gains=[[1.0]]), r"decays\[0\]: expected >= 0"),
        (dict(frequencies=[np.nan], decays=[1.0], gains=[[1.0]]), r"frequencies: expected finite"),
        (dict(frequencies=[10.0, 20.0], decays=[1.0], gains=[[1.0, 1.0]]), r"decays: expected 2 values"),
        (dict(frequencies=[10.0, 20.0], decays=[1.0, 1.0], gains=[[1.0]]), r"gains: expected rows of 2"),
        (dict(frequencies=[], decays=[], gains=[[]]), r"expected at least one mode"),
    ],
)
def test_invalid_models_give_clear_errors(kwargs, match):
    with pytest.raises(ModelError, match=match):
        ModalModel(**kwargs)


def test_nyquist_check_needs_a_sample_rate():
    m = ModalModel([30000.0], [1.0], [[1.0]])
    m.validate()
    with pytest.raises(ModelError, match=r"below Nyquist \(22050 Hz"):
        m.validate(44100)
    assert ModalModel([100.0, 30000.0], [1.0, 1.0], [[1.0, 1.0]]).below(22050).n_modes == 1


def test_barycentric_gains():
    m = model()
    g = m.gains_at({"vertices": ["a", "b", 2], "weights": [0.2, 0.3, 0.5]})
    np.testing.assert_allclose(g, 0.2 * m.gains[0] + 0.3 * m.gains[1] + 0.5 * m.gains[2])
    np.testing.assert_array_equal(m.gains_at("c"), m.gains[2])
    with pytest.raises(PatchError, match="weights: expected non-negative weights summing to 1"):
        parse_location({"vertices": [0, 1], "weights": [0.5, 0.6]}, "loc")
    with pytest.raises(PatchError, match="vertex 3 out of range"):
        m.gains_at(3)


@pytest.mark.parametrize("ext", [".toml", ".npz"])
def test_round_trip(tmp_path, ext):
    m = model()
    path = tmp_path / f"m{ext}"
    m.save(path)
    back = ModalModel.load(path)
    np.testing.assert_array_equal(back.frequencies, m.frequencies)
    np.testing.assert_array_equal(back.decays, m.decays)
    np.testing.assert_array_equal(back.gains, m.gains)
    assert back.points == m.points


def test_jass_sy_import_applies_scales(tmp_path):
    text = "\n".join(
        [
            "nactive_freq:",
            "2",
            "n_freq:",
            "2",
            "n_points:",
            "2",
            "frequency scale:",
            "2.0",
            "damping scale:",
            "0.5",
            "amplitude scale:",
            "10",
            "frequencies:",
            "100",
            "300",
            "dampings:",
            "4",
            "8",
            "amplitudes[point][freq]:",
            "1",
            "0.5",
            "0.25",
            "0.125",
            "END",
        ]
    )
    path = tmp_path / "stick.sy"
    path.write_text(text)
    m = ModalModel.load(path)
    np.testing.assert_allclose(m.frequencies, [200.0, 600.0])
    np.testing.assert_allclose(m.decays, [2.0, 4.0])
    np.testing.assert_allclose(m.gains, [[10.0, 5.0], [2.5, 1.25]])
    path.write_text(text.replace("0.125\n", ""))
    with pytest.raises(ModelError, match=r"stick\.sy: expected 8 numbers for 2 modes x 2 points, got 7"):
        ModalModel.load(path)


def test_unknown_format_and_missing_file(tmp_path):
    with pytest.raises(ModelError, match="no such model file"):
        ModalModel.load(tmp_path / "none.toml")
    (tmp_path / "m.txt").write_text("x")
    with pytest.raises(ModelError, match="unknown model format"):
        ModalModel.load(tmp_path / "m.txt")


def test_t60_conversion():
    d = t60_to_decay(2.0)
    assert np.exp(-d * 2.0) == pytest.approx(1e-3)
