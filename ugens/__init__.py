"""Unit generators. Importing this package registers every built-in ugen type."""

from ugens.impact import ImpactForce
from ugens.mix import Gain, Mixer, Multiply
from ugens.modal import ModalBank

__all__ = ["Gain", "ImpactForce", "Mixer", "ModalBank", "Multiply"]
