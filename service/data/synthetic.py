"""Synthetic measurements from a known truth, optionally with an effect the base model lacks.

The truth: the assembled model plus (optionally) one catalog effect at one building node; each
estimated parameter moved from its default 25 % of the way towards a seeded random bound, the
hidden effect's parameters at its signature's ``[extra.synthetic_truth]``. Simulated on the case
study's synthetic operation or a measurement file's boundary inputs (semi-synthetic), warmed up as
a calibration window is; Gaussian noise on every target (0.1 K on temperatures, 0.005 on positions,
1 % of the mean on powers and flows). Columns in each device's declared unit, named by its
``gt:timeSeriesId``. Details: ``docs/data.md``, *Synthetic data*.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from service.components.library import SignatureLibrary
from service.data.csv_output import write_csv
from service.data.model_series import device_unit, model_warmup_s, read_model_data, warmup_period_steps
from service.data.synthetic_operation import case_study_operation
from service.errors import InputError
from service.graph.store import GraphStore
from service.graph.units import convert
from service.matching.signature import Signature
from service.model.assembly import assemble
from service.model.effect_splicing import EffectRequest
from service.model.simulator import Simulator, loop_substeps, warmup_index
from service.model.wiring import without_model

__all__ = ["SyntheticTruth", "generate_synthetic_data", "NOISE_STD", "applicable_nodes"]

#: The synthetic operation starts this long before the data (a day of history the data does not show).
HISTORY_S = 86400.0
#: First time stamp of the synthetic data.
START = "2026-01-12T00:00:00"
#: Measurement noise standard deviation per simulator unit (relative for W and flows).
NOISE_STD = {"degC": 0.1, "1": 0.005}
_RELATIVE_NOISE = 0.01


@dataclass
class SyntheticTruth:
    """What generated the data: θ by parameter key, the hidden effect (or None) and where."""

    theta: dict[str, float]
    effect: str | None
    node: str | None
    path: Path


def applicable_nodes(store: GraphStore, model_name: str, signature: Signature) -> list[str]:
    """Building nodes where ``signature`` (an effect) can be added to ``model_name``'s base model."""
    from service.matching.matcher import match_signature

    nodes = sorted({m[signature.splice.node] for m in match_signature(
        store, signature, default_graph=store.matching_dataset(model_name)) if m.get(signature.splice.node)})
    usable = []
    for node in nodes:
        try:
            assemble(store, model_name, extra_effects=[EffectRequest(signature.id, node)])
        except ValueError:
            continue
        usable.append(node)
    return usable


def _truth_theta(model, model_name: str, effect: Signature | None, rng: np.random.Generator,
                 given: Mapping[str, float]) -> np.ndarray:
    values = []
    truth = (effect.extra.get("synthetic_truth", {}) if effect is not None else {})
    given = {without_model(key): value for key, value in given.items()}
    unknown = sorted(given.keys() - {without_model(ref.key) for ref in model.estimated_parameters})
    if unknown:
        raise InputError(f"the truth names parameters model {model_name} does not estimate: {', '.join(unknown)}")
    for ref in model.estimated_parameters:
        spec, part = ref.spec, without_model(ref.key)
        if part in given:
            values.append(float(given[part]))
            rng.random()  # the same draws for the others whatever is given
            continue
        if effect is not None and f"/{effect.id}/" in ref.component and spec.name in truth:
            values.append(float(truth[spec.name]))
            continue
        bound = spec.upper if rng.random() < 0.5 else spec.lower
        values.append(spec.default + 0.25 * (bound - spec.default))
    return np.array(values)


