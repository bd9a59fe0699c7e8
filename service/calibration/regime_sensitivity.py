"""Morris elementary-effects sensitivity per operating regime, and the successive calibration plan.

One SALib Morris design (``problem = {"num_vars", "names", "bounds"}``), ONE vectorised simulate
call for all trajectories, then ``SALib.analyze.morris.analyze`` per regime r on its scalar measure
``Y_r``: the RMSE ``sqrt(mean_{t ∈ r} (y(t) − y_obs(t))²)`` over its measured steps, or the mean
output; for a calibration problem the RMS weighted residual of all targets,
``sqrt(mean_{k, t ∈ r} ((y_k(t) − ŷ_k(t)) / s_k)²)``. Regimes compare by each μ*'s share of the
regime's total, ``s[r, i] = μ*[r, i] / Σ_j μ*[r, j]``. Sources: Morris (1991), Technometrics
33(2):161–174; Campolongo, Cariboni & Saltelli (2007). Method: ``docs/calibration.md``.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from SALib.analyze import morris as morris_analyze
from SALib.sample import morris as morris_sample

from service.calibration.model_data import ModelData
from service.calibration.problem import CalibrationProblem
from service.errors import CalibrationError

__all__ = [
    "RegimeSensitivity", "morris_by_regime", "calibration_morris_by_regime", "successive_calibration_plan",
    "dominant_parameters_by_regime",
]


@dataclass(frozen=True)
class RegimeSensitivity:
    """Morris statistics per regime: rows are ``regimes``, columns ``names``.

    ``mu_star``, ``mu_star_conf`` (bootstrap half-width at 95 %), ``sigma`` and ``mu`` are
    ``ndarray[n_regimes, n_parameters]`` in the unit of the regime measure; ``n_steps[r]`` is the
    number of steps the regime's measure averaged over; ``measure`` is ``"rmse"`` or ``"mean output"``.
    A regime without a usable step has NaN rows.
    """

    names: list[str]
    regimes: list[int]
    mu_star: np.ndarray
    mu_star_conf: np.ndarray
    sigma: np.ndarray
    mu: np.ndarray
    n_steps: list[int]
    measure: str

    def _row(self, regime: int) -> int:
        if regime not in self.regimes:
            raise KeyError(f"regime {regime} is not among the analysed regimes {self.regimes}")
        return self.regimes.index(regime)

    def normalised_mu_star(self) -> np.ndarray:
        """``s[r, i] = μ*[r, i] / Σ_j μ*[r, j]`` (0 for a regime whose measure never moves, NaN rows kept)."""
        totals = self.mu_star.sum(axis=1, keepdims=True)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(totals > 0, self.mu_star / totals, np.where(np.isnan(totals), np.nan, 0.0))

    def dominant_parameters(self, regime: int, threshold: float = 0.1) -> list[str]:
        """Parameters holding at least ``threshold`` of the regime's total μ*, most influential first."""
        share = self.normalised_mu_star()[self._row(regime)]
        order = np.argsort(-np.nan_to_num(share, nan=-1.0), kind="stable")
        return [self.names[i] for i in order if share[i] >= threshold]

    def ranking(self, regime: int, top: int | None = None) -> list[dict]:
        """The regime's parameters by decreasing μ*: ``{"parameter", "mu_star", "mu_star_conf", "sigma",
        "share"}`` each (``share`` = normalised μ*); the ``top`` first, or all."""
        row = self._row(regime)
        shares = self.normalised_mu_star()[row]
        order = np.argsort(-np.nan_to_num(self.mu_star[row], nan=-1.0), kind="stable")[:top]
        return [{"parameter": self.names[i], "mu_star": float(self.mu_star[row, i]),
                 "mu_star_conf": float(self.mu_star_conf[row, i]), "sigma": float(self.sigma[row, i]),
                 "share": float(shares[i])} for i in order]

    def table(self) -> str:
        """Readable μ* table: one line per parameter, per regime ``μ* (share %)``."""
        shares = self.normalised_mu_star()
        labels = [_readable(n) for n in self.names]
        width = max(len(n) for n in labels + ["parameter"])
        header = f"{'parameter':<{width}}" + "".join(
            f"  {f'regime {r} (n={n})':>22}" for r, n in zip(self.regimes, self.n_steps))
        lines = [f"Morris μ* of the {self.measure} per regime (share of the regime's total μ*)", header]
        for i, name in enumerate(labels):
            cells = "".join(f"  {f'{self.mu_star[r, i]:.3g} ({100 * shares[r, i]:.0f} %)':>22}"
                            for r in range(len(self.regimes)))
            lines.append(f"{name:<{width}}{cells}")
        return "\n".join(lines)

    def to_dict(self) -> dict:
        return {"names": self.names, "regimes": self.regimes, "measure": self.measure, "n_steps": self.n_steps,
                "mu_star": self.mu_star.tolist(), "mu_star_conf": self.mu_star_conf.tolist(),
                "sigma": self.sigma.tolist(), "mu": self.mu.tolist()}


