"""Rod validation: heavy cantilever against an independent BVP solution and Gamma/8, O(n^-2)
convergence, Euler-Bernoulli flexural frequencies and L^-2 scaling, modal gains, three-point
bending against beam theory, and the experiment functions' output."""

import json

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from physics.rod.chained import ChainedRod
from physics.rod.elastic_experiments import BETA_L, EXPERIMENTS, cantilever_tip, heavy_elastica
from physics.rod.mixed import MixedRod
from physics.rod.model import PointLoad, RodModel
from physics.rod.modes import modal_model, rod_modes
from physics.rod.statics import solve_static

GAMMAS = [1e-3, 1.0, 10.0, 100.0, 1000.0]


@pytest.fixture(scope="module")
def reference():
    return {r["gamma"]: r for r in heavy_elastica(GAMMAS)}


def test_bvp_reference_against_shooting_and_linear_limit(reference):
    for g, r in reference.items():
        if g > 100:  # shooting is too ill-conditioned there
            continue
        # independent check: integrate the IVP from the BVP's clamp curvature (DOP853)
        y0 = [0.0, r["clamp_curvature"], 0.0, 0.0]
        rhs = lambda s, y, g=g: [y[1], g * (1 - s) * np.cos(y[0]), np.cos(y[0]), np.sin(y[0])]  # noqa: E731
        sol = solve_ivp(rhs, (0, 1), y0, method="DOP853", rtol=1e-12, atol=1e-13)
        assert abs(sol.y[1, -1]) < 1e-6 * max(1.0, abs(r["clamp_curvature"]))  # free end: theta'(1) = 0
        assert -sol.y[3, -1] == pytest.approx(r["deflection"], rel=1e-7)
        assert np.all(np.diff(r["theta"]) <= 1e-12)  # monotone, physical branch
    assert reference[1e-3]["deflection"] == pytest.approx(1e-3 / 8, rel=1e-5)
    assert reference[1e-3]["clamp_curvature"] == pytest.approx(-1e-3 / 2, rel=1e-5)
    assert reference[1000.0]["tip_angle"] == pytest.approx(-np.pi / 2, abs=1e-3)


@pytest.mark.parametrize("name", ["chained", "mixed"])
def test_cantilever_matches_heavy_elastica_at_n64(reference, name):
    for g in GAMMAS:
        tip = cantilever_tip(name, 64, g)
        assert tip == pytest.approx(reference[g]["deflection"], rel=1e-3)
    assert cantilever_tip(name, 64, 1e-3) == pytest.approx(1e-3 / 8, rel=1e-3)


def test_cantilever_converges_at_second_order(reference):
    ns = np.array([4, 8, 16, 32])
    for g in (1.0, 10.0):
        for name in ("chained", "mixed"):
            err = np.array([abs(cantilever_tip(name, n, g) / reference[g]["deflection"] - 1) for n in ns])
            order = -np.polyfit(np.log(ns), np.log(err), 1)[0]
            assert order > 1.9, (name, g, err)


@pytest.mark.parametrize("cls", [ChainedRod, MixedRod])
def test_flexural_frequencies_match_euler_bernoulli_and_scale_with_L(cls):
    omegas = {}
    for L in (1.0, 2.0):
        omega, _, _ = rod_modes(cls(RodModel(n=32, length=L, EI=1.0, rho_A=1.0, gravity=0.0)), n_modes=3)
        exact = BETA_L**2 / L**2
        assert np.all(np.abs(omega / exact - 1) < 0.01)
        assert np.all(omega >= exact * (1 - 1e-9))  # discrete frequencies approach from above
        omegas[L] = omega
    assert np.allclose(omegas[1.0] / omegas[2.0], 4.0, rtol=1e-8)


def test_frequencies_converge_at_second_order():
    errs = []
    for n in (8, 16, 32):
        omega, _, _ = rod_modes(
            MixedRod(RodModel(n=n, length=1.0, EI=1.0, rho_A=1.0, gravity=0.0)), n_modes=2
        )
        errs.append(omega / BETA_L[:2] ** 2 - 1)
    errs = np.array(errs)
    assert np.all(errs[1] / errs[2] > 3.5) and np.all(errs[0] / errs[1] > 3.5)


def test_modal_model_tip_gains_follow_the_beam_mode_shape():
    """Euler-Bernoulli cantilever modes normalised to int phi^2 = L have |phi(L)| = 2, so with
    mass-normalised modes the tip gain is 4 / (rho_A L omega_k)."""
    rho_a, L = 0.5, 1.5
    model = RodModel(n=32, length=L, EI=2.0, rho_A=rho_a, gravity=0.0)
    mm = modal_model(ChainedRod(model), [L, 0.0], n_modes=3, d0=1.0, loss=1e-3, beta=1e-5)
    omega = 2 * np.pi * mm.frequencies
    assert np.allclose(mm.gains[0], 4.0 / (rho_a * L * omega), rtol=0.02)
    assert np.allclose(mm.gains[1], 0.0, atol=1e-12)  # clamped point does not move
    assert np.allclose(mm.decays, 1.0 + np.pi * 1e-3 * mm.frequencies + 0.5e-5 * omega**2)
    assert mm.points == ("s=1.5", "s=0")
    mixed = modal_model(MixedRod(model), [L, 0.0], n_modes=3, d0=1.0, loss=1e-3, beta=1e-5)
    assert np.allclose(mixed.gains, mm.gains, rtol=1e-6, atol=1e-14)


def test_three_point_bending_small_load_matches_beam_theory():
    """Straight rod, pinned + roller, central load: F = 48 EI delta / L^3 for small loads."""
    n, L, EI, F = 32, 2.0, 3.0, 1e-4
    form = MixedRod(
        RodModel(n=n, length=L, EI=EI, rho_A=1.0, gravity=0.0, start_bc="pinned", end_bc="roller")
    )
    res = solve_static(form, loads=[PointLoad(n // 2 - 1, L / n, (0.0, -F))])
    delta = -form.point_jacobian(res.q, n // 2 - 1, L / n)[0][1]
    assert F / delta == pytest.approx(48 * EI / L**3, rel=2e-3)


def test_experiments_return_json_and_write_plots(tmp_path):
    assert set(EXPERIMENTS) == {"cantilever", "convergence", "complexity", "vibration", "three_point_bending"}
    for name in ("vibration", "three_point_bending"):
        png = tmp_path / f"{name}.png"
        out = EXPERIMENTS[name](plot=str(png), quick=True)
        json.dumps(out)
        assert png.stat().st_size > 1000
    tpb = EXPERIMENTS["three_point_bending"](quick=True)
    assert tpb["kappa0_0_initial_stiffness"] == pytest.approx(48.0, rel=0.01)
    assert all(np.all(np.diff(tpb[f"kappa0_{k:g}"]) > 0) for k in (0.0, 0.1, 0.2, 0.3))
