"""Calibrated levels of tonal force sources (ResonantScrape, DrillSource).

A force with a line spectrum or a narrow band is loud on a model with a mode at its
frequencies and faint on one without: no force in N fits every model. Given ``model``
(the ModalModel it drives; ``level = "auto"``, the default, or ``"calibrated"``) such a
source scales its force by the model's response at the source's own frequencies, computed once at render
start from the modes in closed form (:func:`jassy.levels.tonal_level_gain`), so that a
calibrated ModalBank of that model rings at ``jassy.levels.TONAL_RMS_DBFS`` RMS (mean power
over the model's locations) at the source's reference operating point; without a model
(or with ``level = "raw"``) the force is in N as set. ResonantScrape,
whose band moves with the slip speed, keeps a table of the factor over the speed, so the
level holds at every speed (times its amplitude law); DrillSource keeps one over the rpm,
each entry calibrated on its harmonics averaged over the entry's rpm step.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from jassy.errors import PatchError
from jassy.levels import TONAL_RMS_DBFS, ForceSpectrum, tonal_level_gain
from jassy.params import ParamSpec
from ugens.modal import ModelParams

#: Entries of a level table: the log of the calibrated level's factor at evenly spaced
#: operating points (ResonantScrape: slip speeds; DrillSource: rpm), stored in ``cfg``.
LEVEL_POINTS = 1024


@nb.njit(inline="always", cache=True)
def log_table(cfg, first, x):
    """exp of the level table starting at ``cfg[first]`` at fractional index x >= 0, linear
    in the log between entries, held beyond the last."""
    i = int(x)
    if i >= LEVEL_POINTS - 1:
        return math.exp(cfg[first + LEVEL_POINTS - 1])
    w = x - i
    return math.exp((1.0 - w) * cfg[first + i] + w * cfg[first + i + 1])


#: The ``model`` and ``level`` parameters of a tonal force source.
TONAL_LEVEL_SPECS = {
    "model": ParamSpec(
        "model", None, fixed=True, doc="the ModalModel this force drives (its level is calibrated to it)"
    ),
    "level": ParamSpec(
        "str",
        "auto",
        choices=("auto", "raw", "calibrated"),
        fixed=True,
        doc="'raw': the force in N as set; 'calibrated': scaled so that at the reference operating "
        f"point a calibrated ModalBank of `model` rings at {TONAL_RMS_DBFS:g} dBFS RMS (mean over its "
        "locations; jassy.levels.tonal_level_gain); 'auto': calibrated when given `model`, else raw",
    ),
}


class TonalLevel(ModelParams):
    """A force source whose level can be calibrated to the model it drives."""

    def force_spectrum(self) -> ForceSpectrum:
        """The force (gain 1) at the source's reference operating point."""
        raise NotImplementedError

    def is_calibrated(self) -> bool:
        """Level 'calibrated', or 'auto' with a ``model``."""
        level = self.values["level"]
        return level == "calibrated" or (level == "auto" and self.values["model"] is not None)

    def tonal_gain(self, spectrum: ForceSpectrum | None = None) -> np.ndarray:
        """The factor on the force (one per spectrum of a stack; default: the reference
        operating point's): 1 when not calibrated, else jassy.levels.tonal_level_gain."""
        if not self.is_calibrated():
            return np.asarray(1.0)
        return tonal_level_gain(
            self.calibration_model(),
            self.force_spectrum() if spectrum is None else spectrum,
            self.sample_rate,
        )

    def calibration_model(self):
        """The model to calibrate to, checked against the sample rate (one error line if
        ``level = 'calibrated'`` was given without it)."""
        if self.values["model"] is None:
            raise PatchError(
                f"nodes.{self.name}.level: 'calibrated' needs `model`, the ModalModel this force drives"
            )
        self.validate_model()
        return self.model
