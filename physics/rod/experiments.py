"""All 2D-rod experiments by name (``jassy rod NAME``): each ``(plot=None, quick=False) -> dict``.

The elastic experiments come from physics.rod.elastic_experiments; the contact ones run
their published variants: the snap-fit for ring types I and II, the shell stack for
Gamma = 10 and 100 (with ``plot``, one PNG per variant: NAME_I.png, NAME_II.png, ...).
"""

from __future__ import annotations

from pathlib import Path

from physics.rod import contact_experiments as contact
from physics.rod.elastic_experiments import EXPERIMENTS as ELASTIC


def _variant_plot(plot: str | None, tag: str) -> str | None:
    return None if plot is None else str(Path(plot).with_name(f"{Path(plot).stem}_{tag}{Path(plot).suffix}"))


def snap_fit(plot: str | None = None, quick: bool = False) -> dict:
    """Ring-on-cylinder snap-fit, types I (100 deg opening) and II (140 deg)."""
    n = 12 if quick else 20
    return {kind: contact.snap_fit(kind, n=n, plot=_variant_plot(plot, kind)) for kind in ("I", "II")}


def shell_stack(plot: str | None = None, quick: bool = False) -> dict:
    """Four semicircular shells dropped on a floor, Gamma = 10 and 100."""
    duration = 0.3 if quick else 1.0
    return {
        f"gamma_{g:g}": contact.shell_stack(g, duration=duration, plot=_variant_plot(plot, f"gamma{g:g}"))
        for g in (10.0, 100.0)
    }


def archery(plot: str | None = None, quick: bool = False) -> dict:
    """A bow and string launching an arrow at a target 3 m away."""
    return contact.archery(plot=plot)


def bicycle(plot: str | None = None, quick: bool = False) -> dict:
    """A bicycle (two rigid wheels and a frame) riding across a sagging rope."""
    return contact.bicycle_on_rope(duration=1.0 if quick else 3.0, plot=plot)


EXPERIMENTS = {
    **ELASTIC,
    "snap_fit": snap_fit,
    "shell_stack": shell_stack,
    "archery": archery,
    "bicycle": bicycle,
}