def _readable(name: str) -> str:
    """A parameter key ``…/component/Fan/supply_fan#c3`` as ``supply_fan.c3``; other names unchanged."""
    return name.rsplit("/", 1)[-1].replace("#", ".")


def _check_problem(problem: Mapping) -> None:
    missing = {"num_vars", "names", "bounds"} - set(problem)
    if missing:
        raise ValueError(f"problem lacks {sorted(missing)}: expected SALib's {{'num_vars', 'names', 'bounds'}}")
    if not (problem["num_vars"] == len(problem["names"]) == len(problem["bounds"])):
        raise ValueError(f"problem has num_vars={problem['num_vars']}, {len(problem['names'])} names and "
                         f"{len(problem['bounds'])} bounds: they must agree")
    for name, (low, high) in zip(problem["names"], problem["bounds"]):
        if not low < high:
            raise ValueError(f"parameter {name!r} has bounds [{low}, {high}]: the lower must be below the upper")


def morris_by_regime(
    problem: Mapping,
    simulate: Callable[[np.ndarray], np.ndarray],
    labels: np.ndarray,
    observed: np.ndarray | None = None,
    *,
    n_trajectories: int = 20,
    num_levels: int = 4,
    seed: int | None = None,
) -> RegimeSensitivity:
    """Morris μ*, σ per regime from one vectorised ensemble run (module docstring).

    :param problem: SALib problem ``{"num_vars", "names", "bounds"}``.
    :param simulate: ``simulate(X: ndarray[n_samples, num_vars]) -> ndarray[n_samples, n_t]``, the
        target output over time for every parameter set, called once.
    :param labels: ``ndarray[n_t]`` regime per step (−1: left out).
    :param observed: ``ndarray[n_t]`` measured target (NaN: not measured) for the RMSE measure, or
        None for the mean-output measure.
    :param n_trajectories: Morris trajectories N (``N·(num_vars + 1)`` model runs).
    :param num_levels: grid levels p of the Morris design.
    :param seed: seed of the design and of the bootstrap confidence intervals.
    """
    _check_problem(problem)
    labels = np.asarray(labels)
    X = morris_sample.sample(dict(problem), n_trajectories, num_levels=num_levels, seed=seed)
    Y = np.asarray(simulate(X), dtype=float)
    if Y.shape != (len(X), len(labels)):
        raise ValueError(f"simulate returned shape {Y.shape}, expected ({len(X)}, {len(labels)}): "
                         "one row per parameter set, one column per labelled step")
    usable = labels >= 0
    if observed is not None:
        observed = np.asarray(observed, dtype=float)
        if observed.shape != labels.shape:
            raise ValueError(f"observed has shape {observed.shape}, labels {labels.shape}: they must agree")
        usable &= np.isfinite(observed)
    regimes = [int(r) for r in np.unique(labels[labels >= 0])]
    n_par = problem["num_vars"]
    stats = {key: np.full((len(regimes), n_par), np.nan) for key in ("mu_star", "mu_star_conf", "sigma", "mu")}
    n_steps = []
    for row, regime in enumerate(regimes):
        steps = usable & (labels == regime)
        n_steps.append(int(steps.sum()))
        if not steps.any():
            continue
        if observed is None:
            measure = Y[:, steps].mean(axis=1)
        else:
            measure = np.sqrt(np.mean((Y[:, steps] - observed[steps]) ** 2, axis=1))
        if not np.isfinite(measure).all():
            raise CalibrationError(f"the simulation gives non-finite values in regime {regime}: "
                                   f"{int((~np.isfinite(measure)).sum())} of {len(measure)} parameter sets")
        result = morris_analyze.analyze(dict(problem), X, measure, num_levels=num_levels, seed=seed)
        for key in stats:
            stats[key][row] = np.asarray(result[key], dtype=float)
    return RegimeSensitivity(
        names=list(problem["names"]), regimes=regimes, n_steps=n_steps,
        measure="rmse" if observed is not None else "mean output", **stats,
    )


