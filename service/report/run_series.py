"""A run's measured and modelled series, recomputed: a run stores numbers, not series.

The model graph (its version still the run's ``gt:modelVersion``) is assembled again, the run's data
file read, and the model simulated at the stored estimates (``gt:median``) over the stored windows
with the stored sub-steps, as :func:`service.calibration.run.predict_test` does. The band of a
Bayesian run is its stored posterior predictive band (model at posterior draws + GP discrepancy +
noise, 5–95 %); of a point fit, or a run that stores none, the ``INTERVAL_LEVEL`` prediction
interval of independent normal residuals with the training window's stored RMSE s: ŷ ± z·s
(z₀.₉₅ = 1.645 for 90 %). A recomputed RMSE more than ``REPRODUCTION_TOLERANCE`` from the stored one
is noted.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from statistics import NormalDist

import numpy as np

from service.calibration.model_data import ModelData
from service.calibration.run import model_version, predict_test
from service.data.model_series import read_model_data
from service.data.operating_filter import operating_mask
from service.errors import InputError
from service.graph.namespaces import local_name
from service.graph.store import GraphStore
from service.model.assembly import assemble
from service.report.stored_run import StoredRun

__all__ = ["RunSeries", "recompute_series", "data_file_locator", "INTERVAL_LEVEL", "INTERVAL_Z",
           "REPRODUCTION_TOLERANCE"]

#: Two-sided level of the prediction interval drawn around the model.
INTERVAL_LEVEL = 0.90
#: Standard normal quantile of the interval's upper end (1.645 for 90 %).
INTERVAL_Z = NormalDist().inv_cdf(0.5 + INTERVAL_LEVEL / 2)
#: Relative difference between the recomputed and the stored test RMSE above which the page warns.
REPRODUCTION_TOLERANCE = 0.01


@dataclass
class RunSeries:
    """Measured and modelled series of one window (``window`` is ``"test"`` or ``"train"``), each
    target node's interval ``band[node] = (low, high)`` (the stored posterior predictive band when
    ``posterior_band``, else ŷ ± z·s), the recomputed RMSE, and ``notes``; ``logged_units`` the unit
    each column was logged in (where the data file gives one), ``compared`` the window's steps the run's
    operating filter (``only_when``) kept."""

    window: str
    timestamps: np.ndarray
    observed: dict[str, np.ndarray]
    predicted: dict[str, np.ndarray]
    band: dict[str, tuple[np.ndarray, np.ndarray]]
    rmse: dict[str, float]
    units: dict[str, str]
    notes: list[str] = field(default_factory=list)
    posterior_band: bool = False
    logged_units: dict[str, str] = field(default_factory=dict)
    compared: np.ndarray | None = None


def recompute_series(store: GraphStore, run: StoredRun, data_path: Path) -> RunSeries:
    """Simulate the run's model at its stored estimates over its test window (else its training
    window), the test window as the continuation of the training run.

    :raises ValueError: the model graph changed since the run, an estimate is missing, or the data
        do not cover the run's windows (each message says which).
    """
    if not store.has_model(run.model):
        raise InputError(f"model {run.model} is no longer in the store: the run's series cannot be simulated again")
    current = model_version(store, run.model)
    if current != run.version:
        raise InputError(f"model {run.model} is now version {current}, the run calibrated version {run.version}: "
                         "its series cannot be recomputed")
    model = assemble(store, run.model)
    data = read_model_data(model, data_path)
    compared = operating_mask(data, run.settings.get("only_when", []))
    md = ModelData(model, data, int(run.settings["substeps"]), compared,
                   warmup_s=run.settings.get("warmup_s", 0.0))  # a run stored before warm-ups was simulated cold
    missing = [ref.key for ref in model.estimated_parameters if ref.key not in run.estimates]
    if missing:
        raise InputError(f"run {run.run_id} stores no estimate of {', '.join(missing)}")
    theta = np.array([run.estimates[ref.key].median for ref in model.estimated_parameters])
    train = data.window(*run.train)
    if run.test is not None:
        name, window = "test", data.window(*run.test)
        predicted = predict_test(md, train, window, theta)
    else:
        name, window = "train", train
        predicted = {node: values[0] for node, values in md.simulate_targets(train, theta[None, :]).items()}
    observed = {node: np.where(np.isfinite(predicted[node]), values, np.nan)
                for node, values in md.observed(window).items()}
    stored_bands = {node: b for node, b in run.bands.items() if b.window == name}
    posterior = bool(stored_bands) and set(predicted) <= set(stored_bands)
    band, rmse, notes = {}, {}, []
    for node, values in predicted.items():
        if posterior:
            band[node] = stored_bands[node].at_every_step(values.size)
        else:
            s = run.metrics.get("train", {}).get(node, {}).get("rmse", float("nan"))
            band[node] = (values - INTERVAL_Z * s, values + INTERVAL_Z * s)
        finite = np.isfinite(observed[node]) & np.isfinite(values)
        rmse[node] = float(np.sqrt(np.mean((observed[node][finite] - values[finite]) ** 2)))
        stored = run.metrics.get(name, {}).get(node, {}).get("rmse")
        if stored is not None and abs(rmse[node] - stored) > REPRODUCTION_TOLERANCE * stored:
            notes.append(f"{local_name(node)}: the recomputed {name} RMSE {rmse[node]:.4g} differs from the stored "
                         f"{stored:.4g}" + (" (a Bayesian run stores the predictive median's error; the figure "
                                            "simulates the posterior median parameters)" if run.method == "bayes"
                                            else ": the data file is not the one the run used"))
    return RunSeries(name, data.timestamps[window], observed, predicted, band, rmse, dict(md.units), notes, posterior,
                     dict(data.source_units), compared[window])


def data_file_locator(explicit: Path | None = None, folder: Path | None = None) -> Callable[[str], Path]:
    """For the command line: ``explicit`` when given, else the run's recorded file name in ``folder``
    (the current folder by default). The locator raises FileNotFoundError naming what it tried."""

    def locate(source: str) -> Path:
        path = explicit if explicit is not None else (folder or Path.cwd()) / Path(source).name
        if not path.is_file():
            raise FileNotFoundError(f"{path}: no such file (the run used {source!r}; give its path with --data)")
        return path

    return locate
