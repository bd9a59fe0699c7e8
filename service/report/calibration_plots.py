"""Figures of a calibration run: measured vs predicted with intervals, MCMC traces and a corner plot.

:func:`plot_calibration` is what ``graphtwin calibrate --plots DIR`` writes: the fit for every run
(:func:`service.report.plots.plot_measured_vs_model`), and for a Bayesian run the trace of every
parameter (every walker of the β = 1 chain, burn-in shaded) and the corner plot of the kept samples
(marginals with 16/50/84 % quantiles, pairwise 2-D histograms), in physical units. matplotlib with
the Agg backend; ``*_figure`` functions return the figure, ``plot_*`` save it and return the path.
More: ``docs/report.md``, "Figures".
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.ticker import MaxNLocator  # noqa: E402

from service.graph.units import bracketed_unit  # noqa: E402
from service.report.plots import plot_measured_vs_model  # noqa: E402

if TYPE_CHECKING:
    from service.calibration.run import CalibrationOutcome

__all__ = ["trace_figure", "corner_figure", "plot_trace", "plot_corner", "plot_calibration", "parameter_label"]

#: Interval drawn on the measured-vs-predicted figure of a Bayesian run.
FIT_INTERVAL_LEVEL = 0.9
#: Points drawn per walker on a trace panel.
TRACE_MAX_POINTS = 500
_DPI = 90


def parameter_label(key: str) -> str:
    """``…/component/HotWaterLoop/heating_coil_air_side#metal_time_constant`` → ``metal_time_constant
    (heating_coil_air_side)``; a key without ``#`` is returned unchanged."""
    if "#" not in key:
        return key
    path, name = key.rsplit("#", 1)
    return f"{name} ({path.rstrip('/').rsplit('/', 1)[-1]})"


def _save(fig: Figure, path: Path | str) -> Path:
    path = Path(path)
    fig.savefig(path, dpi=_DPI)
    plt.close(fig)
    return path


