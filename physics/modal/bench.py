"""Timings of ``jassy modes``: ``python -m physics.modal.bench [ELEMENTS] [MODES]``.

Solves the shipped bowl geometry (bronze, a thin shell: the common case for sounding
objects), a plate and a solid sphere (the hardest case for a direct solver: 3D fill) at about
ELEMENTS voxels (default 20000) for MODES modes (default 50), and prints each stage. The
wall-clock figures drift on a shared VM; the CPU time is printed alongside.
"""

from __future__ import annotations

import sys
import time


def bench_modes(elements: int = 20000, n_modes: int = 50, shapes=("bowl", "plate", "sphere")) -> list[dict]:
    from physics.modal import fem, meshes
    from physics.modal.materials import material
    from physics.modal.shipped import BOWL

    makers = {
        "bowl": (lambda: meshes.bowl(**BOWL), "bronze"),
        "plate": (lambda: meshes.plate(0.3, 0.2, 0.004), "aluminium"),
        "sphere": (lambda: meshes.sphere(0.05, 5), "steel"),
    }
    rows = []
    for name in shapes:
        make, mat = makers[name]
        mesh = make()
        wall0, cpu0 = time.perf_counter(), time.process_time()
        model, report, _ = fem.modes_from_mesh(
            mesh, material(mat), n_modes=n_modes, elements=elements, points={"p": tuple(mesh.vertices[0])}
        )
        rows.append(
            {
                "shape": name,
                "elements": report.n_elements,
                "dofs": report.n_dofs,
                "modes": model.n_modes,
                "f1": float(model.frequencies[0]),
                "wall": time.perf_counter() - wall0,
                "cpu": time.process_time() - cpu0,
                **{k: round(v, 3) for k, v in report.timings.items()},
            }
        )
    return rows


def main(argv: list[str] | None = None) -> None:
    argv = sys.argv[1:] if argv is None else argv
    elements = int(argv[0]) if argv else 20000
    n_modes = int(argv[1]) if len(argv) > 1 else 50
    bench_modes(2000, 5, ("bowl",))  # warm-up: numba compile and imports
    print(f"jassy modes: ~{elements} voxel elements, {n_modes} modes")
    print(f"{'shape':<7} {'elements':>8} {'dofs':>7} {'voxelise':>8} {'assemble':>8} {'factor':>7} "
          f"{'eigsh':>7} {'gains':>6} {'total':>7} {'cpu':>7}")  # fmt: skip
    for r in bench_modes(elements, n_modes):
        print(
            f"{r['shape']:<7} {r['elements']:>8} {r['dofs']:>7} {r['voxelise']:>8.2f} {r['assemble']:>8.2f} "
            f"{r['factor']:>7.2f} {r['eigsh']:>7.2f} {r['gains']:>6.2f} {r['total']:>7.2f} {r['cpu']:>7.2f}"
        )


if __name__ == "__main__":
    main()
