"""Physics: rigid bodies, rods, deformables, modal analysis, burr drilling."""

from jassy import jit  # noqa: F401 (before any kernel compiles: each runs its own code, see jit)
