"""Modal gains anywhere on a model's surface, from analytic mode shapes.

A model's named points give gains at a few places; a plate built from analytic modes can
give them at every point. A :class:`PlateSurface` holds what that takes for a simply
supported rectangular plate (Leissa, "Vibration of Plates", NASA SP-160, 1969, ch. 4):
each mode's orders (m, n), with phi_mn(x, y) = sin(m pi x / a) sin(n pi y / b), and two
per-mode factors, so that at a point (u, v) = (x / a, y / b) of the plate

    gains a_k(u, v) = pickup_k phi_k(u, v)          pickup_k = phi_k(q) / M_k
    driving-point d_k(u, v) = driving_k phi_k(u, v)^2    driving_k = 1 / (M_k w_k)

(the pickup q and the modal masses M_k as the plate builder used them for the model's
rows). A model whose gains are themselves driving-point gains (heard at the contact, as the
glass plate's) has no pickup: its gains anywhere are d_k(u, v). A location ``{surface =
[u, v]}`` (fractions of the sides, 0..1) names such a point; ``{random_on_surface = MODEL}``
in a ``[[generate]]`` table draws one uniformly over the area (jassy.generators).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from jassy.errors import ModelError, PatchError

#: The kinds of analytic surface a model file may carry (its ``[surface] kind``).
SURFACE_KINDS = ("simply_supported_plate",)
SURFACE_KEYS = ("kind", "sides", "orders_x", "orders_y", "pickup", "driving")


@dataclass(frozen=True)
class SurfacePoint:
    """A point of a model's surface: (u, v) = (x / a, y / b), fractions of the plate's sides."""

    u: float
    v: float


def parse_surface_point(value: Any, where: str) -> SurfacePoint:
    """``[u, v]`` (the value of a ``{surface = [u, v]}`` location) as a SurfacePoint."""
    ok = (
        isinstance(value, (list, tuple))
        and len(value) == 2
        and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in value)
    )
    if not ok or not all(0.0 <= float(x) <= 1.0 for x in value):
        raise PatchError(f"{where}.surface: expected [u, v], fractions of the sides in 0..1, got {value!r}")
    return SurfacePoint(float(value[0]), float(value[1]))


def plate_shapes(
    orders_x: np.ndarray, orders_y: np.ndarray, u: Any, v: Any, pi_last: bool = False
) -> np.ndarray:
    """phi_k(u, v) = sin(m_k pi u) sin(n_k pi v), the mode shapes of a simply supported
    rectangular plate (orders m_k, n_k) at (u, v) = (x / a, y / b): (modes,) for a point given
    by two numbers, (points, modes) for arrays of u and v.

    Each sine's argument is rounded as (pi m) u, or as pi (m u) with ``pi_last``: the two
    differ in the last bits. The runtime surface and the glass plate's model file use the
    first, the files of :func:`patches.models_surface.ss_plate_model` were written with the
    second; the flag stays because no single order reproduces every shipped file's gains."""
    u = np.asarray(u, dtype=np.float64)[..., None]
    v = np.asarray(v, dtype=np.float64)[..., None]
    return np.sin(_sine_argument(orders_x, u, pi_last)) * np.sin(_sine_argument(orders_y, v, pi_last))


def _sine_argument(orders: np.ndarray, x: np.ndarray, pi_last: bool) -> np.ndarray:
    """pi m x, rounded as pi (m x) if ``pi_last`` else as (pi m) x (:func:`plate_shapes`)."""
    return np.pi * (orders * x) if pi_last else np.pi * orders * x


