"""Whether a fitted effect is physically plausible where it sits: a size at the prior's limit, or heat
where the graph's component has no source, demotes it in the ranking, and the ranking says why.

An effect parameter at a bound that is neither its null nor a state the physics reaches (its
``attainable`` bounds: a valve entirely stuck, or stuck wide open) means the data ask for more than
the prior allows (the effect's size is the limit, not an estimate). A heat rate into the air
(:attr:`~service.components.component.ComponentModel.heat_rate_parameter`) at a component that can
only take heat from the air (``air_heat_sign = −1``: a chilled-water coil) has no source there.
Unmeasured surroundings fitted colder than every temperature measured in the unit are stated so
(:func:`surroundings_caution`), not demoted: a basement or a ground can be that cold.
The method: ``docs/diagnosis.md``, "Plausibility".
"""

from __future__ import annotations

import numpy as np

from service.components.component import bound_side
from service.data.measurements import MeasuredData
from service.graph.namespaces import local_name
from service.graph.units import quantity_text
from service.model.assembled_model import AssembledModel

__all__ = ["BOUND_SHARE", "at_bound", "bound_note", "demotion_reasons", "flow_share_text", "surroundings_caution"]

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


def _host(model: AssembledModel, node: str, effect_columns: list[int]):
    """The component modelling ``node`` that the effect at ``effect_columns`` is spliced on."""
    effects = {model.estimated_parameters[j].component for j in effect_columns}
    return next((c for iri, c in model.components.items() if node in c.modeled_nodes and iri not in effects), None)


def flow_share_text(model: AssembledModel, node: str, theta: np.ndarray, standard_errors: np.ndarray,
                    effect_columns: list[int]) -> str:
    """An effect's stem position (a leak's λ, a stuck stem's s; ``stem_position_parameter``) stated as
    the share of the fully open flow coefficient its host's valve passes there (``valve_flow_share``)
    at the fitted characteristic, with the share's range over the characteristic's ±2 standard errors,
    or over its whole prior where the data do not identify it: a leak of λ = 0.29 is 14 % of the open
    flow at a rangeability of 7.7 and 3 % at 99. Empty where the host models no valve."""
    refs, host = model.estimated_parameters, _host(model, node, effect_columns)
    if host is None or not host.model_class.valve_characteristic:
        return ""
    stem = next((j for j in effect_columns
                 if refs[j].name == model.components[refs[j].component].model_class.stem_position_parameter), None)
    if stem is None:
        return ""
    values = ({r.name: r.value for r in model.mapped_parameters if r.component == host.iri}
              | {r.name: float(theta[k]) for k, r in enumerate(refs) if r.component == host.iri})
    spans, unidentified = {}, []
    for k, r in enumerate(refs):
        if r.component == host.iri and r.name in host.model_class.valve_characteristic:
            se, width = float(standard_errors[k]), r.spec.upper - r.spec.lower
            if np.isfinite(se) and se <= width:
                spans[r.name] = np.linspace(max(theta[k] - 2 * se, r.spec.lower), min(theta[k] + 2 * se, r.spec.upper), 9)
            else:
                spans[r.name] = np.linspace(r.spec.lower, r.spec.upper, 21)
                unidentified.append(r.name)
    share = host.model_class.valve_flow_share(theta[stem], values)
    grid = np.meshgrid(*spans.values()) if spans else []
    shares = [host.model_class.valve_flow_share(theta[stem], values | dict(zip(spans, point)))
              for point in zip(*(g.ravel() for g in grid))] or [share]
    at = ", ".join(f"{name} = {values[name]:.3g}" for name in host.model_class.valve_characteristic if name in values)
    spread = (f"; {100 * min(shares):.2g}–{100 * max(shares):.2g} % over "
              + (f"the whole range of {', '.join(unidentified)}, which these data do not identify" if unidentified
                 else "±2 standard errors of it")) if max(shares) - min(shares) > 0.005 else ""
    return (f"at {refs[stem].name} {theta[stem]:.3g} the valve passes {100 * share:.2g} % of its fully open flow "
            f"coefficient ({at}{spread})")


def surroundings_caution(model: AssembledModel, theta: np.ndarray, standard_errors: np.ndarray,
                         effect_columns: list[int], data: MeasuredData) -> str:
    """Where an effect's unmeasured surroundings (``surroundings_temperature_parameter``) fit colder
    than the coldest temperature series (°C) in ``data`` by more than two standard errors: that, with
    the sensor, for the reader to check (a chilled-water leak can fit as a casing cooled by 5 °C
    surroundings on a summer day); else empty."""
    refs = model.estimated_parameters
    surroundings = [j for j in effect_columns if refs[j].name
                    == model.components[refs[j].component].model_class.surroundings_temperature_parameter]
    if not surroundings:
        return ""
    lows = {node: float(np.nanmin(values)) for node, values in data.series.items()
            if data.units.get(node) == "degC" and np.isfinite(values).any()}
    if not lows:
        return ""
    sensor, coldest = min(lows.items(), key=lambda item: item[1])
    for j in surroundings:
        se = float(standard_errors[j])
        if np.isfinite(se) and theta[j] + 2.0 * se < coldest:
            return (f"surroundings at {theta[j]:.3g} °C are colder than every temperature measured in the unit "
                    f"(the coldest {coldest:.3g} °C, at {local_name(sensor)}): only a space that cold or a cold "
                    "source explains them")
    return ""


def _share_of_assumed(model: AssembledModel, host, effect: str) -> bool:
    """The effect component ``effect`` sizes a share of a quantity of ``host`` whose scale the graph
    does not state and no fit estimates (its parameters fixed at their defaults: a fan's nominal
    power where no meter measures it)."""
    scaled_by = model.components[effect].model_class.share_of_host_parameters
    if not scaled_by or host is None:
        return False
    estimated = {(r.component, r.name) for r in model.estimated_parameters}
    return not any(p in host.mapped_parameters or (host.iri, p) in estimated for p in scaled_by)


def demotion_reasons(model: AssembledModel, node: str, theta: np.ndarray, effect_columns: list[int]) -> str:
    """Why the ranking puts the effect at ``node`` (its parameters at ``effect_columns`` of ``model``'s
    estimated parameters, fitted to ``theta``) below the plausible ones; empty when nothing does."""
    refs = model.estimated_parameters
    reasons = []
    host = _host(model, node, effect_columns)
    for j in effect_columns:
        spec = refs[j].spec
        side = at_bound(theta[j], spec)
        if side == "upper" and _share_of_assumed(model, host, refs[j].component):
            continue  # a share of a quantity no one stated or measured: its bound is no limit of the physics
        if side:
            bound = quantity_text(getattr(spec, side), spec.unit, "g")
            reasons.append(f"{refs[j].name} fits only at its {side} bound {bound}")
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
