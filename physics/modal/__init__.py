"""Modal models from meshes (finite elements) and from recordings (fitting).

Python API (imported lazily, so ``import physics.modal`` is cheap)::

    from physics.modal import modes_from_mesh, material, load_mesh, fit_recordings, fit_files

    model, report, surface = modes_from_mesh(load_mesh("cup.stl", 0.001), material("ceramic"), n_modes=40)
    result = fit_files(["strike.wav"]); result.model.save("strike.toml"); print(result.report())

* :mod:`physics.modal.fem`: voxel finite element modes of a closed mesh (``jassy modes``).
* :mod:`physics.modal.solver`: nested dissection, multifrontal Cholesky, block eigensolver.
* :mod:`physics.modal.fit`: modes fitted to impact recordings (``jassy fit``).
* :mod:`physics.modal.materials`, :mod:`physics.modal.meshes`, :mod:`physics.modal.subdivision`,
  :mod:`physics.modal.analytic` (validation references), :mod:`physics.modal.shipped` (the
  bowl model of ``patches/bowl.toml``), :mod:`physics.modal.bench` (timings).
* :mod:`physics.modal.cli`: ``add_commands`` for the ``jassy`` CLI, ``describe_model``.
"""

from __future__ import annotations

import importlib

_EXPORTS = {
    "modes_from_mesh": "physics.modal.fem",
    "Material": "physics.modal.materials",
    "MATERIALS": "physics.modal.materials",
    "material": "physics.modal.materials",
    "load_mesh": "physics.modal.meshes",
    "fit_recordings": "physics.modal.fit",
    "fit_files": "physics.modal.fit",
    "resynthesise": "physics.modal.fit",
    "SurfaceMap": "physics.modal.subdivision",
    "describe_model": "physics.modal.cli",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name in _EXPORTS:
        return getattr(importlib.import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module 'physics.modal' has no attribute {name!r}")
