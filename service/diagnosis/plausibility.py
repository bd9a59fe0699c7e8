"""Whether a fitted effect is physically plausible where it sits: a size at the prior's limit, or heat
where the graph's component has no source, demotes it in the ranking, and the ranking says why.

An effect parameter at a bound that is neither its null nor a state the physics reaches (its
``attainable`` bounds: a valve entirely stuck, or stuck wide open) means the data ask for more than
the prior allows (the effect's size is the limit, not an estimate). A heat rate into the air
(:attr:`~service.components.component.ComponentModel.heat_rate_parameter`) at a component that can
only take heat from the air (``air_heat_sign = −1``: a chilled-water coil) has no source there.
The method: ``docs/diagnosis.md``, "Plausibility".
"""

from __future__ import annotations

import numpy as np

from service.components.component import bound_side
from service.graph.namespaces import local_name
from service.graph.units import quantity_text
from service.model.assembled_model import AssembledModel

__all__ = ["BOUND_SHARE", "at_bound", "bound_note", "demotion_reasons"]

#: A fitted value this share of its prior range from a bound sits at the bound.
BOUND_SHARE = 0.005


def at_bound(value: float, spec) -> str:
    """``"lower"`` or ``"upper"`` when ``value`` lies within :data:`BOUND_SHARE` of the prior range
    of that bound of ``spec`` (a :class:`~service.components.component.Parameter`), else ``""``; a
    bound that is the effect's null or ``attainable`` is no limit of the prior: ``""`` there."""
    side = bound_side(value, spec.lower, spec.upper, BOUND_SHARE)
    return "" if side and getattr(spec, side) in {spec.null, *spec.attainable} else side


def bound_note(value: float, spec) -> str:
    """`` (at its lower/upper bound B)`` where :func:`at_bound`: the data push it further than the prior allows."""
    side = at_bound(value, spec)
    return f" (at its {side} bound {quantity_text(getattr(spec, side), spec.unit, 'g')})" if side else ""


def demotion_reasons(model: AssembledModel, node: str, theta: np.ndarray, effect_columns: list[int]) -> str:
    """Why the ranking puts the effect at ``node`` (its parameters at ``effect_columns`` of ``model``'s
    estimated parameters, fitted to ``theta``) below the plausible ones; empty when nothing does."""
    refs = model.estimated_parameters
    reasons = []
    for j in effect_columns:
        spec = refs[j].spec
        side = at_bound(theta[j], spec)
        if side:
            bound = quantity_text(getattr(spec, side), spec.unit, "g")
            reasons.append(f"{refs[j].name} fits only at its {side} bound {bound}")
    effects = {refs[j].component for j in effect_columns}
    host = next((c for iri, c in model.components.items() if node in c.modeled_nodes and iri not in effects), None)
    for j in effect_columns:
        heat_parameter = model.components[refs[j].component].model_class.heat_rate_parameter
        spec = refs[j].spec
        if (host is not None and refs[j].name == heat_parameter and host.model_class.air_heat_sign < 0
                and theta[j] > BOUND_SHARE * (spec.upper - spec.lower)):
            heat = quantity_text(round(float(theta[j]), 0), spec.unit, "g")
            reasons.append(f"{refs[j].name} = {heat} into the air at "
                           f"{local_name(node)}, which can only take heat from the air ({host.signature.label}): "
                           "no heat source there")
    return "; ".join(reasons)
