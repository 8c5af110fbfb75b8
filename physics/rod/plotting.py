"""PNG plots of the rod experiments, written atomically (a failed run leaves no file)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path


def save_plot(path, draw: Callable, size: tuple[float, float] = (6.0, 4.5), dpi: int = 110) -> None:
    """Make one figure, let ``draw(ax)`` fill it, and write it to ``path`` (PNG)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from jassy.files import atomic_path

    fig, ax = plt.subplots(figsize=size)
    try:
        draw(ax)
        fig.tight_layout()
        with atomic_path(Path(path)) as tmp:
            fig.savefig(tmp, dpi=dpi, format="png")
    finally:
        plt.close(fig)
