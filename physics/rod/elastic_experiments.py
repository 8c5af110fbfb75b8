"""Validation experiments of the rod models; each returns a JSON-able dict and optionally
writes a matplotlib PNG (``plot`` path). ``quick`` shrinks sizes for smoke runs.

* cantilever: heavy cantilever tip deflection -y_tip/L against Gamma = rho_A g L^3/EI (the
  master curve), both models at n = 64 (16 if quick), against heavy_elastica (scipy solve_bvp
  of theta'' = Gamma (1 - s) cos theta, theta(0) = 0, theta'(1) = 0) and the linear limit Gamma/8.
* convergence: relative tip error against n at Gamma = 1 and 10 for both models, log-log slope.
* complexity: step time against n (physics.rod.bench.bench_rod).
* vibration: first three flexural frequencies of a clamped-free rod without gravity
  (EI = rho_A = 1) for L = 1 and L = 2 against Euler-Bernoulli (beta L)^2 sqrt(EI/(rho_A L^4)).
* three_point_bending: a rod with natural curvature kappa0 = 0, 0.1, 0.2, 0.3 1/m (L = 10 m,
  an arch bulging upwards, EI = 1, no gravity), pinned at its start and on a frictionless
  roller at its end (the two supports are the rod's ends: contact with support cylinders is not
  modelled), loaded at mid-length by a prescribed downward point force F (dead load, ramped);
  force-displacement curve F L^2/EI against delta/L. Mixed model, n = 64.
"""

from __future__ import annotations

import numpy as np
from scipy.integrate import solve_bvp

from physics.rod.chained import ChainedRod
from physics.rod.mixed import MixedRod
from physics.rod.model import PointLoad, RodModel
from physics.rod.modes import rod_modes
from physics.rod.plotting import save_plot
from physics.rod.statics import solve_static

BETA_L = np.array([1.8751040687, 4.6940911330, 7.8547574382])
"""Roots of 1 + cos(bL) cosh(bL) = 0 (clamped-free Euler-Bernoulli beam)."""

MODELS = {"chained": ChainedRod, "mixed": MixedRod}


def heavy_elastica(gammas, tol: float = 1e-10) -> list[dict]:
    """Heavy cantilever reference by collocation (scipy solve_bvp) with continuation in Gamma
    from small loads (the monotone, physical branch). Per Gamma: deflection -y_tip/L, x_tip/L,
    tip angle (rad), clamp curvature kappa(0) L, and the solution (s, theta, theta')."""
    s = np.linspace(0.0, 1.0, 41)
    y = np.zeros((4, s.size))
    y[2] = s
    out, done = [], 0.0
    for gamma in np.sort(np.asarray(gammas, dtype=np.float64)):
        path = [gamma] if done == 0.0 else np.geomspace(max(done, gamma * 1e-2), gamma, 5)[1:]
        for g in path:
            sol = solve_bvp(
                lambda s, y, g=g: np.vstack((y[1], g * (1 - s) * np.cos(y[0]), np.cos(y[0]), np.sin(y[0]))),
                lambda a, b: np.array([a[0], b[1], a[2], a[3]]),
                s, y, tol=tol, max_nodes=100000,
            )  # fmt: skip
            if not sol.success:
                raise RuntimeError(f"heavy_elastica: solve_bvp failed at Gamma = {g:g}: {sol.message}")
            s, y = sol.x, sol.y
        done = gamma
        out.append({"gamma": float(gamma), "deflection": float(-y[3, -1]), "x_tip": float(y[2, -1]),
                    "tip_angle": float(y[0, -1]), "clamp_curvature": float(y[1, 0]),
                    "s": s.copy(), "theta": y[0].copy(), "dtheta": y[1].copy()})  # fmt: skip
    return out


