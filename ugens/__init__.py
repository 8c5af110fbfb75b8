"""Unit generators. Importing this package registers every built-in ugen type."""

from ugens.bubbles import Bubble, BubbleStream
from ugens.delay import Delay
from ugens.drill import DrillSource
from ugens.dynamics import Limiter
from ugens.engine import Engine
from ugens.envelope import Envelope
from ugens.filters import Biquad, OnePole
from ugens.friction import Friction
from ugens.impact import ImpactForce
from ugens.impact_train import ImpactTrain
from ugens.mix import Gain, Mixer, Multiply
from ugens.modal import ModalBank
from ugens.noise import FractalNoise, WhiteNoise
from ugens.nonlinear_impact import HuntCrossleyImpact
from ugens.oscillators import Sine
from ugens.radiation import Radiation
from ugens.roll import RathRoll, Roll
from ugens.scrape import ResonantScrape, Scrape
from ugens.stochastic import Bounce, Break, Crumple

__all__ = [
    "Biquad",
    "Bounce",
    "Break",
    "Bubble",
    "BubbleStream",
    "Crumple",
    "Delay",
    "DrillSource",
    "Engine",
    "Envelope",
    "FractalNoise",
    "Friction",
    "Gain",
    "HuntCrossleyImpact",
    "ImpactForce",
    "ImpactTrain",
    "Limiter",
    "Mixer",
    "ModalBank",
    "Multiply",
    "OnePole",
    "Radiation",
    "RathRoll",
    "ResonantScrape",
    "Roll",
    "Scrape",
    "Sine",
    "WhiteNoise",
]
