"""Locations anywhere on a plate model's surface (jassy.surface): gains from the analytic
mode shapes, the {surface = [u, v]} location, the random_on_surface generator and the files."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import chi2_contingency, kstest

import ugens
from jassy import Event, Graph, ModalModel, render
from jassy.errors import JassyError, PatchError
from jassy.generators import expand
from jassy.surface import SurfacePoint

PATCHES = Path(__file__).resolve().parents[1] / "patches"
SHEET = ModalModel.load(PATCHES / "tin_sheet_model.toml")
#: The tin sheet as built (patches.models_surface.tin_sheet_model): a 0.5 x 0.35 m steel
#: panel 0.8 mm thick, simply supported, heard at (0.31, 0.43) of its sides.
A, B, H, RHO, E, NU, PICKUP = 0.5, 0.35, 0.0008, 7850.0, 200e9, 0.3, (0.31, 0.43)


def plate_frequencies(m, n):
    """f_mn = (pi / 2) sqrt(D / (rho h)) ((m / a)^2 + (n / b)^2) (Leissa, isotropic plate)."""
    d = E * H**3 / (12 * (1 - NU**2))
    return math.pi / 2 * math.sqrt(d / (RHO * H)) * ((m / A) ** 2 + (n / B) ** 2)


def analytic(u, v):
    """Gains phi(p) phi(q) / M and driving-point gains phi(p)^2 / (M w) at (u, v), for the
    model's modes in its order (the orders it states, checked against the formula below)."""
    m, n = SHEET.surface.orders_x, SHEET.surface.orders_y
    mass = RHO * H * A * B / 4
    phi = np.sin(math.pi * m * u) * np.sin(math.pi * n * v)
    at_pickup = np.sin(math.pi * m * PICKUP[0]) * np.sin(math.pi * n * PICKUP[1])
    return phi * at_pickup / mass, phi**2 / (mass * 2 * math.pi * plate_frequencies(m, n))


def test_the_tin_sheets_surface_is_the_plate_formula_anywhere():
    # every (m, n) below 16 kHz, once, each at its own frequency
    m, n = np.meshgrid(np.arange(1, 300), np.arange(1, 300), indexing="ij")
    below = plate_frequencies(m, n) < 16000.0
    expected = set(zip(m[below].tolist(), n[below].tolist(), strict=True))
    orders = list(
        zip(
            SHEET.surface.orders_x.astype(int).tolist(),
            SHEET.surface.orders_y.astype(int).tolist(),
            strict=True,
        )
    )
    assert len(orders) == len(set(orders)) == SHEET.n_modes == 1106 and set(orders) == expected
    np.testing.assert_allclose(
        SHEET.frequencies, plate_frequencies(SHEET.surface.orders_x, SHEET.surface.orders_y), rtol=1e-12
    )
    assert SHEET.surface.sides == (A, B)
    rng = np.random.default_rng(1)
    for u, v in rng.uniform(0, 1, (20, 2)):
        gains, driving = analytic(u, v)
        scale = np.abs(gains).max()
        np.testing.assert_allclose(SHEET.gains_at({"surface": [u, v]}), gains, rtol=0, atol=1e-12 * scale)
        np.testing.assert_allclose(SHEET.driving_at(SurfacePoint(u, v)), driving, rtol=1e-12)


def test_the_surface_at_the_named_points_is_their_rows():
    for i in range(4):
        for j in range(3):
            row = SHEET.gains_at(f"x{i}y{j}")
            at = SHEET.gains_at({"surface": [(i + 0.5) / 4, (j + 0.5) / 3]})
            np.testing.assert_allclose(at, row, rtol=0, atol=1e-12 * np.abs(row).max())


def test_random_on_surface_is_uniform_over_the_area():
    table = {"node": "hit", "action": "impact", "times": {"every": 0.001}, "stop": 4.0, "seed": 9,
             "args": {"location": {"random_on_surface": "sheet"}}}  # fmt: skip
    uv = np.array(
        [e["impact"]["location"]["surface"] for _, e in expand([table], {"sheet": SHEET}, None, "p")]
    )
    assert uv.shape == (4000, 2)
    assert kstest(uv[:, 0], "uniform").pvalue > 1e-3 and kstest(uv[:, 1], "uniform").pvalue > 1e-3
    # uniform over the area: equal counts in a 5 x 5 grid of equal cells, u and v independent
    counts = np.histogram2d(uv[:, 0], uv[:, 1], bins=5, range=[[0, 1], [0, 1]])[0]
    assert chi2_contingency(counts).pvalue > 1e-3
    expected = uv.shape[0] / 25
    assert np.sum((counts - expected) ** 2 / expected) < 60  # chi^2 with 24 dof: p ~ 1e-4
    # every drop its own point: no two of the 4000 alike (12 named points would repeat)
    assert np.unique(uv, axis=0).shape[0] == uv.shape[0]


