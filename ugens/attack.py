"""StrikeAttack: the broadband start of a strike that a modal model's modes do not explain.

A fitted model (``jassy fit``) keeps the first strike's residual over its first milliseconds
(recording minus modal resynthesis: the contact, the mallet, the unresolved high modes) as
``ModalModel.attack``, samples of the response to a unit impulse (1 N s). Driven by the same
force as the model's ModalBank, this ugen adds that residual to every strike:

    y[n] = gain sum_m attack[m] F[n - m] / fs

so the discrete unit impulse F = fs delta[n] plays the stored samples from its own frame on,
as the bank plays the modes (van den Doel, Kry & Pai 2001, "FoleyAutomatic", excite modal
models with such a recorded residual; commuted synthesis, Smith 1993, folds it into the
excitation the same way). The attack is resampled to the render rate when the two differ.
Cost: the length of the attack per non-zero force sample (a tap costs one attack; a
continuous force costs a convolution); silence costs a ring read per sample.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from jassy.errors import PatchError
from jassy.params import ParamSpec
from jassy.registry import register
from jassy.ugen import UGen
from ugens.modal import ModelParams


@nb.njit(cache=True)
def scatter_attack(force, out, n, taps, ring, pos):
    """out[i] = sum_m taps[m] force[i - m] for i < n, force before this call remembered in
    ``ring`` (length a power of two >= len(taps), read at ``pos[0]``): every non-zero force
    sample adds its scaled taps into the ring ahead of it."""
    mask = ring.size - 1
    p = pos[0]
    for i in range(n):
        f = force[i]
        if f != 0.0:
            for m in range(taps.size):
                ring[(p + m) & mask] += f * taps[m]
        out[i] = ring[p]
        ring[p] = 0.0
        p = (p + 1) & mask
    pos[0] = p


@register
class StrikeAttack(ModelParams, UGen):
    """The stored attack of a fitted modal model (``ModalModel.attack``), played for every
    strike of the force input: in a patch, drive it with the ModalBank's force and mix the
    two (the bank rings the modes, this adds the contact and what the modes miss).

    Input: force in N. Output: the model's gain units times N s (the recording's units for a
    fitted model), times ``gain``; silence for a model without an attack."""

    type_name = "StrikeAttack"
    inputs = ("input",)
    param_specs = {
        "model": ParamSpec("model", required=True, fixed=True, doc="the ModalModel (name in a patch)"),
        "gain": ParamSpec("float", 1.0, fixed=True, doc="multiplies the attack"),
    }

    def _prepare(self) -> None:
        model = self.model
        if model.attack is not None and not np.all(np.isfinite(model.attack)):  # pragma: no cover - validated
            raise PatchError(f"nodes.{self.name}.model: attack: expected finite samples")
        rate = float(self.sample_rate)
        taps = model.attack_at(rate)
        self.taps = np.ascontiguousarray(taps * self.values["gain"] / rate, dtype=np.float64)
        size = 1 << int(np.ceil(np.log2(max(self.taps.size, 1) + 1)))
        self.ring = np.zeros(size)
        self.pos = np.zeros(1, dtype=np.int64)

    def _reset(self) -> None:
        self.ring[:] = 0.0
        self.pos[0] = 0

    def process(self, start: int, n: int) -> None:
        scatter_attack(self.sources["input"].out, self.out, n, self.taps, self.ring, self.pos)

    def state_arrays(self):
        return {"ring": self.ring, "pos": self.pos}
