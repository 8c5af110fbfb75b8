"""Optional peer engines as benchmark references: the same chain in Pinocchio, the same
pile in MuJoCo.

Pinocchio (Carpentier et al., SII 2019; ``pip install pin``) is imported only here and only
when asked for; every function returns None when it is not installed.
"""

from __future__ import annotations

import math

import numpy as np

from physics.rigid.articulated import REVOLUTE, Chain

# Pinocchio's Data for a chain of n joints holds tensors of O(n^3) doubles (1.8 GB measured
# at 300 joints on this machine), so the reference stops where that fits comfortably.
PINOCCHIO_MAX_JOINTS = 300


def pinocchio_chain(chain: Chain):
    """(model, data) of ``chain`` in Pinocchio, or None when Pinocchio is not installed. Joints
    whose axis is a coordinate axis use Pinocchio's specialised joints (RX/RY/RZ, PX/PY/PZ),
    its fastest form; other axes the "unaligned" joints."""
    try:
        import pinocchio as pin
    except ImportError:
        return None
    if chain.n > PINOCCHIO_MAX_JOINTS:
        return None
    model = pin.Model()
    model.gravity.linear = np.array(chain.gravity, dtype=np.float64)
    for i in range(chain.n):
        ax = chain.axis[i]
        revolute = chain.joint_type[i] == REVOLUTE
        k = int(np.argmax(np.abs(ax)))
        if abs(ax[k]) == 1.0 and ax[k] > 0:
            joint = getattr(pin, ("JointModelR" if revolute else "JointModelP") + "XYZ"[k])()
        elif revolute:
            joint = pin.JointModelRevoluteUnaligned(*ax)
        else:
            joint = pin.JointModelPrismaticUnaligned(*ax)
        parent = 0 if chain.parent[i] < 0 else int(chain.parent[i]) + 1
        placement = pin.SE3(chain.joint_rot[i].copy(), chain.joint_pos[i].copy())
        jid = model.addJoint(parent, joint, placement, f"joint{i}")
        inertia = pin.Inertia(float(chain.mass[i]), chain.com[i].copy(), chain.inertia[i].copy())
        model.appendBodyToJoint(jid, inertia, pin.SE3.Identity())
    return model, model.createData()


def pinocchio_aba(reference, q, qd, tau) -> np.ndarray:
    """Pinocchio's ABA on a (model, data) pair from ``pinocchio_chain``."""
    import pinocchio as pin

    model, data = reference
    return pin.aba(model, data, q, qd, tau)


def mujoco_pile(n: int, seed: int = 0, h: float = 1e-3, settle: float = 1.0):
    """The pile of ``bench.pile`` in MuJoCo (Todorov et al., IROS 2012; ``pip install mujoco``),
    settled for ``settle`` s: (model, data), or None when MuJoCo is not installed.

    The same pen (floor and four walls as planes), the same bodies (spheres of radius 2 cm and
    cubes of half-size 1.8 cm alternating, density 1100 kg/m^3, the same start poses), the same
    step h and friction: jassy takes the geometric mean of two bodies' coefficients (plastic
    0.35, wood 0.45), MuJoCo the larger of two geoms', so the bodies get 0.35 and the pen
    sqrt(0.35 * 0.45). MuJoCo's own defaults otherwise (Newton solver, pyramidal cones, soft
    contacts without restitution or rolling friction)."""
    try:
        import mujoco
    except ImportError:
        return None
    rng = np.random.default_rng(seed)
    side = 0.05 * math.ceil(math.sqrt(n / 2.0)) + 0.05
    pen_mu = math.sqrt(0.35 * 0.45)
    walls = [((0, 0, 0), (0, 0, 1))]
    walls += [((-side, 0, 0), (1, 0, 0)), ((side, 0, 0), (-1, 0, 0))]
    walls += [((0, -side, 0), (0, 1, 0)), ((0, side, 0), (0, -1, 0))]
    xml = [f'<mujoco><option timestep="{h:.17g}"/><worldbody>']
    for pos, normal in walls:
        xml.append(
            f'<geom type="plane" size="0 0 1" pos="{pos[0]:.17g} {pos[1]:.17g} {pos[2]:.17g}" '
            f'zaxis="{normal[0]} {normal[1]} {normal[2]}" friction="{pen_mu:.17g} 0.005 0.0001"/>'
        )
    per_layer = max(1, int((2 * side / 0.05) ** 2))
    cols = int(2 * side / 0.05)
    for i in range(n):
        layer, cell = divmod(i, per_layer)
        x = -side + 0.025 + 0.05 * (cell % cols)
        y = -side + 0.025 + 0.05 * (cell // cols)
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        geom = 'type="sphere" size="0.02"' if i % 2 == 0 else 'type="box" size="0.018 0.018 0.018"'
        xml.append(
            f'<body pos="{x:.17g} {y:.17g} {0.03 + 0.05 * layer:.17g}" '
            f'quat="{q[0]:.17g} {q[1]:.17g} {q[2]:.17g} {q[3]:.17g}">'
            f'<freejoint/><geom {geom} density="1100" friction="0.35 0.005 0.0001"/></body>'
        )
    xml.append("</worldbody></mujoco>")
    model = mujoco.MjModel.from_xml_string("".join(xml))
    data = mujoco.MjData(model)
    mujoco.mj_step(model, data, nstep=int(round(settle / h)))
    return model, data


def mujoco_steps(reference, steps: int) -> None:
    """``steps`` MuJoCo steps of a (model, data) pair from ``mujoco_pile``."""
    import mujoco

    model, data = reference
    mujoco.mj_step(model, data, nstep=steps)
