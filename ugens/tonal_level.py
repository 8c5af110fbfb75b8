"""Calibrated levels of tonal force sources (ResonantScrape, DrillSource).

A force with a line spectrum or a narrow band is loud on a model with a mode at its
frequencies and faint on one without: no force in N fits every model. With
``level = "calibrated"`` and ``model`` (the ModalModel it drives) such a source scales its
force by the model's response at the source's own frequencies, computed once at render
start from the modes in closed form (:func:`jassy.levels.tonal_level_gain`), so that a
calibrated ModalBank of that model rings at ``jassy.levels.TONAL_RMS_DBFS`` RMS (mean power
over the model's locations) at the source's reference operating point. ResonantScrape,
whose band moves with the slip speed, keeps a table of the factor over the speed, so the
level holds at every speed (times its amplitude law); DrillSource's factor is fixed at its
starting rpm, and its lines meet other modes as the rpm changes.
"""

from __future__ import annotations

import numpy as np

from jassy.errors import PatchError
from jassy.levels import TONAL_RMS_DBFS, ForceSpectrum, tonal_level_gain
from jassy.params import ParamSpec
from ugens.modal import ModelParams

#: The ``model`` and ``level`` parameters of a tonal force source.
TONAL_LEVEL_SPECS = {
    "model": ParamSpec(
        "model", None, fixed=True, doc="the ModalModel this force drives (needed by level = 'calibrated')"
    ),
    "level": ParamSpec(
        "str",
        "raw",
        choices=("raw", "calibrated"),
        fixed=True,
        doc="'raw': the force in N as set; 'calibrated': scaled so that at the reference operating "
        f"point a calibrated ModalBank of `model` rings at {TONAL_RMS_DBFS:g} dBFS RMS (mean over its "
        "locations; jassy.levels.tonal_level_gain)",
    ),
}


class TonalLevel(ModelParams):
    """A force source whose level can be calibrated to the model it drives."""

    def force_spectrum(self) -> ForceSpectrum:
        """The force (gain 1) at the source's reference operating point."""
        raise NotImplementedError

    def tonal_gain(self, spectrum: ForceSpectrum | None = None) -> np.ndarray:
        """The factor on the force (one per spectrum of a stack; default: the reference
        operating point's): 1 for level 'raw', else jassy.levels.tonal_level_gain."""
        if self.values["level"] != "calibrated":
            return np.asarray(1.0)
        if self.values["model"] is None:
            raise PatchError(
                f"nodes.{self.name}.level: 'calibrated' needs `model`, the ModalModel this force drives"
            )
        self.validate_model()
        return tonal_level_gain(
            self.model, self.force_spectrum() if spectrum is None else spectrum, self.sample_rate
        )
