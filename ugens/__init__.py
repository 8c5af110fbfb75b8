"""Unit generators. Importing this package registers every built-in ugen type."""

from ugens.analysis import EnvelopeFollower, Onset, Pitch, SpectralFeatures, ZeroCrossings
from ugens.attack import StrikeAttack
from ugens.bubbles import Bubble, BubbleStream
from ugens.dcmotor import DCMotor
from ugens.delay import Delay
from ugens.drill import DrillSource
from ugens.dynamics import Limiter
from ugens.engine import Engine
from ugens.envelope import Envelope
from ugens.explosion import Explosion
from ugens.filters import Biquad, OnePole
from ugens.friction import Friction
from ugens.impact import ImpactForce
from ugens.impact_train import ImpactTrain
from ugens.mix import Gain, Mixer, Multiply
from ugens.modal import ModalBank
from ugens.noise import FractalNoise, WhiteNoise
from ugens.nonlinear_impact import HuntCrossleyImpact
from ugens.oscillators import Sine
from ugens.pitchshift import PitchShift
from ugens.pressure import SoundPressure
from ugens.radiation import Radiation
from ugens.reverb import Reverb
from ugens.roll import RathRoll, Roll
from ugens.sampler import Sampler
from ugens.scrape import ResonantScrape, Scrape
from ugens.spatial import Spatialiser
from ugens.stochastic import Bounce, Break, Crumple
from ugens.wind import CavityTone, KarmanWhistle, Wind

__all__ = [
    "Biquad",
    "Bounce",
    "Break",
    "Bubble",
    "BubbleStream",
    "CavityTone",
    "Crumple",
    "DCMotor",
    "Delay",
    "DrillSource",
    "Engine",
    "EnvelopeFollower",
    "Envelope",
    "Explosion",
    "FractalNoise",
    "Friction",
    "Gain",
    "HuntCrossleyImpact",
    "ImpactForce",
    "ImpactTrain",
    "KarmanWhistle",
    "Limiter",
    "Mixer",
    "ModalBank",
    "Multiply",
    "Onset",
    "OnePole",
    "Pitch",
    "PitchShift",
    "Radiation",
    "RathRoll",
    "ResonantScrape",
    "Reverb",
    "Roll",
    "Sampler",
    "Scrape",
    "Sine",
    "SoundPressure",
    "StrikeAttack",
    "Spatialiser",
    "SpectralFeatures",
    "WhiteNoise",
    "Wind",
    "ZeroCrossings",
]
