"""jassy: physically based sound synthesis with one clock for physics, sound and touch.

The core (this package) holds the clock, graph, scheduler, engines, shared data types,
patch files and the CLI. It does not import ``ugens``, ``physics`` or ``patches`` at
import time.
"""

from jassy import jit  # noqa: F401 (first: every kernel runs its own compiled code, see jit)
from jassy.engines.offline import OfflineEngine, Rendering, render
from jassy.errors import JassyError, ModelError, PatchError, RenderError
from jassy.events import ContactTrack, Event, HapticFrame, Impact
from jassy.graph import Graph
from jassy.modal_model import Location, ModalModel
from jassy.ugen import UGen

__version__ = "0.1.0"

__all__ = [
    "ContactTrack",
    "Event",
    "Graph",
    "HapticFrame",
    "Impact",
    "JassyError",
    "Location",
    "ModalModel",
    "ModelError",
    "OfflineEngine",
    "PatchError",
    "RenderError",
    "Rendering",
    "UGen",
    "render",
]
