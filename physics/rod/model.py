"""Rod parameters (RodModel), state (RodState), element poses (Arcs), dead point loads, and the
time-stepping shared by both formulations (chained.ChainedRod, mixed.MixedRod).

A rod of length L (m) is cut into n equal elements of constant curvature. Energies:
bending E_b = 1/2 EI sum_i (kappa_i - kappa0_i)^2 l, gravity V_g = rho_A g int y ds (g along -y).
Boundary conditions at each end: "clamped" (x, y, theta held), "pinned" (x, y held),
"roller" (y held: a frictionless horizontal support) or "free". The start is held at
``start``; the end at ``end`` if given, else at the end pose of the rest shape (rod started at
``start`` with its rest curvature). "roller" and ``end`` are this package's additions to the
super-circle model (Bertails et al., "Super-Helices", SIGGRAPH 2006).

One linearly implicit (semi-implicit Euler) step for the next velocity v+:
(M + h D + h^2 K) v+ = M v + h (-grad V + f_gyro) with bilateral constraints C v+ = -g(q)/h
(the constraint violation is removed in one step), then q+ = q + h v+.
K is the stiffness with the destabilising part of the gravity Hessian dropped (K >= 0, so A is
SPD); f_gyro = -rho_A int J^T (dJ/dt v) ds are the velocity-quadratic inertial forces. When the
state carries the previous step's constraint impulses lam, A also gets the PSD part of the
constraints' geometric stiffness h^2 (lam/h) . d2g (the tension of a hanging mixed rod; without
it, large steps of the mixed model are unstable). ``step`` stores lam; ``advance`` accepts it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from jassy.errors import JassyError
from physics.rod import arc

BC_ROWS = {"clamped": (0, 1, 2), "pinned": (0, 1), "roller": (1,), "free": ()}
"""Held components of the end pose (x, y, theta) for each boundary condition."""


@dataclass(frozen=True)
class RodModel:
    """An inextensible planar rod: n elements, length (m), EI (N m^2), rho_A (kg/m), contact
    radius (m), rest curvature per element (1/m), gravity (m/s^2 along -y), start pose
    (x m, y m, theta rad), boundary conditions, viscous bending damping (N m^2 s: moment
    damping * kappa_dot), optional held end pose (x, y, theta)."""

    n: int
    length: float
    EI: float
    rho_A: float
    radius: float = 0.0
    rest_curvature: float | np.ndarray = 0.0
    gravity: float = 9.81
    start: tuple[float, float, float] = (0.0, 0.0, 0.0)
    start_bc: str = "clamped"
    end_bc: str = "free"
    damping: float = 0.0
    end: tuple[float, float, float] | None = None

    def __post_init__(self):
        if isinstance(self.n, bool) or not isinstance(self.n, (int, np.integer)) or self.n < 1:
            raise JassyError(f"RodModel.n: expected an integer >= 1 (elements), got {self.n!r}")
        for name, positive in (("length", True), ("EI", True), ("rho_A", True), ("radius", False),
                               ("damping", False)):  # fmt: skip
            v = getattr(self, name)
            ok = (
                isinstance(v, (int, float, np.floating))
                and math.isfinite(v)
                and (v > 0 or not positive and v >= 0)
            )
            if not ok:
                raise JassyError(
                    f"RodModel.{name}: expected a finite number {'> 0' if positive else '>= 0'}, got {v!r}"
                )
        if not math.isfinite(self.gravity):
            raise JassyError(f"RodModel.gravity: expected a finite number (m/s^2), got {self.gravity!r}")
        k0 = np.asarray(self.rest_curvature, dtype=np.float64)
        if k0.ndim > 1 or (k0.ndim == 1 and k0.size != self.n) or not np.all(np.isfinite(k0)):
            raise JassyError(
                f"RodModel.rest_curvature: expected a finite number or {self.n} values (1/m), "
                f"got {self.rest_curvature!r}"
            )
        for name in ("start_bc", "end_bc"):
            if getattr(self, name) not in BC_ROWS:
                raise JassyError(
                    f"RodModel.{name}: expected one of {sorted(BC_ROWS)}, got {getattr(self, name)!r}"
                )
        for name in ("start", "end"):
            pose = getattr(self, name)
            if pose is not None and (len(pose) != 3 or not all(math.isfinite(float(p)) for p in pose)):
                raise JassyError(f"RodModel.{name}: expected a finite pose (x, y, theta), got {pose!r}")

    @property
    def l(self) -> np.ndarray:  # noqa: E743
        """Element lengths (m), shape (n,)."""
        return np.full(self.n, self.length / self.n)

    @property
    def kappa0(self) -> np.ndarray:
        """Rest curvature per element (1/m), shape (n,)."""
        return np.broadcast_to(np.asarray(self.rest_curvature, dtype=np.float64), (self.n,)).copy()

    @property
    def end_target(self) -> np.ndarray:
        """Pose (x, y, theta) at which the end is held (``end`` or the rest shape's end)."""
        if self.end is not None:
            return np.asarray(self.end, dtype=np.float64)
        r, th = arc.forward_kinematics(*self.start, self.kappa0, self.l)
        return np.array([r[-1].real, r[-1].imag, th[-1]])


@dataclass
class RodState:
    """Generalised coordinates q and velocities v (layout set by the formulation); lam: the
    constraint impulses (N s) of the step that produced this state, if known (used for the
    geometric stiffness of the constraints in the next step)."""

    q: np.ndarray
    v: np.ndarray
    lam: np.ndarray | None = None


@dataclass(frozen=True)
class Arcs:
    """Start pose (x, y m; theta rad), curvature kappa (1/m) and length l (m) of each element."""

    x: np.ndarray
    y: np.ndarray
    theta: np.ndarray
    kappa: np.ndarray
    l: np.ndarray  # noqa: E741


@dataclass(frozen=True)
class PointLoad:
    """A dead force (fx, fy) in N at arc length s (m) of an element."""

    element: int
    s: float
    force: tuple[float, float]


@dataclass
class Dynamics:
    """Terms of one step at (q, v): mass M, damping D, stiffness K (PSD part), grad V, f_gyro."""

    M: object
    D: object
    K: object
    grad: np.ndarray
    gyro: np.ndarray
    extra: dict = field(default_factory=dict)


class FormulationBase:
    """Shared time stepping; subclasses provide dynamics(), constraints(), kkt_factor(), project()."""

    model: RodModel
    ndof: int

    def check_step(self, h: float) -> None:
        if not (isinstance(h, (int, float, np.floating)) and math.isfinite(h) and h > 0):
            raise JassyError(f"h: expected a time step > 0 s, got {h!r}")

    def linear_system(self, state: RodState, h: float) -> tuple:
        """(A, b, C, c): A v+ + C^T lam = b, C v+ = c for one linearly implicit step."""
        self.check_step(h)
        d = self.dynamics(state.q, state.v)
        A = d.M + h * d.D + (h * h) * d.K
        C, g = self.constraints(state.q)
        if state.lam is not None and state.lam.shape == g.shape:
            # geometric stiffness of the constraints, forces lam / h of the previous step
            A = A + h * self.constraint_hessian(state.q, state.lam, psd=True)
        b = d.M @ state.v + h * (d.gyro - d.grad)
        return A, b, C, -g / h

    def advance(
        self, state: RodState, v_next: np.ndarray, h: float, lam: np.ndarray | None = None
    ) -> RodState:
        """q+ = q + h v+, projected on the gluing constraints (mixed); v+ kept; lam (the step's
        constraint impulses, optional) is stored for the next step's geometric stiffness."""
        v_next = np.asarray(v_next, dtype=np.float64)
        if v_next.shape != (self.ndof,) or not np.all(np.isfinite(v_next)):
            raise JassyError(f"v_next: expected {self.ndof} finite velocities, got shape {v_next.shape}")
        lam = None if lam is None else np.array(lam, dtype=np.float64)
        return RodState(self.project(state.q + h * v_next), v_next.copy(), lam)

    def step(self, state: RodState, h: float) -> RodState:
        """One contact-free step (KKT solve of linear_system)."""
        A, b, C, c = self.linear_system(state, h)
        v, lam = self.kkt_factor(A, C).solve(b, c)
        return self.advance(state, v, h, lam)

    def energy(self, state: RodState) -> float:
        """Kinetic + bending + gravity energy (J)."""
        d = self.dynamics(state.q, state.v)
        return float(0.5 * state.v @ (d.M @ state.v) + self.potential(state.q)[0])

    def load_terms(self, q: np.ndarray, loads) -> tuple[float, np.ndarray, list]:
        """Potential -F.r, its gradient and Hessian blocks [(cols, H)] for dead point loads."""
        V, grad, blocks = 0.0, np.zeros(self.ndof), []
        for load in loads:
            f = np.asarray(load.force, dtype=np.float64)
            p, cols, J = self.point_jacobian(q, load.element, load.s)
            V -= float(f @ p)
            grad[cols] -= f @ J
            hcols, H = self.point_hessian(q, load.element, load.s)
            blocks.append((hcols, -(f[0] * H[0] + f[1] * H[1])))
        return V, grad, blocks

    def point_jacobians(self, q, elements: np.ndarray, s: np.ndarray):
        """point_jacobian at each (element, s): (points (m, 2), cols (m, k), J (m, 2, k)); narrower
        rows are padded with zero columns (repeating their first index)."""
        out = [self.point_jacobian(q, int(e), float(si)) for e, si in zip(elements, s, strict=True)]
        k = max((len(c) for _, c, _ in out), default=0)
        cols = np.zeros((len(out), k), dtype=np.int64)
        J = np.zeros((len(out), 2, k))
        for m, (_, c, Jm) in enumerate(out):
            cols[m] = c[0]
            cols[m, : len(c)] = c
            J[m, :, : len(c)] = Jm
        return np.array([p for p, _, _ in out]).reshape(-1, 2), cols, J

    def check_point(self, element: int, s: float) -> None:
        n, le = self.model.n, self.model.length / self.model.n
        if isinstance(element, bool) or not isinstance(element, (int, np.integer)) or not 0 <= element < n:
            raise JassyError(f"element: expected an integer in [0, {n - 1}], got {element!r}")
        if not (math.isfinite(s) and -1e-12 * le <= s <= le * (1 + 1e-12)):
            raise JassyError(f"s: expected an arc length in [0, {le:g}] m, got {s!r}")


def sparse_from_blocks(blocks: np.ndarray) -> sp.bsr_matrix:
    """Block-diagonal sparse matrix from (n, b, b) blocks."""
    n, b, _ = blocks.shape
    return sp.bsr_matrix((blocks, np.arange(n), np.arange(n + 1)), shape=(n * b, n * b))