def generate_synthetic_data(
    store: GraphStore,
    model_name: str,
    output: Path,
    *,
    library: SignatureLibrary,
    hidden_effect: str | None = None,
    node: str | None = None,
    seed: int = 0,
    n_days: float = 7.0,
    step_s: float = 600.0,
    substeps: int | None = None,
    operation: Path | str | None = None,
    truth: Mapping[str, float] | None = None,
) -> SyntheticTruth:
    """Write a measurement CSV for ``model_name`` (columns named by the devices' time-series ids).

    :param hidden_effect: effect signature id hidden in the truth; None for a truth without one.
    :param node: where to put it (the first applicable node when None).
    :param operation: a measurement CSV of the model whose boundary inputs drive the truth (real
        operation: its time grid and its boundary columns as measured; ``n_days`` and ``step_s`` are
        then the file's). None: the case study's synthetic operation
        (:func:`service.data.synthetic_operation.case_study_operation`), after a day's warm-up.
    :param truth: parameter key → its value in the truth (a calibration's estimates, say; keys are
        matched without their model name, so a run of the same model under another name applies);
        the others are drawn as the module docstring says.
    :raises UnknownEffectError: an unknown effect; :raises InputError: one that does not apply to the model; a truth key that
        is no estimated parameter of the model (with the effect); synthetic operation of fewer than two
        steps.
    """
    if operation is None and n_days * 86400.0 < 2 * step_s:
        raise InputError(f"{n_days:g} days of data: give at least two steps of {step_s / 60:g} min "
                         f"({2 * step_s / 86400.0:.3g} days); a calibration needs more than its first six hours")
    effect = None
    requests = []
    if hidden_effect is not None:
        effect = library.effect(hidden_effect)
        nodes = applicable_nodes(store, model_name, effect)
        if not nodes:
            raise InputError(f"effect {hidden_effect} applies nowhere in model {model_name}")
        if node is None:
            node = nodes[0]
        elif node not in nodes:
            raise InputError(f"effect {hidden_effect} does not apply at {node}; it applies at {', '.join(nodes)}")
        requests = [EffectRequest(hidden_effect, node)]
    model = assemble(store, model_name, library=library, extra_effects=requests)
    rng = np.random.default_rng(seed)
    theta = _truth_theta(model, model_name, effect, rng, truth or {})
    if operation is None:
        history = int(round(HISTORY_S / step_s))
        synthetic = case_study_operation(n_days=n_days + HISTORY_S / 86400.0, step_s=step_s, seed=seed,
                                         start=str(np.datetime64(START) - np.timedelta64(int(HISTORY_S), "s")))
        timestamps, boundary = synthetic.timestamps, {}
        for component in model.boundary_inputs:
            link = model.measurement(component)
            if link.series_id not in synthetic.series:
                raise InputError(
                    f"the built-in synthetic operation (the case study's: {', '.join(sorted(synthetic.series))}) has no "
                    f"series for {link.node} ({link.series_id}): give this model's boundary inputs as measured in a "
                    "CSV (`graphtwin example generate --operation FILE`; data.md, the data contract)")
            boundary[component] = synthetic.series[link.series_id]
    else:
        measured = read_model_data(model, operation)
        history, timestamps, step_s = 0, measured.timestamps, measured.step_s
        boundary = {c: measured.series[model.measurement(c).node] for c in model.boundary_inputs}
    # warmed up as ModelData warms a window up: the first day repeated, then the history
    n_total = next(iter(boundary.values())).size
    warmup = history + int(round(model_warmup_s(model) / step_s))
    index = warmup_index(slice(history, n_total), warmup, warmup_period_steps(n_total, step_s))
    result = Simulator(model, step_s, substeps or loop_substeps(model, step_s)).run(
        {c: v[index] for c, v in boundary.items()}, theta[None, :], warmup_steps=warmup)
    boundary = {c: v[history:] for c, v in boundary.items()}
    columns = {}
    for component in model.boundary_inputs + model.targets:
        link = model.measurement(component)
        unit = device_unit(model, component)
        values = boundary.get(component)
        if values is None:
            clean = result.target(component)[0]
            sigma = NOISE_STD.get(unit, _RELATIVE_NOISE * float(np.nanmean(np.abs(clean))))
            values = clean + rng.normal(0.0, sigma, clean.size)
        columns[link.series_id] = convert(values, unit, link.unit, where=link.node)
    write_csv(output, timestamps[history:], columns)
    return SyntheticTruth(
        theta={ref.key: float(v) for ref, v in zip(model.estimated_parameters, theta)},
        effect=hidden_effect, node=node, path=Path(output),
    )