def cantilever_tip(name: str, n: int, gamma: float, load_steps: int | None = None) -> float:
    """Static -y_tip/L of the heavy cantilever (L = EI = rho_A = 1, g = Gamma) with n elements."""
    form = MODELS[name](RodModel(n=n, length=1.0, EI=1.0, rho_A=1.0, gravity=gamma))
    steps = load_steps or max(1, int(np.ceil(np.log10(max(gamma, 1.0)) * 6)))
    res = solve_static(form, load_steps=steps)
    p, _, _ = form.point_jacobian(res.q, n - 1, form.l[-1])
    return float(-p[1])


def _plot(path, draw) -> None:
    def decorated(ax):
        draw(ax)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend()

    save_plot(path, decorated)


def cantilever(plot: str | None = None, quick: bool = False) -> dict:
    """Master curve: tip deflection vs Gamma for both models against the BVP and Gamma/8."""
    n = 16 if quick else 64
    gammas = np.geomspace(1e-3, 1e3, 7 if quick else 13)
    ref = heavy_elastica(gammas)
    exact = np.array([r["deflection"] for r in ref])
    result = {"n": n, "gamma": gammas.tolist(), "reference": exact.tolist(), "linear": (gammas / 8).tolist()}
    for name in MODELS:
        tips = np.array([cantilever_tip(name, n, g) for g in gammas])
        result[name] = tips.tolist()
        result[f"{name}_max_rel_error"] = float(np.max(np.abs(tips / exact - 1)))
    if plot:

        def draw(ax):
            ax.loglog(gammas, exact, "k-", label="heavy elastica (solve_bvp)")
            ax.loglog(gammas, gammas / 8, "k:", label="linear Gamma/8")
            ax.loglog(gammas, result["chained"], "o", mfc="none", label=f"chained n={n}")
            ax.loglog(gammas, result["mixed"], "x", label=f"mixed n={n}")
            ax.set_ylim(1e-5, 2)
            ax.set_xlabel("Gamma = rho g A L^3 / EI")
            ax.set_ylabel("tip deflection / L")

        _plot(plot, draw)
    return result


def convergence(plot: str | None = None, quick: bool = False) -> dict:
    """Relative tip-deflection error vs n at Gamma = 1 and 10, both models, log-log slopes."""
    ns = [2, 4, 8, 16] if quick else [2, 4, 8, 16, 32, 64]
    result = {"n": ns}
    for gamma, ref in zip((1.0, 10.0), heavy_elastica([1.0, 10.0]), strict=True):
        for name in MODELS:
            err = np.array([abs(cantilever_tip(name, n, gamma) / ref["deflection"] - 1) for n in ns])
            key = f"{name}_gamma{gamma:g}"
            result[key] = err.tolist()
            result[f"{key}_order"] = float(-np.polyfit(np.log(ns), np.log(err), 1)[0])
    if plot:

        def draw(ax):
            for key in (k for k in result if k.endswith(("gamma1", "gamma10"))):
                ax.loglog(ns, result[key], "o-" if key.startswith("chained") else "x--", label=key)
            ax.loglog(ns, 0.3 / np.asarray(ns, float) ** 2, "k:", label="n^-2")
            ax.set_xlabel("elements n")
            ax.set_ylabel("relative tip error")

        _plot(plot, draw)
    return result


def complexity(plot: str | None = None, quick: bool = False) -> dict:
    """Median step time vs n (chained dense vs mixed banded, SuperLU reference)."""
    from physics.rod.bench import bench_rod

    rows = bench_rod(quick=quick)
    result = {"rows": rows}
    if plot:

        def draw(ax):
            for name, style in (("chained", "o-"), ("mixed", "x-"), ("mixed_splu", "s--")):
                sel = [r for r in rows if r["model"] == name and "step_ms" in r]
                ax.loglog([r["n"] for r in sel], [r["step_ms"] for r in sel], style, label=name)
            ax.set_xlabel("elements n")
            ax.set_ylabel("step time (ms)")

        _plot(plot, draw)
    return result