def trace_figure(chain: np.ndarray, names: Sequence[str], burn_in: int = 0) -> Figure:
    """One panel per parameter: every walker's value against the step.

    :param chain: ``ndarray[n_steps, n_walkers, n_parameters]`` (the β = 1 chain, burn-in included).
    :param names: one label per parameter (with its unit if wanted).
    :param burn_in: steps discarded as burn-in (shaded).

    A long chain is drawn at every ``ceil(n_steps / TRACE_MAX_POINTS)``-th step (what a page shows).
    :raises ValueError: for a chain that is not 3-D or names that do not match its last axis.
    """
    chain = np.asarray(chain, dtype=float)
    if chain.ndim != 3 or chain.shape[2] != len(names):
        raise ValueError(f"chain has shape {chain.shape}, expected (n_steps, n_walkers, {len(names)})")
    n_steps, _, n_par = chain.shape
    fig, axes = plt.subplots(n_par, 1, figsize=(9, 1.3 * n_par + 0.6), sharex=True, squeeze=False)
    stride = -(-n_steps // TRACE_MAX_POINTS)
    steps = np.arange(0, n_steps, stride)
    for j, ax in enumerate(axes[:, 0]):
        ax.plot(steps, chain[::stride, :, j], color="black", lw=0.4, alpha=0.3)
        if burn_in > 0:
            ax.axvspan(0, burn_in, color="tab:red", alpha=0.12, lw=0)
        ax.set_ylabel(names[j], fontsize=6, rotation=0, ha="right", va="center")
        ax.tick_params(labelsize=6)
    axes[-1, 0].set_xlabel("step (β = 1 chain; shaded: burn-in)", fontsize=8)
    fig.tight_layout()
    return fig


def corner_figure(
    samples: np.ndarray, names: Sequence[str], truth: np.ndarray | None = None, bins: int = 30
) -> Figure:
    """Marginals on the diagonal, pairwise 2-D histograms below it; ``n(n + 1)/2`` axes.

    :param samples: ``ndarray[n_samples, n_parameters]`` (burn-in discarded, thinned).
    :param names: one label per parameter.
    :param truth: ``ndarray[n_parameters]`` to mark (a synthetic truth), or None.
    :param bins: histogram bins per axis.
    :raises ValueError: for samples that are not 2-D or names that do not match them.
    """
    samples = np.asarray(samples, dtype=float)
    if samples.ndim != 2 or samples.shape[1] != len(names):
        raise ValueError(f"samples have shape {samples.shape}, expected (n_samples, {len(names)})")
    n_par = samples.shape[1]
    size = max(1.1 * n_par, 3.0)
    fig = plt.figure(figsize=(size, size))
    grid = fig.add_gridspec(n_par, n_par, hspace=0.08, wspace=0.08)
    ranges = []
    for j in range(n_par):
        lo, hi = np.min(samples[:, j]), np.max(samples[:, j])
        ranges.append((lo, hi) if hi > lo else (lo - 0.5 * abs(lo) - 1e-12, hi + 0.5 * abs(hi) + 1e-12))
    for row in range(n_par):
        for col in range(row + 1):
            ax = fig.add_subplot(grid[row, col])
            if row == col:
                ax.hist(samples[:, col], bins=bins, range=ranges[col], color="tab:blue", histtype="stepfilled", alpha=0.6)
                for q in np.quantile(samples[:, col], [0.16, 0.5, 0.84]):
                    ax.axvline(q, color="black", lw=0.6, ls="--")
                ax.set_yticks([])
            else:
                ax.hist2d(samples[:, col], samples[:, row], bins=bins, range=[ranges[col], ranges[row]], cmap="Blues")
                if truth is not None:
                    ax.axhline(truth[row], color="tab:red", lw=0.6)
            if truth is not None:
                ax.axvline(truth[col], color="tab:red", lw=0.6)
            ax.tick_params(labelsize=4)
            ax.xaxis.set_major_locator(MaxNLocator(3))
            if row != col:
                ax.yaxis.set_major_locator(MaxNLocator(3))
            if row == n_par - 1:
                ax.set_xlabel(names[col], fontsize=5)
            else:
                ax.set_xticklabels([])
            if col == 0 and row > 0:
                ax.set_ylabel(names[row], fontsize=5)
            elif col > 0:
                ax.set_yticklabels([])
    return fig


def plot_trace(path: Path | str, chain: np.ndarray, names: Sequence[str], burn_in: int = 0) -> Path:
    """:func:`trace_figure` saved as a PNG at ``path``."""
    return _save(trace_figure(chain, names, burn_in), path)


def plot_corner(path: Path | str, samples: np.ndarray, names: Sequence[str], truth: np.ndarray | None = None) -> Path:
    """:func:`corner_figure` saved as a PNG at ``path``."""
    return _save(corner_figure(samples, names, truth), path)


def plot_calibration(outcome: CalibrationOutcome, folder: Path | str, truth: np.ndarray | None = None) -> list[Path]:
    """Write the figures of a run to ``folder`` (created if needed), named ``<run id>-<figure>.png``.

    Always ``-fit.png`` (measured vs predicted on the test window when there is one, else the
    training window; with the 90 % predictive interval when the run has one); for a Bayesian run
    also ``-trace.png`` and ``-corner.png``.

    :param truth: θ of a synthetic truth to mark on the corner plot (physical units), or None.
    :returns: the paths written, in that order.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    record = outcome.record
    window_name = "test" if outcome.test is not None else "train"
    window = outcome.test if outcome.test is not None else outcome.train
    md = outcome.model_data
    intervals = {n: levels[FIT_INTERVAL_LEVEL] for n, levels in outcome.intervals.get(window_name, {}).items()}
    paths = [plot_measured_vs_model(
        folder / f"{record.run_id}-fit.png", md.data.timestamps[window], md.observed(window),
        {"model" if record.method == "point" else "posterior median": outcome.predictions[window_name]},
        md.units, intervals or None,
        title=f"{record.model_name} ({record.method}): {window_name} window", interval_level=FIT_INTERVAL_LEVEL,
    )]
    calibrator = outcome.calibrator
    if record.method == "bayes" and calibrator is not None:
        units = {e.key: e.unit for e in record.estimates}
        names = [f"{parameter_label(k)}\n{bracketed_unit(units.get(k, ''))}".strip() for k in calibrator.parameter_names_]
        n_theta = len(names)
        paths.append(plot_trace(folder / f"{record.run_id}-trace.png", calibrator.chain_[:, :, :n_theta], names,
                                calibrator.convergence_.burn_in))
        paths.append(plot_corner(folder / f"{record.run_id}-corner.png", calibrator.samples_, names, truth))
    return paths