def calibration_morris_by_regime(
    problem: CalibrationProblem,
    labels: np.ndarray,
    *,
    targets: Sequence[str] | None = None,
    n_trajectories: int = 10,
    num_levels: int = 4,
    seed: int | None = None,
) -> RegimeSensitivity:
    """Morris per regime of a calibration problem's weighted RMS residual (module docstring).

    The design spans the problem's prior bounds; the whole design is ONE ``problem.run`` call.
    ``n_steps`` of the result counts measured values (targets × steps) per regime.

    :param problem: the calibration problem (its observations and target scales are used).
    :param labels: ``ndarray[problem.n_steps]`` regime per step of the problem (−1: left out).
    :param targets: the targets whose residuals form the measure (default all).
    """
    labels = np.asarray(labels)
    if labels.shape != (problem.n_steps,):
        raise ValueError(f"labels have shape {labels.shape}, expected ({problem.n_steps},): one per problem step")
    keys = list(problem.target_keys if targets is None else targets)
    unknown = sorted(set(keys) - set(problem.target_keys))
    if unknown or not keys:
        raise ValueError(f"unknown targets {unknown}: the problem has {list(problem.target_keys)}")
    scales = problem.target_scales
    spec = {"num_vars": problem.n_parameters, "names": list(problem.parameter_names),
            "bounds": [[lo, hi] for lo, hi in zip(problem.lower, problem.upper)]}

    def stacked(theta: np.ndarray) -> np.ndarray:
        outputs = problem.run(theta)
        return np.concatenate([outputs[k] / scales[k] for k in keys], axis=1)

    observed = np.concatenate([problem.observed[k] / scales[k] for k in keys])
    return morris_by_regime(spec, stacked, np.tile(labels, len(keys)), observed,
                            n_trajectories=n_trajectories, num_levels=num_levels, seed=seed)


def dominant_parameters_by_regime(
    model_data: ModelData,
    window: slice,
    labels: np.ndarray,
    *,
    n_regimes: int | None = None,
    top: int = 3,
    n_trajectories: int = 10,
    seed: int | None = 0,
    settling_s: float | None = None,
) -> list[list[dict]]:
    """Per regime, the ``top`` parameters that move the model's misfit most there (Morris μ*).

    The measure is :func:`calibration_morris_by_regime` on the calibration problem of ``window``
    (all targets, the first ``settling_s`` not compared; None: ``ModelData.unscored_start_s``); one ensemble run of
    ``n_trajectories · (n_parameters + 1)`` members.

    :param labels: ``ndarray[window length]`` regime per step of the window (−1: left out), e.g.
        ``OperatingRegimes.predict(features[window])``.
    :param n_regimes: return regimes 0 … n_regimes − 1 (an empty list for a regime without
        measured steps in the window); default the regimes present.
    :returns: ``result[r]`` = list of ``{"parameter": "<component local name>.<name>", "key", "node",
        "unit", "mu_star", "mu_star_conf", "sigma", "share"}``, largest μ* first; ``mu_star``,
        ``mu_star_conf`` and ``sigma`` are in weighted-residual units (residual / target scale),
        ``share`` is μ* over the regime's total μ*.
    """
    problem = model_data.problem(window, settling_s=settling_s)
    sensitivity = calibration_morris_by_regime(problem, labels, n_trajectories=n_trajectories, seed=seed)
    refs = {ref.key: ref for ref in model_data.model.estimated_parameters}
    regimes = range(n_regimes) if n_regimes is not None else sensitivity.regimes
    result = []
    for regime in regimes:
        present = regime in sensitivity.regimes and sensitivity.n_steps[sensitivity.regimes.index(regime)] > 0
        rows = sensitivity.ranking(regime, top) if present else []
        for row in rows:
            ref = refs[row["parameter"]]
            node = model_data.model.components[ref.component].node
            row.update(parameter=_readable(ref.key), key=ref.key, node=node, unit=ref.spec.unit)
        result.append(rows)
    return result


def successive_calibration_plan(
    sensitivity: RegimeSensitivity, *, min_share: float = 0.02,
) -> list[tuple[int, list[str]]]:
    """The order of a successive (regime-by-regime) calibration.

    Each parameter goes to the regime where its normalised μ* is highest; parameters whose share is
    below ``min_share`` in every regime are left out (they cannot be identified from these data:
    keep them at their prior). Regimes are ordered by the number of parameters assigned (most
    first; ties: larger summed share, then lower regime number), regimes without a parameter are
    omitted; within a regime the parameters are ordered by share, largest first.
    """
    shares = np.nan_to_num(sensitivity.normalised_mu_star(), nan=0.0)
    assigned: dict[int, list[tuple[float, str]]] = {}
    for i, name in enumerate(sensitivity.names):
        row = int(np.argmax(shares[:, i]))
        if shares[row, i] >= min_share:
            assigned.setdefault(sensitivity.regimes[row], []).append((float(shares[row, i]), name))
    order = sorted(assigned, key=lambda r: (-len(assigned[r]), -sum(s for s, _ in assigned[r]), r))
    return [(regime, [name for _, name in sorted(assigned[regime], key=lambda p: -p[0])]) for regime in order]
