"""The estimator that knows the plant's parameters (``campaign --oracle``): the same run --
plant, noise, controller, switch manager -- with an estimator whose model takes the run's
plant parameters instead of learning them.

The family's multipliers are applied to the plant.* keys the estimator reads as
:func:`core.sim.family.plant_params` applies them to the plant (leakage paths, displacement,
bulk modulus, friction, sensor noise), and the adaptive states (the stages ``adapt_*``) are left
out, there being nothing to learn; every other stage runs as configured. A run the stack fails
and its oracle passes was lost to learning the parameters; one both fail was not (the sensors'
noise, the model's structure, the loop). It is not a bound: the model's structure stays the
stack's, and where the plant departs from it (the boost check valves under load) the adaptive
states can fit what known parameters cannot.
"""
from __future__ import annotations

from ..estimator import params as EP
from .family import plant_params

ADAPTIVE = tuple(s for s in EP.STAGES if s.startswith('adapt_'))


def estimator_params(estimator: dict, multipliers: dict) -> dict:
    """The estimator's parameters ``estimator`` (dotted keys) for the plant of one family row:
    its plant.* keys scaled by ``multipliers``, the adaptive stages switched off."""
    return EP.without(plant_params(estimator, multipliers), *ADAPTIVE)
