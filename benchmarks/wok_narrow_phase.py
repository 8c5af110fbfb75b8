"""The rigid narrow phase alone on fixed poses of the wok scene: every pair of bodies
(``pair_contacts``, margin 2 mm) at 120 poses 50 ms apart, split into the wok mesh against
the food and food against food; CPU time, best of 5. The poses are simulated once and saved
to ``--states`` so that two checkouts time the same geometry:

    PYTHONPATH=NEW python benchmarks/wok_narrow_phase.py --states /tmp/wok_states.npz
    PYTHONPATH=OLD python benchmarks/wok_narrow_phase.py --states /tmp/wok_states.npz

Both layouts of the model are read: the Model record with its contact buffers
(``World.model``, ``narrow.new_contacts``) and the older geometry tuple (``World.arrays``)."""

from __future__ import annotations

import argparse
import os
import time

import numba as nb
import numpy as np


@nb.njit(cache=False, _nrt=False)
def _pairs(pos, rot, geo, margin, buf, repeats, first, last, pair_contacts, extra):
    """Contacts of bodies first..last-1 against every later body at every pose, ``repeats``
    times (``extra``: pair_contacts' arguments after the count); returns the number of
    contacts."""
    total = 0
    for _ in range(repeats):
        for s in range(pos.shape[0]):
            n = pos.shape[1]
            for a in range(first, min(n, last)):
                for b in range(a + 1, n):
                    total += pair_contacts(a, b, pos[s], rot[s], geo, margin, buf, 0, *extra)
    return total


def main() -> None:
    from patches.wok import build_world, simulate_wok
    from physics.rigid import narrow
    from physics.rigid.narrow import new_mesh_memory
    from physics.rigid.spatial import rotation_matrices

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--states", required=True, help="npz of wok poses (written if missing)")
    args = p.parse_args()
    if not os.path.exists(args.states):
        _, _, result = simulate_wok(6.0)  # poses every 10 ms; keep every 5th
        np.savez(args.states, pos=result.pos[::5], quat=result.quat[::5])
    data = np.load(args.states)
    world, _ = build_world(14, 0)
    pos = np.ascontiguousarray(data["pos"])
    rot = np.stack([rotation_matrices(q) for q in data["quat"]])
    if hasattr(world, "model"):
        geo = world.model().geometry
        buf = narrow.new_contacts(4096, new_mesh_memory(int(geo.point_start[-1])))
    else:  # a tree from before the Model record
        from physics.rigid import stepper

        geo = world.arrays()[0]
        buf = stepper._new_buffers(4096, new_mesh_memory(geo[21][-1]))
    if hasattr(narrow, "narrow_entries"):  # its methods called apart
        pair_contacts = narrow.pair_contacts_of
        extra = (narrow.narrow_entries(pos[0], rot[0], geo, buf),)
    else:  # a tree from before
        pair_contacts, extra = narrow.pair_contacts, ()
    _pairs(pos[:1], rot[:1], geo, 0.002, buf, 1, 0, 1000, pair_contacts, extra)  # compile
    for name, first, last in (("wok mesh vs food", 0, 1), ("food vs food", 1, 1000)):
        best = np.inf
        for _ in range(5):
            t0 = time.process_time()
            count = _pairs(pos, rot, geo, 0.002, buf, 3, first, last, pair_contacts, extra)
            best = min(best, time.process_time() - t0)
        print(f"{name:18s} {count:7d} contacts  {best * 1e3:6.1f} ms CPU")


if __name__ == "__main__":
    main()
