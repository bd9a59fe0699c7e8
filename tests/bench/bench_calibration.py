"""Benchmark of the calibration numerics on a stand-in of the case study's size.

Stand-in problem: 1 day at 10-min steps (144), 5 targets, 20 parameters. Each target is a first-order
lag (gain, time constant, offset, a quadratic term: 4 parameters) driven by two boundary inputs and,
for targets 2–5, by the previous target's output, stepped in a numpy loop over the 144 steps for the
whole ensemble at once: about the work of a vectorised ensemble simulation of a small HVAC model.

Figures printed:
  * Kennedy–O'Hagan log-posterior evaluations per second, one batched call for all walkers of all
    temperatures, against the baseline of the same evaluations one walker per call (same run);
    split into the simulate and the GP share;
  * point calibration wall time (goal for the real model: < 30 s);
  * parallel-tempering MCMC wall time to convergence, or to ``--max-steps`` (goal for the real model:
    < 15 min on 2 cores), with steps, IAT and the evaluations per second it achieved.

Run: ``OPENBLAS_NUM_THREADS=1 python tests/bench/bench_calibration.py [--max-steps N] [--skip-mcmc]``.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from service.bayesian_calibration import BayesianCalibrator
from service.calibration_problem import CalibrationProblem
from service.koh_likelihood import KennedyOHaganLikelihood
from service.point_calibration import PointCalibrator

N_STEPS = 144
DT_S = 600.0
N_TARGETS = 5
PER_TARGET = ("gain", "time_constant_s", "offset", "curvature")
LOWER = np.array([0.2, 600.0, -2.0, -0.5])
UPPER = np.array([2.0, 20000.0, 2.0, 0.5])
TRUTH = np.array([1.0, 3600.0, 0.5, 0.1])


def stand_in_problem(seed: int = 0) -> CalibrationProblem:
    rng = np.random.default_rng(seed)
    hours = np.arange(N_STEPS) * DT_S / 3600.0
    drive = np.stack([np.sin(2 * np.pi * hours / 24.0), (hours % 6 < 3).astype(float)])
    drive += 0.05 * rng.standard_normal(drive.shape)

    def simulate(theta: np.ndarray) -> dict[str, np.ndarray]:
        n = theta.shape[0]
        p = theta.reshape(n, N_TARGETS, len(PER_TARGET))
        lag = -np.expm1(-DT_S / p[:, :, 1])
        state = np.zeros((N_TARGETS, n))
        out = np.empty((N_TARGETS, n, N_STEPS))
        for k in range(N_STEPS):
            upstream = drive[0, k]
            for j in range(N_TARGETS):
                signal = upstream + drive[1, k]
                target = p[:, j, 0] * signal + p[:, j, 3] * signal**2 + p[:, j, 2]
                state[j] += lag[:, j] * (target - state[j])
                out[j, :, k] = state[j]
                upstream = state[j]
        return {f"target{j}": out[j] for j in range(N_TARGETS)}

    truth = np.tile(TRUTH, N_TARGETS)[None, :]
    clean = simulate(truth)
    observed = {key: values[0] + 0.05 * rng.standard_normal(N_STEPS) for key, values in clean.items()}
    return CalibrationProblem(
        parameter_names=tuple(f"target{j}:{name}" for j in range(N_TARGETS) for name in PER_TARGET),
        lower=np.tile(LOWER, N_TARGETS), upper=np.tile(UPPER, N_TARGETS),
        simulate=simulate, observed=observed, default=np.tile((LOWER + UPPER) / 2, N_TARGETS),
    )


def bench_log_posterior(problem: CalibrationProblem, n_members: int, repeats: int) -> None:
    likelihood = KennedyOHaganLikelihood(problem)
    rng = np.random.RandomState(0)
    batch = likelihood.initial_ensemble(np.tile(TRUTH, N_TARGETS), {k: 0.05 for k in problem.target_keys}, n_members, rng)
    likelihood.evaluate(batch)  # warm-up
    start = time.perf_counter()
    for _ in range(repeats):
        likelihood.evaluate(batch)
    batched = (time.perf_counter() - start) / repeats
    start = time.perf_counter()
    for _ in range(repeats):
        problem.run(batch[:, : problem.n_parameters])
    simulate_only = (time.perf_counter() - start) / repeats
    n_single = min(n_members, 32)
    start = time.perf_counter()
    for row in batch[:n_single]:
        likelihood.evaluate(row[None, :])
    single = (time.perf_counter() - start) / n_single
    print(f"log posterior, batch of {n_members} (n_dim {likelihood.n_dim}):")
    print(f"  batched     {n_members / batched:9.0f} evaluations/s  ({1e3 * batched:.1f} ms per call; "
          f"simulate {100 * simulate_only / batched:.0f} %, GP + rest {100 * (1 - simulate_only / batched):.0f} %)")
    print(f"  one per call{1 / single:9.0f} evaluations/s  (baseline)")
    print(f"  ratio batched / baseline: {single * n_members / batched:.1f}×   goal ≥ 1,000 evaluations/s")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--max-steps", type=int, default=20000)
    parser.add_argument("--skip-mcmc", action="store_true")
    args = parser.parse_args()
    problem = stand_in_problem()
    n_dim = problem.n_parameters + 3 * N_TARGETS
    n_walkers = 2 * n_dim + 2
    bench_log_posterior(problem, 4 * n_walkers, repeats=5)

    start = time.perf_counter()
    point = PointCalibrator(random_state=0).fit(problem)
    elapsed = time.perf_counter() - start
    identified = sum(v.identified for v in point.identifiability_.values())
    print(f"point calibration: {elapsed:.2f} s ({point.n_simulate_calls_} simulate calls, "
          f"{point.n_simulated_members_} members; {identified}/{problem.n_parameters} identified; "
          f"{elapsed / 30:.2f} of the 30 s goal)")
    if args.skip_mcmc:
        return
    start = time.perf_counter()
    bayes = BayesianCalibrator(n_temperatures=4, max_steps=args.max_steps, random_state=0, progress=True).fit(problem)
    elapsed = time.perf_counter() - start
    evaluations = bayes.n_steps_ * n_walkers * len(bayes.betas_)
    print(f"PT-MCMC: {elapsed:.1f} s, {bayes.n_steps_} steps, converged {bayes.converged_}, IAT {bayes.iat_:.0f}, "
          f"{evaluations / elapsed:.0f} evaluations/s, acceptance {bayes.acceptance_:.2f}, "
          f"swap rates {np.round(bayes.swap_rate_, 2)}; {elapsed / 900:.2f} of the 15 min goal")


if __name__ == "__main__":
    main()
