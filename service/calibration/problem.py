"""The calibration problem: the one contract between a simulation model and the calibrators.

A :class:`CalibrationProblem` holds the names and physical prior bounds of θ, a vectorised
``simulate``: θ ``ndarray[n_ensemble, n_parameters]`` → ``{target: ndarray[n_ensemble, n_steps]}`` in
ONE call, the targets' measured series (NaN: not measured, masked out), their scales and optionally
the discrepancy GP's inputs. Residuals are divided by the target scale: unless given, the robust
range of the observations, (P95 − P5) / 3.29 (σ of a normal distribution; the standard deviation
when that range is 0), never below the unit's
instrument accuracy (:data:`INSTRUMENT_ACCURACY_FLOOR`, else 1 % of the mean magnitude).
Why: ``docs/calibration.md``, *The problem and its weights*.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import numpy as np

from service.errors import CalibrationError

__all__ = [
    "CalibrationProblem", "INSTRUMENT_ACCURACY_FLOOR", "RELATIVE_ACCURACY_FLOOR",
    "default_target_scale",
]

#: Smallest target scale per unit: the accuracy of a typical building-automation sensor
#: (a class-B Pt1000 at room temperature ±0.3 K, better sensors ±0.1 K; a position feedback ±1 %).
INSTRUMENT_ACCURACY_FLOOR: dict[str, float] = {"degC": 0.1, "K": 0.1, "1": 0.01}
#: Floor for units without an entry above, as a share of the mean absolute observed value
#: (power and flow meters are specified as ±1 % of reading).
RELATIVE_ACCURACY_FLOOR = 0.01

#: P95 − P5 of a normal distribution in standard deviations (2 × 1.6449).
NORMAL_P5_TO_P95 = 3.2897

Simulate = Callable[[np.ndarray], Mapping[str, np.ndarray]]


def default_target_scale(values: np.ndarray, unit: str = "", target: str = "") -> float:
    """Typical magnitude of a target's variation, used to weight its residuals (module docstring).

    :param values: the observed series, NaN where not measured.
    :param unit: the target's unit (``"degC"``, ``"1"``, ``"W"``, …), chooses the accuracy floor.
    :raises CalibrationError: when the series is constant at zero in a unit without an absolute floor.
    """
    finite = np.asarray(values, dtype=float)
    finite = finite[np.isfinite(finite)]
    low, high = np.percentile(finite, [5.0, 95.0])
    spread = float(high - low) / NORMAL_P5_TO_P95
    if spread == 0.0:
        spread = float(np.std(finite))
    floor = INSTRUMENT_ACCURACY_FLOOR.get(unit, RELATIVE_ACCURACY_FLOOR * float(np.mean(np.abs(finite))))
    scale = max(spread, floor)
    if not scale > 0.0:
        raise CalibrationError(
            f"target {target} is constant at 0 in the window and its unit {unit!r} has no accuracy "
            "floor, so its errors cannot be weighed: choose a window in which it reads something "
            "(calling the library: give its target_scales entry)"
        )
    return float(scale)


def _frozen(array: np.ndarray) -> np.ndarray:
    array = np.array(array, dtype=float)
    array.setflags(write=False)
    return array


@dataclass(frozen=True)
class CalibrationProblem:
    """Parameters to estimate, a vectorised simulator and the observations of the targets.

    :param parameter_names: names of the columns of θ.
    :param lower: physical lower prior bounds, ``ndarray[n_parameters]``, in the parameters' units.
    :param upper: physical upper prior bounds, strictly above ``lower``.
    :param simulate: θ ``ndarray[n_ensemble, n_parameters]`` → ``{target: ndarray[n_ensemble, n_steps]}``.
    :param observed: ``{target: ndarray[n_steps]}``, NaN where not measured.
    :param target_scales: ``{target: scale}`` in the target's unit; missing entries get
        :func:`default_target_scale`.
    :param gp_inputs: ``ndarray[n_steps, n_features]`` (or ``[n_steps]``) inputs of the discrepancy
        GP, e.g. time and boundary inputs; None lets the Bayesian calibrator use the time index.
    :param gp_input_names: one name per ``gp_inputs`` column (the GP's length scales are named by
        them); None: ``gp_input<j>``.
    :param units: ``{target: unit}`` (``"degC"``, ``"1"``, ``"W"``, …); missing entries are ``""``.
    :param default: a θ known to be plausible (the components' defaults), ``ndarray[n_parameters]``
        within the bounds; the point calibrator screens it with its start candidates.
    :param vectorised_simulate: a simulate call with a few dozen members costs about what one
        member costs (numpy over the ensemble); False when it steps each member on its own (an FMU).
    :raises ValueError: naming the parameter, target or array and the expected shape.
    :raises CalibrationError: no parameter, or a target without measurements in the window.
    """

    parameter_names: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray
    simulate: Simulate
    observed: Mapping[str, np.ndarray]
    target_scales: Mapping[str, float] = field(default_factory=dict)
    gp_inputs: np.ndarray | None = None
    gp_input_names: tuple[str, ...] | None = None
    units: Mapping[str, str] = field(default_factory=dict)
    default: np.ndarray | None = None
    vectorised_simulate: bool = True

    def __post_init__(self) -> None:
        names = tuple(self.parameter_names)
        if not names:
            raise CalibrationError("a calibration problem needs at least one parameter to estimate")
        duplicates = sorted({n for n in names if names.count(n) > 1})
        if duplicates:
            raise ValueError(f"duplicate parameter names: {', '.join(duplicates)}")
        object.__setattr__(self, "parameter_names", names)
        n_par = len(names)
        for label in ("lower", "upper"):
            bound = _frozen(getattr(self, label))
            if bound.shape != (n_par,):
                raise ValueError(f"{label} has shape {bound.shape}, expected ({n_par},): one per parameter")
            for name, value in zip(names, bound):
                if not np.isfinite(value):
                    raise ValueError(f"parameter {name}: {label} bound {value} is not finite")
            object.__setattr__(self, label, bound)
        for name, lo, hi in zip(names, self.lower, self.upper):
            if not lo < hi:
                raise ValueError(f"parameter {name}: lower bound {lo:g} is not below upper bound {hi:g}")
        if self.default is not None:
            default = _frozen(self.default)
            if default.shape != (n_par,):
                raise ValueError(f"default has shape {default.shape}, expected ({n_par},)")
            for name, value, lo, hi in zip(names, default, self.lower, self.upper):
                if not lo <= value <= hi:
                    raise ValueError(f"parameter {name}: default {value:g} outside bounds [{lo:g}, {hi:g}]")
            object.__setattr__(self, "default", default)
        self._set_observed()
        self._set_units_and_scales()
        self._set_gp_inputs()

    def _set_observed(self) -> None:
        if not self.observed:
            raise ValueError("a calibration problem needs at least one target with observations")
        observed: dict[str, np.ndarray] = {}
        n_steps = None
        for key, series in self.observed.items():
            values = _frozen(series)
            if values.ndim != 1:
                raise ValueError(f"observed[{key!r}] has shape {values.shape}, expected (n_steps,)")
            if n_steps is None:
                n_steps = values.shape[0]
            elif values.shape != (n_steps,):
                raise ValueError(
                    f"observed[{key!r}] has shape {values.shape}, expected ({n_steps},) like the first target"
                )
            if not np.isfinite(values).any():
                raise CalibrationError(f"target {key} has no measurements in the window")
            observed[key] = values
        object.__setattr__(self, "observed", observed)

    def _set_units_and_scales(self) -> None:
        for label in ("units", "target_scales"):
            unknown = sorted(set(getattr(self, label)) - set(self.observed))
            if unknown:
                raise ValueError(f"{label} names targets without observations: {', '.join(unknown)}")
        units = {key: str(self.units.get(key, "")) for key in self.observed}
        scales: dict[str, float] = {}
        for key, values in self.observed.items():
            if key in self.target_scales:
                scale = float(self.target_scales[key])
                if not (np.isfinite(scale) and scale > 0.0):
                    raise ValueError(f"target_scales[{key!r}] = {scale:g} must be positive and finite")
            else:
                scale = default_target_scale(values, units[key], key)
            scales[key] = scale
        object.__setattr__(self, "units", units)
        object.__setattr__(self, "target_scales", scales)

    def _set_gp_inputs(self) -> None:
        if self.gp_inputs is None:
            return
        inputs = np.array(self.gp_inputs, dtype=float)
        if inputs.ndim == 1:
            inputs = inputs[:, None]
        if inputs.ndim != 2 or inputs.shape[0] != self.n_steps:
            raise ValueError(
                f"gp_inputs has shape {np.shape(self.gp_inputs)}, expected ({self.n_steps}, n_features)"
            )
        bad_rows = np.flatnonzero(~np.isfinite(inputs).all(axis=1))
        if bad_rows.size:
            raise ValueError(f"gp_inputs is not finite in row {bad_rows[0]}")
        if self.gp_input_names is not None and len(self.gp_input_names) != inputs.shape[1]:
            raise ValueError(f"{len(self.gp_input_names)} gp_input_names for {inputs.shape[1]} gp_inputs columns")
        inputs.setflags(write=False)
        object.__setattr__(self, "gp_inputs", inputs)

    @property
    def n_parameters(self) -> int:
        return len(self.parameter_names)

    @property
    def target_keys(self) -> tuple[str, ...]:
        return tuple(self.observed)

    @property
    def n_steps(self) -> int:
        return next(iter(self.observed.values())).shape[0]

    @property
    def masks(self) -> dict[str, np.ndarray]:
        """``{target: bool[n_steps]}``: where the target was measured."""
        return {key: np.isfinite(values) for key, values in self.observed.items()}

    @property
    def n_observations(self) -> int:
        """Number of measured values over all targets (the n of the residual vector)."""
        return int(sum(mask.sum() for mask in self.masks.values()))

    def to_unit(self, theta: np.ndarray) -> np.ndarray:
        """Physical θ → the unit cube, ``(θ − lower) / (upper − lower)``."""
        return (np.asarray(theta, dtype=float) - self.lower) / (self.upper - self.lower)

    def from_unit(self, unit_theta: np.ndarray) -> np.ndarray:
        """The unit cube → physical θ."""
        return self.lower + np.asarray(unit_theta, dtype=float) * (self.upper - self.lower)

    def run(self, theta: np.ndarray) -> dict[str, np.ndarray]:
        """Simulate an ensemble in one call and check what comes back.

        :param theta: ``ndarray[n_ensemble, n_parameters]`` in physical units.
        :returns: ``{target: ndarray[n_ensemble, n_steps]}`` for every target.
        :raises ValueError: for θ or an output of the wrong shape, or a missing target.
        """
        theta = np.asarray(theta, dtype=float)
        if theta.ndim != 2 or theta.shape[1] != self.n_parameters:
            raise ValueError(f"theta has shape {theta.shape}, expected (n_ensemble, {self.n_parameters})")
        outputs = self.simulate(theta)
        checked: dict[str, np.ndarray] = {}
        expected = (theta.shape[0], self.n_steps)
        for key in self.observed:
            if key not in outputs:
                raise ValueError(f"simulate returned no output for target {key!r}")
            values = np.asarray(outputs[key], dtype=float)
            if values.shape != expected:
                raise ValueError(f"simulate output for target {key!r} has shape {values.shape}, expected {expected}")
            checked[key] = values
        return checked

    def weighted_residuals(self, outputs: Mapping[str, np.ndarray]) -> np.ndarray:
        """``(y − ŷ) / scale`` at the measured points, targets concatenated in order.

        :param outputs: ``{target: ndarray[n_ensemble, n_steps]}`` from :meth:`run`.
        :returns: ``ndarray[n_ensemble, n_observations]``.
        """
        masks = self.masks
        return np.concatenate(
            [
                (self.observed[key][masks[key]] - outputs[key][:, masks[key]]) / self.target_scales[key]
                for key in self.observed
            ],
            axis=1,
        )
