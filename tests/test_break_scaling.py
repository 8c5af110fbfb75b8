"""Break's SDT energy scaling: each micro-impact's energy and size are scaled by the
share of the energy left (SDT breaking~), and the cascade ends below one crushing energy."""

import numpy as np
import pytest
from scipy import stats

from jassy import Event, Graph, render
from ugens.stochastic import ENERGY_CLIP, ENERGY_LAMBDA, Break

FS = 48000


def cascade(scaling, budget=0.05, crush=1e-3, fragment=0.8, seed=11):
    b = Break(name="b", density=2000.0, crushing_energy=crush, fragment=fragment, mass=1e-3, duration=5e-5,
              seed=seed, scaling=scaling)  # fmt: skip
    b.log_capacity = 100000
    render(
        Graph(b), [Event(0.05, "b", "break", {"energy": budget})], duration=3.0, sample_rate=FS, limiter=False
    )
    return b.event_log()


def test_sdt_scaling_shrinks_events_with_the_energy_left():
    budget, crush, fragment = 0.05, 1e-3, 0.8
    log = cascade("sdt", budget, crush, fragment)
    energies, sizes = log[:, 1], log[:, 2]
    # the share of the energy left before each event: R_0 = 1, R_{k+1} = R_k - e_k / budget
    share = 1.0 - np.concatenate([[0.0], np.cumsum(energies)[:-1]]) / budget
    draws = energies / (crush * share)  # SDT: e_k = E R_k clip(Exp(1.45), 0.1, 10)
    assert np.all(draws >= ENERGY_CLIP[0] - 1e-9) and np.all(draws <= ENERGY_CLIP[1] + 1e-9)
    inner = draws[(draws > ENERGY_CLIP[0]) & (draws < ENERGY_CLIP[1])]
    clipped = stats.truncexpon(b=(ENERGY_CLIP[1] - ENERGY_CLIP[0]) * ENERGY_LAMBDA, loc=ENERGY_CLIP[0],
                               scale=1 / ENERGY_LAMBDA)  # fmt: skip
    assert stats.kstest(inner, clipped.cdf).pvalue > 1e-3
    scaled = sizes / (fragment * share)  # size_k = fragment R_k U(0.5, 1)
    assert np.all((scaled >= 0.5 - 1e-12) & (scaled <= 1.0 + 1e-12))
    assert stats.kstest((scaled - 0.5) * 2, "uniform").pvalue > 1e-3
    # it ends once the energy left is below one crushing energy; the rest is never emitted
    left = budget - energies.sum()
    assert left <= crush < budget * share[-1]
    q = energies.size // 4
    assert energies[-q:].mean() < 0.25 * energies[:q].mean()  # a fading cascade


def test_full_scaling_keeps_full_size_events_and_spends_the_budget():
    budget, crush = 0.05, 1e-3
    sdt, full = cascade("sdt", budget, crush), cascade("full", budget, crush)
    assert full[:, 1].sum() == pytest.approx(budget, rel=1e-12)
    draws = full[:-1, 1] / crush  # unscaled: E clip(Exp(1.45), 0.1, 10)
    assert np.all((draws >= ENERGY_CLIP[0] - 1e-12) & (draws <= ENERGY_CLIP[1] + 1e-12))
    assert np.all((full[:, 2] >= 0.4 - 1e-12) & (full[:, 2] <= 0.8 + 1e-12))  # fragment U(0.5, 1)
    assert sdt[:, 1].sum() < budget and sdt.shape[0] > full.shape[0]