@pytest.mark.timeout(300)  # a cold numba compile on a loaded machine, not a hang
def test_an_impact_at_a_surface_point_rings_with_the_analytic_gains():
    u, v = 0.137, 0.781
    gains, _ = analytic(u, v)
    one_row = ModalModel(SHEET.frequencies, SHEET.decays, gains[None, :])
    outs = []
    for model, location in ((SHEET, {"surface": [u, v]}), (one_row, 0)):
        hit = ugens.ImpactForce(name="hit")
        bank = ugens.ModalBank(model, name="bank")(hit)
        score = [Event(0.01, "hit", "impact", {"location": location, "impulse": 1e-3})]
        outs.append(render(Graph(bank), score, duration=0.2, sample_rate=48000, limiter=False).audio[0])
    assert np.abs(outs[0]).max() > 0
    np.testing.assert_allclose(outs[0], outs[1], rtol=0, atol=1e-9 * np.abs(outs[1]).max())


@pytest.mark.parametrize("suffix", [".toml", ".npz"])
def test_a_model_file_keeps_its_surface(tmp_path, suffix):
    point = SurfacePoint(0.3, 0.6)
    for model in (SHEET, ModalModel.load(PATCHES / "glass_plate_model.toml")):  # with and without pickup
        path = tmp_path / f"{model.name}{suffix}"
        model.truncated(50).save(path)
        back = ModalModel.load(path)
        np.testing.assert_array_equal(back.gains_at(point), model.gains_at(point)[:50])
        np.testing.assert_array_equal(back.driving_at(point), model.driving_at(point)[:50])


def test_surface_errors_are_one_line_naming_the_key():
    plain = ModalModel(np.array([440.0]), np.array([3.0]), np.ones((2, 1)), ("a", "b"), "bar")
    table = {"node": "hit", "action": "impact", "times": {"every": 0.5}, "stop": 1.0,
             "args": {"location": {"random_on_surface": "bar"}}}  # fmt: skip
    with pytest.raises(JassyError, match=r"args\.location\.random_on_surface: model 'bar' has no surface"):
        expand([table], {"bar": plain}, None, "p.toml")
    with pytest.raises(PatchError, match=r"location: model bar has no surface .* use its points \(a, b\)"):
        ugens.ModalBank(plain, name="b", location={"surface": [0.5, 0.5]})
    with pytest.raises(PatchError, match=r"location\.surface: expected \[u, v\], fractions of the sides"):
        ugens.ModalBank(SHEET, name="b", location={"surface": [1.5, 0.5]})


def test_the_glass_plates_surface_gives_driving_point_gains_anywhere():
    """The glass plate's gains are driving-point gains (no pickup): phi^2 / (M w) anywhere,
    from its constants (300 x 200 x 5 mm soda-lime glass, E 70 GPa, nu 0.22, 2500 kg/m^3)."""
    plate = ModalModel.load(PATCHES / "glass_plate_model.toml")
    assert plate.surface.pickup is None
    m, n = plate.surface.orders_x, plate.surface.orders_y
    a, b, h, rho = 0.3, 0.2, 0.005, 2500.0
    d = 70e9 * h**3 / (12 * (1 - 0.22**2))
    f = math.pi / 2 * math.sqrt(d / (rho * h)) * ((m / a) ** 2 + (n / b) ** 2)
    np.testing.assert_allclose(plate.frequencies, f, rtol=1e-12)
    for u, v in ((0.5, 0.5), (0.07, 0.09), (0.23, 0.61)):
        phi = np.sin(math.pi * m * u) * np.sin(math.pi * n * v)
        expected = phi**2 / (rho * h * a * b / 4 * 2 * math.pi * f)
        np.testing.assert_allclose(plate.gains_at({"surface": [u, v]}), expected, rtol=1e-12, atol=1e-30)
        np.testing.assert_allclose(plate.driving_at(SurfacePoint(u, v)), expected, rtol=1e-12, atol=1e-30)
    for name, (u, v) in {"centre": (0.5, 0.5), "corner": (0.07, 0.09)}.items():
        np.testing.assert_allclose(
            plate.gains_at({"surface": [u, v]}), plate.gains_at(name), rtol=1e-12, atol=1e-30
        )
