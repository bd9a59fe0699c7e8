"""What a calibration run produced, in a shape that is written as triples and printed as JSON.

A :class:`CalibrationRecord` is independent of how the estimate was made (point or Bayesian): every
estimated parameter gets a median and a 16–84 % interval (the Bayesian posterior quantiles, or for a
point fit θ̂ ± one standard error of the Jacobian covariance, clipped to the prior bounds), a MAP
(the posterior mode, or θ̂), and the identifiability verdict; every target gets its metrics on the
training window and, when given, the test window, and there per operating regime. A Bayesian run
with a test window also keeps every target's posterior predictive band there (:class:`PredictiveBand`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from datetime import datetime

import numpy as np

from service.calibration.metrics import TargetMetrics
from service.calibration.model_data import ModelData, gp_input_name
from service.graph.units import difference_unit
from service.model.assembled_model import AssembledModel

__all__ = ["ParameterEstimate", "SamplerConvergence", "CalibrationDiagnostics", "CalibrationRecord", "PredictiveBand",
           "PREDICTIVE_BAND_LEVEL", "parameter_estimates", "discrepancy_table"]

#: Two-sided level of the posterior predictive band a Bayesian run keeps (its 5–95 % quantiles).
PREDICTIVE_BAND_LEVEL = 0.9


@dataclass(frozen=True)
class ParameterEstimate:
    """One estimated parameter (physical unit ``unit``) of the component ``component`` that
    represents building node ``node``."""

    key: str
    name: str
    component: str
    node: str
    unit: str
    lower: float
    upper: float
    median: float
    quantile16: float
    quantile84: float
    map: float
    standard_error: float
    identified: bool
    reasons: tuple[str, ...] = ()

    def to_dict(self) -> dict:
        return {
            "name": self.name, "component": self.component, "node": self.node, "unit": self.unit,
            "median": self.median, "quantile16": self.quantile16, "quantile84": self.quantile84,
            "map": self.map, "standard_error": self.standard_error, "lower": self.lower, "upper": self.upper,
            "identified": self.identified, "reasons": list(self.reasons),
        }


def parameter_estimates(model: AssembledModel, theta, q16, q84, theta_map, se, verdicts) -> list[ParameterEstimate]:
    """One :class:`ParameterEstimate` per estimated parameter of ``model`` (θ's columns): median,
    16/84 % quantiles, MAP and standard error, and the identifiability verdict (``verdicts`` by key)."""
    estimates = []
    for j, ref in enumerate(model.estimated_parameters):
        verdict = verdicts.get(ref.key)
        estimates.append(ParameterEstimate(
            key=ref.key, name=ref.name, component=ref.component, node=model.components[ref.component].node,
            unit=ref.spec.unit, lower=ref.spec.lower, upper=ref.spec.upper, median=float(theta[j]),
            quantile16=float(q16[j]), quantile84=float(q84[j]), map=float(theta_map[j]), standard_error=float(se[j]),
            identified=bool(verdict.identified) if verdict is not None else True,
            reasons=tuple(verdict.reasons) if verdict is not None else (),
        ))
    return estimates


def discrepancy_table(quantiles: Mapping[str, Mapping[str, np.ndarray]], md: ModelData,
                      gp_nodes: Sequence[str]) -> dict[str, dict[str, tuple[float, float, float, str]]]:
    """A Bayesian run's discrepancy GP per target, ``name → (median, q16, q84, unit)``: its amplitude σ_f
    and noise σ_n in the target's difference unit (K for °C), each length scale in its input's unit (h
    for time, the port unit of a boundary input). ``quantiles``: ``BayesianCalibrator.discrepancy_``."""
    unit_of = {gp_input_name(node): "h" if node == "time" else md.data.units[node] for node in gp_nodes}
    table = {}
    for target, entries in quantiles.items():
        error_unit = difference_unit(md.units[target])
        table[target] = {name: (float(q[1]), float(q[0]), float(q[2]),
                                unit_of.get(name.partition(":")[2], error_unit) if ":" in name else error_unit)
                         for name, q in entries.items()}
    return table


@dataclass(frozen=True)
class SamplerConvergence:
    """How the Bayesian sampler's β = 1 chain ended: ``converged`` by the 20 × IAT rule, ``iat`` the
    integrated autocorrelation time [steps], ``n_steps`` sampled, ``acceptance`` the fraction of
    proposals accepted."""

    converged: bool
    iat: float
    n_steps: int
    acceptance: float

    def describe(self) -> str:
        """How it ended, in words: the chain's length in IATs says how far to trust it."""
        length = (f"{self.n_steps / self.iat:.0f} × its IAT of {self.iat:.0f} steps, 20 × needed"
                  if np.isfinite(self.iat) else "IAT unknown")
        return (f"{'converged' if self.converged else 'NOT converged'} after {self.n_steps} steps ({length}; "
                f"acceptance {self.acceptance:.2f})")


@dataclass
class CalibrationDiagnostics:
    """What a run noticed beside its estimates: data, model and window ``warnings`` (sentences), the
    ``start`` note of a fit started from another model's calibration, the point fit's least-squares
    ``cost`` (½ Σ weighted r²), and the Bayesian ``sampler``'s convergence; None: not of this run."""

    warnings: list[str] = field(default_factory=list)
    start: str | None = None
    cost: float | None = None
    sampler: SamplerConvergence | None = None

    def to_dict(self) -> dict:
        """``{"warnings", "start"?, "cost"?, "converged"?, "iat"?, "n_steps"?, "acceptance"?}``: a key
        only where the run has the value."""
        result: dict = {"warnings": list(self.warnings)}
        if self.start is not None:
            result["start"] = self.start
        if self.cost is not None:
            result["cost"] = self.cost
        if self.sampler is not None:
            result.update(converged=self.sampler.converged, iat=self.sampler.iat,
                          n_steps=self.sampler.n_steps, acceptance=self.sampler.acceptance)
        return result


@dataclass(frozen=True)
class PredictiveBand:
    """The posterior predictive's central ``level`` interval of one target on ``window`` (``"test"``):
    ``lower`` and ``upper`` at every step of the window, ``ndarray[n_steps]`` in the target's unit
    (NaN where nothing was predicted). Model at posterior draws + GP discrepancy + noise."""

    window: str
    level: float
    lower: np.ndarray
    upper: np.ndarray


@dataclass
class CalibrationRecord:
    """A finished calibration: provenance, estimates and metrics (``metrics[window][target node]``)."""

    run_id: str
    model_name: str
    model_version: str
    method: str
    seed: int | None
    data_source: str
    train_window: tuple[datetime, datetime]
    test_window: tuple[datetime, datetime] | None
    started: datetime
    finished: datetime
    settings: dict
    estimates: list[ParameterEstimate]
    metrics: dict[str, dict[str, TargetMetrics]] = field(default_factory=dict)
    diagnostics: CalibrationDiagnostics = field(default_factory=CalibrationDiagnostics)
    #: Test-window error per operating regime (:meth:`service.calibration.regime_breakdown.RegimeBreakdown.rows`).
    regimes: list[dict] = field(default_factory=list)
    regime_rule_accuracy: float = float("nan")
    #: Target node → its posterior predictive band (a Bayesian run with a test window; series, not in ``to_dict``).
    predictive_bands: dict[str, PredictiveBand] = field(default_factory=dict)
    #: A Bayesian run's discrepancy GP per target node (:func:`discrepancy_table`).
    discrepancy: dict[str, dict[str, tuple[float, float, float, str]]] = field(default_factory=dict)

    def to_dict(self) -> dict:
        return {
            "run_id": self.run_id, "model": self.model_name, "model_version": self.model_version,
            "method": self.method, "seed": self.seed, "data": self.data_source,
            "train": [t.isoformat() for t in self.train_window],
            "test": [t.isoformat() for t in self.test_window] if self.test_window else None,
            "started": self.started.isoformat(), "finished": self.finished.isoformat(),
            "settings": self.settings,
            "parameters": {e.key: e.to_dict() for e in self.estimates},
            "metrics": {w: {t: m.to_dict() for t, m in per.items()} for w, per in self.metrics.items()},
            "diagnostics": self.diagnostics.to_dict(),
            "regimes": self.regimes, "regime_rule_accuracy": self.regime_rule_accuracy,
            **({"discrepancy": {target: {name: {"median": v[0], "quantile16": v[1], "quantile84": v[2], "unit": v[3]}
                                         for name, v in entries.items()}
                                for target, entries in self.discrepancy.items()}} if self.discrepancy else {}),
        }