class PlateSurface(NamedTuple):
    """Mode shapes of a simply supported rectangular plate, per mode of its model."""

    sides: tuple[float, float]  #: a, b (m)
    orders_x: np.ndarray  #: m_k, half-waves along a
    orders_y: np.ndarray  #: n_k, half-waves along b
    pickup: np.ndarray | None  #: phi_k(q) / M_k: gains = pickup x phi_k; None: gains = driving
    driving: np.ndarray  #: 1 / (M_k w_k): driving-point gains = driving x phi_k^2 (m per N s)

    def shapes(self, point: SurfacePoint) -> np.ndarray:
        """phi_k(u, v) of every mode."""
        return plate_shapes(self.orders_x, self.orders_y, point.u, point.v)

    def gains(self, point: SurfacePoint) -> np.ndarray:
        if self.pickup is None:
            return self.driving_gains(point)
        return self.pickup * self.shapes(point)

    def driving_gains(self, point: SurfacePoint) -> np.ndarray:
        return self.driving * self.shapes(point) ** 2

    def modes(self, keep: Any) -> PlateSurface:
        """The surface of a model keeping the modes ``keep`` (an index, mask or slice)."""
        pickup = None if self.pickup is None else self.pickup[keep]
        return PlateSurface(self.sides, self.orders_x[keep], self.orders_y[keep], pickup, self.driving[keep])

    def to_dict(self) -> dict[str, Any]:
        """The ``[surface]`` table of a model file (no ``pickup`` key: gains = driving)."""
        table = {
            "kind": SURFACE_KINDS[0],
            "sides": list(self.sides),
            "orders_x": self.orders_x.astype(int).tolist(),
            "orders_y": self.orders_y.astype(int).tolist(),
            "pickup": None if self.pickup is None else self.pickup.tolist(),
            "driving": self.driving.tolist(),
        }
        return {key: value for key, value in table.items() if value is not None}


def surface_from_dict(data: Any, n_modes: int, where: str) -> PlateSurface:
    """A model file's ``[surface]`` table, checked against the model's mode count."""
    if not isinstance(data, dict):
        raise ModelError(f"{where}: surface: expected a table ([surface])")
    data = {key: value for key, value in data.items() if value is not None}
    unknown = set(data) - set(SURFACE_KEYS)
    missing = set(SURFACE_KEYS) - set(data) - {"pickup"}
    if unknown or missing:
        raise ModelError(
            f"{where}: surface: expected the keys {', '.join(SURFACE_KEYS)} (pickup optional)"
            + (f"; unknown {', '.join(sorted(unknown))}" if unknown else "")
            + (f"; missing {', '.join(sorted(missing))}" if missing else "")
        )
    kind = data["kind"]
    if isinstance(kind, np.ndarray):
        kind = kind.item()
    if kind not in SURFACE_KINDS:
        raise ModelError(f"{where}: surface.kind: expected one of {', '.join(SURFACE_KINDS)}, got {kind!r}")
    try:
        sides = np.asarray(data["sides"], dtype=np.float64).reshape(-1)
        arrays = [
            np.asarray(data.get(k, np.zeros(n_modes)), dtype=np.float64).reshape(-1) for k in SURFACE_KEYS[2:]
        ]
    except (TypeError, ValueError):
        raise ModelError(f"{where}: surface: expected numeric sides, orders, pickup and driving") from None
    if sides.shape != (2,) or not np.all(np.isfinite(sides)) or np.any(sides <= 0):
        raise ModelError(f"{where}: surface.sides: expected [a, b] in m, both > 0")
    for key, arr in zip(SURFACE_KEYS[2:], arrays, strict=True):
        if arr.shape != (n_modes,) or not np.all(np.isfinite(arr)):
            raise ModelError(f"{where}: surface.{key}: expected {n_modes} finite values, one per mode")
    orders_x, orders_y, pickup, driving = arrays
    for key, orders in (("orders_x", orders_x), ("orders_y", orders_y)):
        if np.any(orders < 1) or np.any(orders != np.round(orders)):
            raise ModelError(f"{where}: surface.{key}: expected whole numbers of half-waves >= 1")
    if np.any(driving < 0):
        raise ModelError(f"{where}: surface.driving: expected values >= 0 (1 / (M w))")
    pickup = pickup if "pickup" in data else None
    return PlateSurface((float(sides[0]), float(sides[1])), orders_x, orders_y, pickup, driving)
