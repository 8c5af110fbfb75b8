"""Shipped surface models: modes to 16 kHz and texture maps dense enough to interpolate.

The truth here is Kirchhoff's simply supported plate written out afresh (Leissa, NASA SP-160,
ch. 4): frequencies from every (m, n) order, mode shapes sin(m pi x / a) sin(n pi y / b)
evaluated at points the model does not store (midpoints between its track points).
"""

import numpy as np
import pytest

from jassy.modal_model import ModalModel
from patches.models_surface import steel_plate_model, wood_board_model

ONE_DB = 1.0 - 10 ** (-1 / 20)  # a 1 dB change, as a fraction of the value


class Plate:
    """Sides a, b (m), thickness h (m), density rho, moduli e1, e2 (Pa), Poisson nu; the
    straight track between two (x/a, y/b) points and the pickup (x/a, y/b)."""

    def __init__(self, a, b, h, rho, e1, e2, nu, track, pickup):
        self.a, self.b, self.h, self.rho, self.track, self.pickup = a, b, h, rho, track, pickup
        self.d1 = e1 * h**3 / (12 * (1 - nu**2))
        self.d2 = e2 * h**3 / (12 * (1 - nu**2))

    def orders(self, f_max):
        """(m, n, f) of every mode below f_max, by frequency."""
        m, n = np.meshgrid(np.arange(1, 400), np.arange(1, 400), indexing="ij")
        km, kn = m.ravel() / self.a, n.ravel() / self.b
        stiff = self.d1 * km**4 + 2 * np.sqrt(self.d1 * self.d2) * km**2 * kn**2 + self.d2 * kn**4
        f = np.pi / 2 * np.sqrt(stiff / (self.rho * self.h))
        assert f[(m.ravel() == 399) | (n.ravel() == 399)].min() > f_max  # no order left out
        keep = np.flatnonzero(f < f_max)
        keep = keep[np.argsort(f[keep], kind="stable")]
        return m.ravel()[keep], n.ravel()[keep], f[keep]

    def gain(self, s, m, n):
        """Strike-to-pickup gains at fraction s along the track (one row per s)."""
        (u0, v0), (u1, v1) = self.track
        u, v = u0 + np.outer(s, 1) * (u1 - u0), v0 + np.outer(s, 1) * (v1 - v0)
        shape = np.sin(np.pi * u * m) * np.sin(np.pi * v * n)
        pu, pv = self.pickup
        listen = np.sin(np.pi * pu * m) * np.sin(np.pi * pv * n)
        return shape * listen / (self.rho * self.h * self.a * self.b / 4)

    def wavelength(self, f):
        """Shortest bending wavelength (m) at f Hz (along the stiffer direction)."""
        d = max(self.d1, self.d2)
        return 2 * np.pi / ((2 * np.pi * f) ** 2 * self.rho * self.h / d) ** 0.25

    def track_length(self):
        (u0, v0), (u1, v1) = self.track
        return np.hypot((u1 - u0) * self.a, (v1 - v0) * self.b)


STEEL = Plate(0.6, 0.45, 0.002, 7850.0, 200e9, 200e9, 0.3, ((0.12, 0.3), (0.88, 0.62)), (0.37, 0.71))
PINE = Plate(0.8, 0.3, 0.018, 450.0, 10e9, 0.8e9, 0.3, ((0.1, 0.5), (0.9, 0.4)), (0.33, 0.62))
CASES = [(steel_plate_model, STEEL, 16000.0), (wood_board_model, PINE, 20000.0)]


def track_order(model: ModalModel) -> list[str]:
    """Point names in order along the track: t0, t0_1, .., t1, ..."""

    def key(name):
        i, _, j = name[1:].partition("_")
        return (int(i), int(j or 0))

    return sorted(model.points, key=key)


@pytest.mark.parametrize(("builder", "plate", "f_max"), CASES, ids=["steel_plate", "wood_board"])
def test_models_hold_every_mode_to_the_top_of_their_range(builder, plate, f_max):
    model = builder()
    m, n, f = plate.orders(f_max)
    assert model.n_modes == f.size
    np.testing.assert_allclose(model.frequencies, f, rtol=1e-12)
    assert model.frequencies.max() > f_max - 200  # the data reach the top of the range


@pytest.mark.parametrize(("builder", "plate", "f_max"), CASES, ids=["steel_plate", "wood_board"])
def test_track_points_resolve_the_shortest_wavelength(builder, plate, f_max):
    model = builder()
    names = track_order(model)
    assert names[0] == "t0" and names[-1] == "t8" and model.points[:9] == tuple(f"t{i}" for i in range(9))
    spacing = plate.track_length() / (len(names) - 1)
    assert spacing <= plate.wavelength(model.frequencies.max()) / 4


@pytest.mark.parametrize(("builder", "plate", "f_max"), CASES, ids=["steel_plate", "wood_board"])
def test_gains_at_midpoints_match_the_mode_shapes_within_1_db(builder, plate, f_max):
    """Below 5 kHz the linearly interpolated gain at the midpoint of every pair of
    neighbouring track points is within 1 dB of the mode shape there: wherever the true
    gain is at least half the mode's largest along the track, as a ratio; everywhere, the
    difference is below a 1 dB change of that largest gain (near a nodal line a ratio
    means nothing)."""
    model = builder()
    m, n, f = plate.orders(f_max)
    low = f < 5000.0
    names = track_order(model)
    s = np.linspace(0.0, 1.0, len(names))
    mid = (s[:-1] + s[1:]) / 2
    truth = plate.gain(mid, m, n)[:, low]
    interpolated = np.array(
        [
            model.gains_at({"vertices": [p, q], "weights": [0.5, 0.5]})
            for p, q in zip(names, names[1:], strict=False)
        ]
    )[:, low]
    stored = plate.gain(s, m, n)[:, low]
    np.testing.assert_allclose(
        np.array([model.gains_at(p) for p in names])[:, low],
        stored,
        rtol=1e-6,
        atol=1e-9 * np.abs(stored).max(),
    )
    peak = np.abs(plate.gain(np.linspace(0, 1, 2001), m, n)[:, low]).max(axis=0)
    assert np.all(np.abs(interpolated - truth) <= ONE_DB * peak)
    strong = np.abs(truth) >= 0.5 * peak
    level = 20 * np.log10(interpolated[strong] / truth[strong])
    assert np.all(np.abs(level) <= 1.0), (level.min(), level.max())
