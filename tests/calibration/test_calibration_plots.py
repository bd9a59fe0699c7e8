"""Trace and corner figures show what they claim: one panel per parameter, every walker, the burn-in,
the quantiles and the correlation ridge; the PNGs decode at the size the figure asks for."""

from __future__ import annotations

import matplotlib.image
import numpy as np
import pytest
from matplotlib.collections import QuadMesh

from service.report.calibration_plots import corner_figure, parameter_label, plot_corner, plot_trace, trace_figure

NAMES = ("UA [W/K]", "C [J/K]", "P [W]")


def correlated_samples(n: int = 4000, rho: float = 0.99, seed: int = 0) -> np.ndarray:
    """Three parameters; the first two correlated with ``rho``, the third independent."""
    rng = np.random.default_rng(seed)
    a, b, c = rng.standard_normal((3, n))
    return np.column_stack([200.0 + 10.0 * a, 4e6 + 1e5 * (rho * a + np.sqrt(1 - rho**2) * b), 5000.0 + 50.0 * c])


def test_trace_has_one_panel_per_parameter_with_every_walker_and_the_burn_in():
    rng = np.random.default_rng(1)
    chain = np.cumsum(rng.standard_normal((120, 10, 3)), axis=0)
    fig = trace_figure(chain, NAMES, burn_in=30)
    assert len(fig.axes) == 3
    for j, ax in enumerate(fig.axes):
        assert len(ax.lines) == 10  # one per walker
        np.testing.assert_array_equal(ax.lines[4].get_ydata(), chain[:, 4, j])
        (shaded,) = ax.patches  # the burn-in, steps 0 … 30
        assert shaded.get_x() == 0 and shaded.get_width() == 30
        assert ax.get_ylabel() == NAMES[j]
    with pytest.raises(ValueError, match=r"chain has shape \(120, 10, 3\), expected \(n_steps, n_walkers, 2\)"):
        trace_figure(chain, NAMES[:2])


def test_corner_has_the_lower_triangle_the_quantiles_the_truth_and_the_ridge():
    samples = correlated_samples()
    truth = np.array([200.0, 4e6, 5000.0])
    fig = corner_figure(samples, NAMES, truth=truth)
    assert len(fig.axes) == 6  # n (n + 1) / 2
    diagonal = [fig.axes[0], fig.axes[2], fig.axes[5]]  # row by row: (0,0), (1,0), (1,1), (2,0), (2,1), (2,2)
    for j, ax in enumerate(diagonal):
        dashed = sorted(line.get_xdata()[0] for line in ax.lines if line.get_linestyle() == "--")
        np.testing.assert_allclose(dashed, np.quantile(samples[:, j], [0.16, 0.5, 0.84]))
        truth_lines = [line.get_xdata()[0] for line in ax.lines if line.get_linestyle() == "-"]
        assert truth_lines == [truth[j]]
    # the correlated pair (C against UA) concentrates on the diagonal of its 2-D histogram,
    # the independent pair (P against UA) does not
    def diagonal_share(ax):
        counts = next(c for c in ax.collections if isinstance(c, QuadMesh)).get_array().reshape(30, 30)
        i, j = np.indices(counts.shape)
        return counts[np.abs(i - j) <= 3].sum() / counts.sum()

    assert diagonal_share(fig.axes[1]) > 0.9
    assert diagonal_share(fig.axes[3]) < 0.5
    assert fig.axes[3].get_xlabel() == NAMES[0] and fig.axes[3].get_ylabel() == NAMES[2]


def test_plots_are_written_as_decodable_pngs(tmp_path):
    samples = correlated_samples(n=500)
    corner = plot_corner(tmp_path / "corner.png", samples, NAMES)
    trace = plot_trace(tmp_path / "trace.png", samples.reshape(50, 10, 3), NAMES, burn_in=5)
    for path in (corner, trace):
        image = matplotlib.image.imread(path)
        assert image.ndim == 3 and image.shape[0] > 200 and image.shape[1] > 200
        assert image[..., :3].std() > 0.05  # not a blank canvas


def test_parameter_labels_name_the_parameter_and_its_component():
    key = "https://w3id.org/graphtwin/resource/model/case/component/HotWaterLoop/heating_coil_air_side#metal_time_constant"
    assert parameter_label(key) == "metal_time_constant (heating_coil_air_side)"
    assert parameter_label("UA") == "UA"
