"""Figures people would rather look at than read: measured vs model per sensor, and error history.

matplotlib with the non-interactive Agg backend (no display needed). Every ``*_figure`` function
returns the figure (tests read its axes and legend), every ``plot_*`` function writes it as one PNG
and returns the path. Legends sit outside the axes: a legend never covers data.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

from service.diagnosis.error_history import ErrorHistory  # noqa: E402
from service.graph.namespaces import local_name  # noqa: E402
from service.graph.units import bracketed_unit, difference_unit  # noqa: E402

__all__ = ["measured_vs_model_figure", "residuals_figure", "error_history_figure", "plot_measured_vs_model",
           "plot_residuals", "plot_error_history", "save_figure"]


def _finish_time_panels(fig: Figure, axes, title: str) -> Figure:
    """Legend right of the first of the stacked time-series panels (outside every axes: the layout
    narrows the panels to make room), the title above them all, dates slanted."""
    axes[0, 0].legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0, fontsize=8)
    if title:
        fig.suptitle(title, fontsize=10)
    fig.autofmt_xdate()
    fig.tight_layout()
    return fig


def save_figure(fig: Figure, path: Path | str, dpi: int = 110) -> Path:
    """``fig`` as a PNG at ``path`` (a path or a binary file object), closed."""
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    return path


def measured_vs_model_figure(
    timestamps: np.ndarray,
    observed: Mapping[str, np.ndarray],
    models: Mapping[str, Mapping[str, np.ndarray]],
    units: Mapping[str, str],
    intervals: Mapping[str, tuple[np.ndarray, np.ndarray]] | None = None,
    title: str = "",
    interval_level: float = 0.9,
    interval_label: str = "",
    left_out: np.ndarray | None = None,
) -> Figure:
    """One panel per sensor: the measurement and each named model prediction (e.g. ``before`` and
    ``after``), with the shaded interval where given, labelled ``interval_label`` (default: the
    ``interval_level`` prediction interval); the steps ``left_out`` (bool per step: an operating
    filter did not compare them) shaded light grey."""
    sensors = list(observed)
    fig, axes = plt.subplots(len(sensors), 1, figsize=(11, 2.2 * len(sensors)), sharex=True, squeeze=False)
    for ax, sensor in zip(axes[:, 0], sensors):
        if left_out is not None and left_out.any():
            ax.fill_between(timestamps, 0, 1, where=left_out, step="mid", transform=ax.get_xaxis_transform(),
                            color="0.85", lw=0, label="not compared (operating filter)")
        if intervals and sensor in intervals:
            low, high = intervals[sensor]
            ax.fill_between(timestamps, low, high, color="tab:blue", alpha=0.2,
                            label=interval_label or f"{100 * interval_level:.0f} % prediction interval")
        ax.plot(timestamps, observed[sensor], color="black", lw=0.8, label="measured")
        for (name, prediction), color in zip(models.items(), ("tab:red", "tab:green", "tab:blue")):
            ax.plot(timestamps, prediction[sensor], color=color, lw=1.0, label=name)
        ax.set_title(local_name(sensor), fontsize=8, loc="left")  # a long name as a y label ran into the next panel's
        ax.set_ylabel(bracketed_unit(units.get(sensor, '')), fontsize=8)
        ax.grid(alpha=0.3)
    return _finish_time_panels(fig, axes, title)


def plot_measured_vs_model(path: Path, *args, **kwargs) -> Path:
    """:func:`measured_vs_model_figure` saved as a PNG at ``path``."""
    return save_figure(measured_vs_model_figure(*args, **kwargs), Path(path))


def residuals_figure(
    timestamps: np.ndarray,
    residuals: Mapping[str, np.ndarray],
    units: Mapping[str, str],
    thresholds: Mapping[str, float],
    episodes: Mapping[str, list[tuple[object, object]]] | None = None,
    title: str = "",
) -> Figure:
    """One panel per sensor: the residual y − ŷ, the band ±``thresholds[sensor]`` within which the
    model counts as matching (the diagnosis' failure threshold), and each failure episode
    (start, end) shaded: where in time the model fails."""
    sensors = list(residuals)
    fig, axes = plt.subplots(len(sensors), 1, figsize=(11, 2.0 * len(sensors)), sharex=True, squeeze=False)
    for ax, sensor in zip(axes[:, 0], sensors):
        for start, end in (episodes or {}).get(sensor, []):
            ax.axvspan(np.datetime64(start), np.datetime64(end), color="tab:red", alpha=0.15, lw=0)
        band = thresholds.get(sensor, 0.0)
        ax.axhspan(-band, band, color="tab:green", alpha=0.15, lw=0, label="matching band")
        ax.axhline(0.0, color="grey", lw=0.6)
        ax.plot(timestamps, residuals[sensor], color="black", lw=0.8, label="measured − model")
        ax.set_title(local_name(sensor), fontsize=8, loc="left")  # a long name as a y label ran into the next panel's
        ax.set_ylabel(bracketed_unit(difference_unit(units.get(sensor, ''))), fontsize=8)  # a residual: K for °C
        ax.grid(alpha=0.3)
    return _finish_time_panels(fig, axes, title)


def plot_residuals(path: Path, *args, **kwargs) -> Path:
    """:func:`residuals_figure` saved as a PNG at ``path``."""
    return save_figure(residuals_figure(*args, **kwargs), Path(path))


def error_history_figure(history: ErrorHistory) -> Figure:
    """Test-window RMSE per sensor (one column each) across model versions: the error falling; with
    regimes, a second row with the RMSE per regime (numbered as the runs and the history's table
    number them), one bar per version, the versions' legend below every panel."""
    sensors, versions = list(history.rmse), history.versions
    rules = list(history.regime_rmse)
    rows = 2 if rules else 1
    fig, axes = plt.subplots(rows, len(sensors), figsize=(2.8 * len(sensors), 3.2 * rows), squeeze=False)
    colours = plt.get_cmap("tab10")
    base = versions[0].split("+", 1)[0]
    ticks = [("base" if v == base else v.removeprefix(base)).replace("+", "\n+").strip("\n") for v in versions]
    for ax, sensor in zip(axes[0], sensors):
        ax.bar(range(len(versions)), history.rmse[sensor], color=[colours(i) for i in range(len(versions))])
        ax.set_xticks(range(len(versions)), ticks, fontsize=7)
        ax.set_title(local_name(sensor), fontsize=8)
        ax.set_ylabel(f"test RMSE {bracketed_unit(history.units.get(sensor, ''))}".strip(), fontsize=8)
    if rules:
        width = 0.8 / len(versions)
        for ax, sensor in zip(axes[1], sensors):
            for i, version in enumerate(versions):
                values = [history.regime_rmse[rule].get(sensor, [np.nan] * len(versions))[i] for rule in rules]
                ax.bar(np.arange(len(rules)) + (i - (len(versions) - 1) / 2) * width, values, width,
                       color=colours(i), label=version)
            ax.set_xticks(range(len(rules)), [history.regime_number.get(rule, str(j)) for j, rule in enumerate(rules)],
                          fontsize=7)
            ax.set_xlabel("regime", fontsize=7)
            error_axis = bracketed_unit(history.units.get(sensor, ''))
            ax.set_ylabel(f"RMSE per regime {error_axis}".strip(), fontsize=8)
        handles, labels = axes[1][0].get_legend_handles_labels()
        fig.legend(handles, labels, loc="lower center", ncol=len(versions), fontsize=8, frameon=False)
    if not history.comparable:
        fig.suptitle("versions tested on different data, windows or filters: not comparable as they stand", fontsize=9, color="#b23b3b")
    fig.tight_layout(rect=(0, 0.06 if rules else 0, 1, 1))
    return fig


def plot_error_history(path: Path, history: ErrorHistory) -> Path:
    """:func:`error_history_figure` saved as a PNG at ``path``."""
    return save_figure(error_history_figure(history), Path(path))
