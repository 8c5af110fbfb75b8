"""Optional peer engines as benchmark references: the same chain in Pinocchio.

Pinocchio (Carpentier et al., SII 2019; ``pip install pin``) is imported only here and only
when asked for; every function returns None when it is not installed.
"""

from __future__ import annotations

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
