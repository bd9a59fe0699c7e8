"""A run's diagnostics are typed and written as JSON with only the keys the run has, in a fixed order."""

import json

from service.calibration.record import CalibrationDiagnostics, SamplerConvergence


def test_a_point_runs_diagnostics_hold_its_warnings_and_cost():
    diagnostics = CalibrationDiagnostics(warnings=["column 'x': 1 gap(s) longer than 5 steps left unfilled"], cost=12.5)
    assert list(diagnostics.to_dict().items()) == [
        ("warnings", ["column 'x': 1 gap(s) longer than 5 steps left unfilled"]), ("cost", 12.5)]


def test_a_bayesian_runs_diagnostics_hold_the_start_note_and_the_samplers_convergence():
    diagnostics = CalibrationDiagnostics(start="started from the latest calibration of base: 3 of 4 parameters",
                                         sampler=SamplerConvergence(converged=False, iat=82.4, n_steps=1800, acceptance=0.31))
    assert list(diagnostics.to_dict().items()) == [
        ("warnings", []), ("start", "started from the latest calibration of base: 3 of 4 parameters"),
        ("converged", False), ("iat", 82.4), ("n_steps", 1800), ("acceptance", 0.31)]
    assert json.loads(json.dumps(diagnostics.to_dict())) == diagnostics.to_dict()
