"""All 2D-rod experiments by name (``jassy rod NAME``): the elastic ones and the contact ones."""

from __future__ import annotations

from physics.rod.contact_experiments import EXPERIMENTS as CONTACT
from physics.rod.elastic_experiments import EXPERIMENTS as ELASTIC

EXPERIMENTS = {**ELASTIC, **CONTACT}
