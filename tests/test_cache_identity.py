"""A render is the same bits whether its process compiled the numba kernels or loaded them
from numba's cache (jassy.jit: every kernel runs the copies of its callees compiled with it).

Before, crumple and rain differed by up to 1.8e-15 between the two: a caller's re-optimised
copy of a called kernel vectorised a reduction differently from the callee's own code, and
which one ran depended on what the process had compiled or loaded first."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

#: Patches whose kernels call other kernels (crumple: the node-by-node path; rain: the
#: graph program), each rendered for RENDER_SECONDS (both differed within 0.25 s before).
PATCHES = ("crumple", "rain")
RENDER_SECONDS = 1.0

RENDER_AND_HASH = f"""
import hashlib, json, sys
import numpy as np
from jassy.engines.offline import OfflineEngine
from jassy.patchfile import load_patch
hashes = {{}}
for name in sys.argv[1:]:
    patch = load_patch(name)
    rendering = OfflineEngine(patch.graph, patch.score, 48000).render({RENDER_SECONDS})
    audio = np.ascontiguousarray(rendering.audio)
    assert np.abs(audio).max() > 0, name
    hashes[name] = hashlib.sha256(audio.tobytes()).hexdigest()
json.dump(hashes, sys.stdout)
"""


def _render_in_fresh_process(cache_dir, names) -> dict:
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache_dir))
    done = subprocess.run(
        [sys.executable, "-c", RENDER_AND_HASH, *names], env=env, capture_output=True, text=True, timeout=400
    )
    assert done.returncode == 0, done.stderr[-2000:]
    return json.loads(done.stdout)


@pytest.mark.timeout(800)
def test_renders_are_identical_with_kernels_compiled_or_loaded_from_the_cache(tmp_path):
    cold = _render_in_fresh_process(tmp_path, PATCHES)  # empty cache: every kernel compiled here
    assert any(name.endswith(".nbc") for _, _, files in os.walk(tmp_path) for name in files)
    # every kernel loaded from the cache, in the other order (which kernels a process met
    # first used to decide which code ran)
    warm = _render_in_fresh_process(tmp_path, PATCHES[::-1])
    assert warm == cold
