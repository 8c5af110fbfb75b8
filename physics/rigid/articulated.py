"""Articulated chains: Featherstone's ABA (O(n)), with CRBA + RNEA as the dense reference.

Spatial vectors are 6-vectors, angular part first, in each link's own frame (Featherstone's
Plucker convention; Pai, Ascher & Kry's phi = (omega; v)). Motion transforms X (6x6) map a
parent-frame motion vector into the child frame; forces map back with X^T.

Model (``Chain``, immutable): link i hangs from link parent[i] (< i; -1 = fixed base) through
a 1-dof joint: revolute (rotation q about ``axis``, rad) or prismatic (translation q along
``axis``, m). The joint frame sits at ``joint_pos[i]`` (m) with orientation ``joint_rot[i]``
in the parent link frame (x_parent = R x_joint + p) and coincides with link i's frame at
q = 0. Link i has mass (kg), centre of mass ``com`` (m, link frame) and rotational inertia
about the COM ``inertia`` (kg m^2, link axes). ``gravity`` (m/s^2) is in base coordinates.

Passes (RBDA ch. 5-7; the ABA is the leaves-to-root sparse elimination of Pai et al.'s
augmented system, see the reference page A2):
``aba`` O(n) forward dynamics; ``crba`` joint-space mass matrix H (O(n^2) fill);
``rnea`` inverse dynamics; forward dynamics by the dense route is solve(H, tau - rnea(q, qd, 0)).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numba
import numpy as np
from scipy.linalg import cho_factor, cho_solve

from jassy.errors import JassyError
from jassy.jit import drop_stale_cache, specialise
from physics.rigid import aba as aba_kernels
from physics.rigid.aba import (
    ABA_BAD_FEXT,
    ABA_BAD_Q,
    ABA_BAD_QD,
    ABA_BAD_TAU,
    ABA_OK,
    PRISMATIC,
    REVOLUTE,
    ChainModel,
    aba_checked,
    aba_data_size,
    aba_into,
    new_aba_data,
)

drop_stale_cache(__file__, [aba_kernels])  # its cache holds copies of aba's kernels


@numba.njit(cache=True)
def _skew(a):
    return np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])


@numba.njit(cache=True)
def _rot(axis, angle):
    """Rotation matrix by ``angle`` about unit ``axis`` (Rodrigues)."""
    k = _skew(axis)
    return np.eye(3) + np.sin(angle) * k + (1.0 - np.cos(angle)) * (k @ k)


@numba.njit(cache=True)
def _plucker(R, p):
    """Motion transform parent -> child for a child frame at (R, p) in the parent:
    [[E, 0], [-E p^, E]] with E = R^T."""
    X = np.zeros((6, 6))
    for i in range(3):
        for j in range(3):
            X[i, j] = R[j, i]
            X[3 + i, 3 + j] = R[j, i]
    P = _skew(p)
    for i in range(3):
        for j in range(3):
            X[3 + i, j] = -(R[0, i] * P[0, j] + R[1, i] * P[1, j] + R[2, i] * P[2, j])
    return X


@numba.njit(cache=True)
def _mv(A, x):
    y = np.zeros(6)
    for i in range(6):
        for j in range(6):
            y[i] += A[i, j] * x[j]
    return y


@numba.njit(cache=True)
def _mtv_into(A, x, y):
    """y = A^T x (6x6), in place."""
    for i in range(6):
        y[i] = 0.0
    for j in range(6):
        for i in range(6):
            y[i] += A[j, i] * x[j]


@numba.njit(cache=True)
def _mtv(A, x):
    y = np.empty(6)
    _mtv_into(A, x, y)
    return y


@numba.njit(cache=True)
def _add_xtax(out, X, A):
    """out += X^T A X (6x6)."""
    T = np.zeros((6, 6))
    for i in range(6):
        for k in range(6):
            aik = A[i, k]
            for j in range(6):
                T[i, j] += aik * X[k, j]
    for i in range(6):
        for k in range(6):
            xki = X[k, i]
            for j in range(6):
                out[i, j] += xki * T[k, j]


@numba.njit(cache=True)
def _cross3(a0, a1, a2, b0, b1, b2):
    return a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0


@numba.njit(cache=True)
def _crm_mv(v, m):
    """Spatial motion cross product v x m = (w x m_w, w x m_v + v_o x m_w)."""
    y = np.empty(6)
    y[0], y[1], y[2] = _cross3(v[0], v[1], v[2], m[0], m[1], m[2])
    a = _cross3(v[0], v[1], v[2], m[3], m[4], m[5])
    b = _cross3(v[3], v[4], v[5], m[0], m[1], m[2])
    y[3], y[4], y[5] = a[0] + b[0], a[1] + b[1], a[2] + b[2]
    return y


@numba.njit(cache=True)
def _crf_mv(v, f):
    """Spatial force cross product v x* f = (w x f_n + v_o x f_f, w x f_f)."""
    y = np.empty(6)
    a = _cross3(v[0], v[1], v[2], f[0], f[1], f[2])
    b = _cross3(v[3], v[4], v[5], f[3], f[4], f[5])
    y[0], y[1], y[2] = a[0] + b[0], a[1] + b[1], a[2] + b[2]
    y[3], y[4], y[5] = _cross3(v[0], v[1], v[2], f[3], f[4], f[5])
    return y


@numba.njit(cache=True)
def _kinematics(jtype, axis, xtree, q):
    """Xup[i] (parent -> link i at q) and motion subspaces S[i] (link frame)."""
    n = q.size
    Xup = np.zeros((n, 6, 6))
    S = np.zeros((n, 6))
    for i in range(n):
        if jtype[i] == REVOLUTE:
            XJ = _plucker(_rot(axis[i], q[i]), np.zeros(3))
            S[i, :3] = axis[i]
        else:
            XJ = _plucker(np.eye(3), q[i] * axis[i])
            S[i, 3:] = axis[i]
        for r in range(6):
            for k in range(6):
                xrk = XJ[r, k]
                if xrk != 0.0:
                    for c in range(6):
                        Xup[i, r, c] += xrk * xtree[i, k, c]
    return Xup, S


@numba.njit(cache=True)
def _velocities(parent, Xup, S, qd):
    n = qd.size
    v = np.zeros((n, 6))
    c = np.zeros((n, 6))
    for i in range(n):
        vj = S[i] * qd[i]
        v[i] = vj if parent[i] < 0 else _mv(Xup[i], v[parent[i]]) + vj
        c[i] = _crm_mv(v[i], vj)
    return v, c


@numba.njit(cache=True)
def _rnea(parent, jtype, axis, xtree, inertia, a0, q, qd, qdd, fext):
    n = q.size
    Xup, S = _kinematics(jtype, axis, xtree, q)
    v, c = _velocities(parent, Xup, S, qd)
    a = np.empty((n, 6))
    f = np.empty((n, 6))
    for i in range(n):
        a[i] = _mv(Xup[i], a0 if parent[i] < 0 else a[parent[i]]) + S[i] * qdd[i] + c[i]
        f[i] = _mv(inertia[i], a[i]) + _crf_mv(v[i], _mv(inertia[i], v[i])) - fext[i]
    tau = np.empty(n)
    for i in range(n - 1, -1, -1):
        tau[i] = S[i] @ f[i]
        if parent[i] >= 0:
            f[parent[i]] += _mtv(Xup[i], f[i])
    return tau


@numba.njit(cache=True)
def _crba(parent, jtype, axis, xtree, inertia, q):
    n = q.size
    Xup, S = _kinematics(jtype, axis, xtree, q)
    IC = inertia.copy()
    for i in range(n - 1, -1, -1):
        if parent[i] >= 0:
            _add_xtax(IC[parent[i]], Xup[i], IC[i])
    H = np.zeros((n, n))
    G = np.empty(6)
    for i in range(n):
        F = _mv(IC[i], S[i])
        H[i, i] = S[i] @ F
        j = i
        while parent[j] >= 0:
            _mtv_into(Xup[j], F, G)
            F, G = G, F
            j = parent[j]
            H[i, j] = F @ S[j]
            H[j, i] = H[i, j]
    return H


@numba.njit(cache=True)
def _poses(parent, jtype, axis, jrot, jpos, q):
    """World (base) rotation and origin of every link frame."""
    n = q.size
    R = np.empty((n, 3, 3))
    p = np.empty((n, 3))
    for i in range(n):
        if jtype[i] == REVOLUTE:
            Rl, pl = jrot[i] @ _rot(axis[i], q[i]), jpos[i].copy()
        else:
            Rl, pl = jrot[i].copy(), jpos[i] + jrot[i] @ (q[i] * axis[i])
        if parent[i] < 0:
            R[i], p[i] = Rl, pl
        else:
            R[i] = R[parent[i]] @ Rl
            p[i] = p[parent[i]] + R[parent[i]] @ pl
    return R, p


@numba.njit(cache=True)
def _simulate(m, d, q0, qd0, tau, h, steps, rk4):
    n = q0.size
    fext = np.zeros((n, 6))
    Q = np.empty((steps + 1, n))
    QD = np.empty((steps + 1, n))
    Q[0], QD[0] = q0, qd0
    q, qd = q0.copy(), qd0.copy()
    for s in range(steps):
        if rk4:
            k1q = qd
            aba_into(m, d, q, qd, tau, fext)
            k1v = d.qdd.copy()
            q2, v2 = q + 0.5 * h * k1q, qd + 0.5 * h * k1v
            aba_into(m, d, q2, v2, tau, fext)
            k2v = d.qdd.copy()
            q3, v3 = q + 0.5 * h * v2, qd + 0.5 * h * k2v
            aba_into(m, d, q3, v3, tau, fext)
            k3v = d.qdd.copy()
            q4, v4 = q + h * v3, qd + h * k3v
            aba_into(m, d, q4, v4, tau, fext)
            q = q + (h / 6.0) * (k1q + 2.0 * v2 + 2.0 * v3 + v4)
            qd = qd + (h / 6.0) * (k1v + 2.0 * k2v + 2.0 * k3v + d.qdd)
        else:  # semi-implicit (symplectic) Euler
            aba_into(m, d, q, qd, tau, fext)
            qd = qd + h * d.qdd
            q = q + h * qd
        Q[s + 1], QD[s + 1] = q, qd
    return Q, QD


def _spatial_inertia(m, c, Ic):
    """6x6 spatial inertia about the link origin: [[Ic + m c^ c^T, m c^], [m c^T, m 1]]."""
    C = np.array([[0.0, -c[2], c[1]], [c[2], 0.0, -c[0]], [-c[1], c[0], 0.0]])
    top = np.hstack([Ic + m * C @ C.T, m * C])
    return np.vstack([top, np.hstack([m * C.T, m * np.eye(3)])])


@dataclass(frozen=True, eq=False)
class Chain:
    """Kinematic tree of 1-dof joints (see module doc). Arrays: parent (n,) int,
    joint_type (n,) int (REVOLUTE = 0, PRISMATIC = 1), axis (n, 3) unit (normalised here),
    joint_rot (n, 3, 3), joint_pos (n, 3) m, mass (n,) kg, com (n, 3) m, inertia (n, 3, 3)
    kg m^2 about the COM, gravity (3,) m/s^2."""

    parent: np.ndarray
    joint_type: np.ndarray
    axis: np.ndarray
    joint_rot: np.ndarray
    joint_pos: np.ndarray
    mass: np.ndarray
    com: np.ndarray
    inertia: np.ndarray
    gravity: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, -9.81]))
    xtree: np.ndarray = field(init=False, repr=False)
    spatial_inertia: np.ndarray = field(init=False, repr=False)
    model: ChainModel = field(init=False, repr=False)
    _scratch: np.ndarray = field(init=False, repr=False)
    _no_force: np.ndarray = field(init=False, repr=False)
    _aba_entry: object = field(init=False, repr=False, default=None)

    def __post_init__(self):
        parent = np.asarray(self.parent, dtype=np.int64).ravel()
        n = parent.size
        if n == 0 or np.any(parent >= np.arange(n)) or np.any(parent < -1):
            raise JassyError("parent: expected n > 0 indices with -1 <= parent[i] < i")
        jt = np.asarray(self.joint_type, dtype=np.int64).ravel()
        if jt.shape != (n,) or not np.all((jt == REVOLUTE) | (jt == PRISMATIC)):
            raise JassyError("joint_type: expected (n,) of REVOLUTE (0) or PRISMATIC (1)")
        shapes = {"axis": (n, 3), "joint_rot": (n, 3, 3), "joint_pos": (n, 3), "mass": (n,), "com": (n, 3)}
        arrs = {}
        for name, shp in {**shapes, "inertia": (n, 3, 3), "gravity": (3,)}.items():
            a = np.array(getattr(self, name), dtype=np.float64)
            if a.shape != shp or not np.all(np.isfinite(a)):
                raise JassyError(f"{name}: expected finite array of shape {shp}, got {a.shape}")
            arrs[name] = a
        norms = np.linalg.norm(arrs["axis"], axis=1)
        if np.any(norms == 0):
            raise JassyError("axis: joint axes must be non-zero")
        arrs["axis"] /= norms[:, None]
        R = arrs["joint_rot"]
        if not np.allclose(R @ R.transpose(0, 2, 1), np.eye(3), atol=1e-9) or np.any(np.linalg.det(R) < 0):
            raise JassyError("joint_rot: expected proper rotation matrices")
        Ic = arrs["inertia"]
        if np.any(arrs["mass"] <= 0) or not np.allclose(Ic, Ic.transpose(0, 2, 1)):
            raise JassyError("mass, inertia: expected mass > 0 and symmetric inertia tensors")
        if np.any(np.linalg.eigvalsh(Ic) < -1e-12 * max(1.0, np.abs(Ic).max())):
            raise JassyError("inertia: expected positive semi-definite inertia tensors")
        for name, a in arrs.items():
            a.setflags(write=False)
            object.__setattr__(self, name, a)
        for name, a in (("parent", parent), ("joint_type", jt)):
            a.setflags(write=False)
            object.__setattr__(self, name, a)
        xtree = np.array([_plucker(R[i], arrs["joint_pos"][i]) for i in range(n)])
        sI = np.array([_spatial_inertia(arrs["mass"][i], arrs["com"][i], Ic[i]) for i in range(n)])
        object.__setattr__(self, "xtree", xtree)
        object.__setattr__(self, "spatial_inertia", sI)
        S = np.zeros((n, 6))
        S[jt == REVOLUTE, :3] = arrs["axis"][jt == REVOLUTE]
        S[jt == PRISMATIC, 3:] = arrs["axis"][jt == PRISMATIC]
        a0 = np.concatenate([np.zeros(3), -arrs["gravity"]])  # base acceleration -g (fictitious)
        model = ChainModel(parent, jt, arrs["axis"], R, arrs["joint_pos"], sI, S, a0)
        object.__setattr__(self, "model", model)
        # scratch of the public ``aba``: numba kernels hold the GIL, so one call runs at a time
        object.__setattr__(self, "_scratch", np.zeros(aba_data_size(n)))
        object.__setattr__(self, "_no_force", np.zeros((n, 6)))  # f_ext = 0, never written

    @property
    def n(self) -> int:
        return self.parent.size

    def _args(self):
        a0 = np.concatenate([np.zeros(3), -self.gravity])  # base acceleration -g (fictitious)
        return self.parent, self.joint_type, self.axis, self.xtree, self.spatial_inertia, a0


def pendulum_chain(
    n: int, length: float = 1.0, mass: float = 1.0, point_mass: bool = False, axis=(0.0, 1.0, 0.0),
    gravity=(0.0, 0.0, -9.81),
) -> Chain:  # fmt: skip
    """Serial chain of n revolute links hanging along -z at q = 0, each ``length`` m long:
    uniform thin rods of ``mass`` kg (COM at mid-length, I = m l^2/12 about x and y), or point
    masses at the far end if ``point_mass``. All joints rotate about ``axis`` (link frame)."""
    if int(n) < 1 or not (length > 0 and mass > 0):
        raise JassyError(f"n, length, mass: expected n >= 1, length > 0, mass > 0; got {n}, {length}, {mass}")
    n = int(n)
    pos = np.zeros((n, 3))
    pos[1:, 2] = -length
    com = np.zeros((n, 3))
    com[:, 2] = -length if point_mass else -length / 2
    Ic = 0.0 if point_mass else mass * length**2 / 12
    return Chain(
        parent=np.arange(n) - 1, joint_type=np.zeros(n, np.int64), axis=np.tile(axis, (n, 1)),
        joint_rot=np.tile(np.eye(3), (n, 1, 1)), joint_pos=pos, mass=np.full(n, float(mass)), com=com,
        inertia=np.tile(np.diag([Ic, Ic, 0.0]), (n, 1, 1)), gravity=np.asarray(gravity, dtype=np.float64),
    )  # fmt: skip


def _state(chain: Chain, name: str, x, shape=None) -> np.ndarray:
    shape = (chain.n,) if shape is None else shape
    a = np.zeros(shape) if x is None else np.ascontiguousarray(x, dtype=np.float64)
    if a.shape != shape or not np.all(np.isfinite(a)):
        raise JassyError(f"{name}: expected finite array of shape {shape}, got {a.shape}")
    return a


_BAD_INPUT = {ABA_BAD_Q: "q", ABA_BAD_QD: "qd", ABA_BAD_TAU: "tau", ABA_BAD_FEXT: "f_ext"}


def _vector(x, shape: tuple, name: str) -> np.ndarray:
    """x as a writeable, C-contiguous float64 array of ``shape`` (one numba type for every call;
    finiteness is checked in the kernel)."""
    if type(x) is np.ndarray and x.dtype == np.float64 and x.flags.c_contiguous and x.flags.writeable:
        a = x
    else:
        a = np.array(x, dtype=np.float64, order="C")
    if a.shape != shape:
        raise JassyError(f"{name}: expected finite array of shape {shape}, got {a.shape}")
    return a


def aba(chain: Chain, q, qd, tau, f_ext=None) -> np.ndarray:
    """Joint accelerations qdd (n,) by the O(n) articulated-body algorithm.

    q (rad | m), qd, tau (N m | N): (n,). f_ext: (n, 6) external spatial force on each link,
    (torque; force) about the link-frame origin in link coordinates (N m; N), default 0.
    The chain was validated when it was built; a call checks shapes and finiteness only."""
    n = chain.parent.size
    fe = chain._no_force if f_ext is None else _vector(f_ext, (n, 6), "f_ext")
    qdd = np.empty(n)
    args = (chain.model, chain._scratch, _vector(q, (n,), "q"), _vector(qd, (n,), "qd"))
    args += (_vector(tau, (n,), "tau"), fe, qdd)
    if chain._aba_entry is None:  # numba's typing of the model record costs microseconds a call
        object.__setattr__(chain, "_aba_entry", specialise(aba_checked, *args))
    code = chain._aba_entry(*args)
    if code != ABA_OK:
        if code in _BAD_INPUT:
            raise JassyError(f"{_BAD_INPUT[code]}: expected finite values")
        raise JassyError("chain: singular articulated inertia (a joint moves no mass)")
    return qdd


def rnea(chain: Chain, q, qd, qdd, f_ext=None) -> np.ndarray:
    """Joint forces tau (n,) giving accelerations qdd (recursive Newton-Euler). With qdd = 0
    this is the bias C(q, qd) (Coriolis, centrifugal, gravity, minus f_ext)."""
    fe = _state(chain, "f_ext", f_ext, (chain.n, 6))
    return _rnea(
        *chain._args(), _state(chain, "q", q), _state(chain, "qd", qd), _state(chain, "qdd", qdd), fe
    )


def crba(chain: Chain, q) -> np.ndarray:
    """Joint-space mass matrix H(q) (n, n) by the composite-rigid-body algorithm."""
    p, jt, ax, xt, sI, _ = chain._args()
    return _crba(p, jt, ax, xt, sI, _state(chain, "q", q))


def dense_forward_dynamics(chain: Chain, q, qd, tau, f_ext=None) -> np.ndarray:
    """qdd = H^-1 (tau - C) with H from CRBA, C from RNEA and a Cholesky solve (O(n^3))."""
    C = rnea(chain, q, qd, np.zeros(chain.n), f_ext)
    return cho_solve(cho_factor(crba(chain, q)), _state(chain, "tau", tau) - C)


def link_poses(chain: Chain, q) -> tuple[np.ndarray, np.ndarray]:
    """World rotation (n, 3, 3) and origin (n, 3) m of each link frame at configuration q."""
    return _poses(
        chain.parent, chain.joint_type, chain.axis, chain.joint_rot, chain.joint_pos, _state(chain, "q", q)
    )


def energy(chain: Chain, q, qd) -> tuple[float, float]:
    """(kinetic 1/2 qd^T H qd, gravitational potential -sum m_i g.x_com,i) in J."""
    qd = _state(chain, "qd", qd)
    R, p = link_poses(chain, q)
    xcom = p + np.einsum("nij,nj->ni", R, chain.com)
    return 0.5 * float(qd @ crba(chain, q) @ qd), -float(chain.mass @ (xcom @ chain.gravity))


def simulate(chain: Chain, q0, qd0, h: float, steps: int, integrator: str = "rk4", tau=None):
    """Integrate the chain with ABA under constant joint forces ``tau`` (default 0).

    h: step (s); integrator: "rk4" (classical Runge-Kutta) or "semi-implicit" (symplectic
    Euler: qd += h qdd(q, qd), then q += h qd). Returns (q, qd), each (steps + 1, n)."""
    if integrator not in ("rk4", "semi-implicit"):
        raise JassyError(f"integrator: expected 'rk4' or 'semi-implicit', got {integrator!r}")
    if not (h > 0 and np.isfinite(h)) or int(steps) < 0:
        raise JassyError(f"h, steps: expected h > 0 and steps >= 0, got {h}, {steps}")
    Q, QD = _simulate(
        chain.model, new_aba_data(chain.n), _state(chain, "q0", q0), _state(chain, "qd0", qd0),
        _state(chain, "tau", tau), float(h), int(steps), integrator == "rk4",
    )  # fmt: skip
    if not (np.all(np.isfinite(Q)) and np.all(np.isfinite(QD))):
        raise JassyError("chain: simulation diverged or hit a singular articulated inertia")
    return Q, QD