def vibration(plot: str | None = None, quick: bool = False) -> dict:
    """First three flexural frequencies (rad/s) for L = 1 and 2 against Euler-Bernoulli."""
    n = 16 if quick else 32
    result = {"n": n, "beta_L": BETA_L.tolist()}
    for L in (1.0, 2.0):
        exact = BETA_L**2 / L**2
        result[f"L{L:g}_exact"] = exact.tolist()
        for name, cls in MODELS.items():
            omega, _, _ = rod_modes(cls(RodModel(n=n, length=L, EI=1.0, rho_A=1.0, gravity=0.0)), n_modes=3)
            result[f"{name}_L{L:g}"] = omega.tolist()
            result[f"{name}_L{L:g}_rel_error"] = (omega / exact - 1).tolist()
    for name in MODELS:
        result[f"{name}_ratio_L1_over_L2"] = (
            np.array(result[f"{name}_L1"]) / np.array(result[f"{name}_L2"])
        ).tolist()
    if plot:

        def draw(ax):
            for L, mark in ((1.0, "o"), (2.0, "s")):
                ax.semilogy(
                    [1, 2, 3],
                    result[f"L{L:g}_exact"],
                    "k" + mark + ":",
                    mfc="none",
                    label=f"Euler-Bernoulli L={L:g}",
                )
                ax.semilogy([1, 2, 3], result[f"mixed_L{L:g}"], "x", label=f"mixed n={n} L={L:g}")
            ax.set_xlabel("mode")
            ax.set_ylabel("omega (rad/s)")

        _plot(plot, draw)
    return result


def three_point_bending(plot: str | None = None, quick: bool = False) -> dict:
    """Force-displacement curves of curved rods (see module docstring)."""
    L, n = 10.0, 32 if quick else 64
    forces = np.linspace(0.0, 20.0, 6 if quick else 21)  # F L^2 / EI
    result = {"n": n, "length": L, "force_normalised": forces.tolist()}
    for k0 in (0.0, 0.1, 0.2, 0.3):
        start = (0.0, 0.0, k0 * L / 2)
        model = RodModel(n=n, length=L, EI=1.0, rho_A=1.0, gravity=0.0, rest_curvature=-k0, start=start,
                         start_bc="pinned", end_bc="roller")  # fmt: skip
        form = MixedRod(model)
        q = form.initial_state().q
        mid = (n // 2 - 1, float(form.l[0]))
        y0 = form.point_jacobian(q, *mid)[0][1]
        small = solve_static(form, loads=[PointLoad(*mid, (0.0, -1e-4 / L**2))]).q
        stiffness = 1e-4 * L / (y0 - form.point_jacobian(small, *mid)[0][1])
        defl = [0.0]
        for f in forces[1:]:
            res = solve_static(form, q0=q, loads=[PointLoad(*mid, (0.0, -f / L**2))], load_steps=1)
            q = res.q
            defl.append(float((y0 - form.point_jacobian(q, *mid)[0][1]) / L))
        result[f"kappa0_{k0:g}"] = defl
        result[f"kappa0_{k0:g}_initial_stiffness"] = float(stiffness)  # d(F L^2/EI) / d(delta/L) at F = 0
    result["beam_theory_stiffness"] = 48.0
    if plot:

        def draw(ax):
            for k0 in (0.0, 0.1, 0.2, 0.3):
                ax.plot(result[f"kappa0_{k0:g}"], forces, "o-", ms=3, label=f"kappa0 = {k0:g} 1/m")
            ax.plot(forces / 48, forces, "k:", label="F = 48 EI delta / L^3")
            ax.set_xlabel("midpoint deflection delta / L")
            ax.set_ylabel("F L^2 / EI")

        _plot(plot, draw)
    return result


EXPERIMENTS = {
    "cantilever": cantilever,
    "convergence": convergence,
    "complexity": complexity,
    "vibration": vibration,
    "three_point_bending": three_point_bending,
}
