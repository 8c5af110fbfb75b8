"""Burr-bone drilling at haptic rate (Agus et al., IEEE VR 2002/2003, Presence 12(1), 2003).

volume: 8-bit density volumes (NPZ/raw, procedural phantom); contact: voxel-sphere overlap
kernels, brute-force moments, h inversion, Hertz friction and Russian-roulette erosion;
octree: the multiresolution moment pyramid; update: one haptic step as one compiled call;
loop: BurrSim (one haptic step), run_loop,
the constant-force Descent and DrillTrack; bench: bench_burr.
"""

from physics.burr.bench import bench_burr, print_burr
from physics.burr.contact import R_VOXEL, brute_moments, cap_volume, depth_from_m0, lens_volume
from physics.burr.loop import BurrParams, BurrSim, ContactState, Descent, DrillTrack, LoopResult, run_loop
from physics.burr.octree import Octree
from physics.burr.volume import Volume, phantom, uniform_block

__all__ = [
    "R_VOXEL",
    "BurrParams",
    "BurrSim",
    "ContactState",
    "Descent",
    "DrillTrack",
    "LoopResult",
    "Octree",
    "Volume",
    "bench_burr",
    "brute_moments",
    "cap_volume",
    "depth_from_m0",
    "lens_volume",
    "phantom",
    "print_burr",
    "run_loop",
    "uniform_block",
]
