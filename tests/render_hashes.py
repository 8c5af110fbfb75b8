"""Hashes of every shipped patch and scene render, to show a refactor changes no bit.

    python tests/render_hashes.py OUT.json [NAME ...]     # render and hash (all by default)
    python tests/render_hashes.py --compare A.json B.json # list what differs; exit 1 if any

Patches are rendered by the offline engine over their own duration (audio and haptic
arrays); scenes write their WAV, haptic CSV and data CSV, whose bytes are hashed (SHA-256,
first 16 hex digits). Compare renders of the same numba cache state: a kernel compiled in
the process can round differently from the same kernel loaded from numba's cache.
"""

from __future__ import annotations

import hashlib
import importlib
import json
import sys
import tempfile
from pathlib import Path

import numpy as np


def digest(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()[:16]


def patch_hashes(name: str) -> dict[str, str]:
    from jassy.engines.offline import OfflineEngine
    from jassy.patchfile import load_patch

    patch = load_patch(name)
    rendering = OfflineEngine(patch.graph, patch.score, patch.sample_rate or 48000).render(
        patch.duration or 4.0
    )
    return {
        "audio": digest(np.ascontiguousarray(rendering.audio).tobytes()),
        "haptic": digest(np.ascontiguousarray(rendering.haptic).tobytes()),
    }


def scene_hashes(name: str) -> dict[str, str]:
    from patches.scenes import SCENES

    module, function = SCENES[name]
    render = getattr(importlib.import_module(module), function)
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp)
        render(out / "audio.wav", out / "haptic.csv", out / "data.csv", sample_rate=48000)
        return {f.name: digest(f.read_bytes()) for f in sorted(out.iterdir())}


def main(argv: list[str]) -> int:
    if argv[:1] == ["--compare"]:
        before, after = (json.loads(Path(p).read_text()) for p in argv[1:3])
        both = before.keys() & after.keys()
        differ = sorted(k for k in both if before[k] != after[k])
        for name in differ:
            print(f"{name}: {before[name]} -> {after[name]}")
        alone = len(before.keys() ^ after.keys())
        print(f"{len(both) - len(differ)} identical, {len(differ)} differ, {alone} in one file only")
        return 1 if differ else 0
    from jassy.patchfile import builtin_patches
    from patches.scenes import SCENES

    names = argv[1:] or sorted(builtin_patches()) + sorted(SCENES)
    hashes = {}
    for name in names:
        hashes[name] = scene_hashes(name) if name in SCENES else patch_hashes(name)
        print(name, hashes[name], flush=True)
    Path(argv[0]).write_text(json.dumps(hashes, indent=1, sort_keys=True))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
