"""The catalog's candidates simulated as members of one shared model: each member's outputs are
those of the candidate's own model (a drift and its factors included) to rounding, and the
candidates' evaluations gathered into shared runs give the evidence each gives evaluated alone.

Rounding: numpy's stacked matrix product (the supply pipe's tanks) rounds a member's row differently
in ensembles of different sizes, at 1e-16; a least-squares path carries that to ~1e-11."""

import numpy as np
import pytest
from case_study import EX, case_study_data

from service.calibration.model_data import ModelData
from service.calibration.run import calibrate
from service.components.library import SignatureLibrary
from service.data.model_series import read_model_data
from service.diagnosis import candidates as candidates_module
from service.diagnosis.candidates import effect_candidates, rank_catalog
from service.diagnosis.drift import _with_drift
from service.diagnosis.shared_runs import SharedRuns, shared_model
from service.model.assembly import assemble
from service.model.effect_splicing import EffectRequest

LIBRARY = SignatureLibrary.load()


@pytest.fixture(scope="module")
def leaking(tmp_path_factory):
    """The case study and three days of its data with a leaking heating valve."""
    path = tmp_path_factory.mktemp("shared") / "days.csv"
    store, _ = case_study_data(path, library=LIBRARY, hidden_effect="ValveLeakage", seed=3, n_days=3.0)
    return store, path


def test_every_candidate_run_as_a_member_of_the_shared_model_gives_its_own_models_outputs_bit_for_bit(leaking):
    store, path = leaking
    found, _ = effect_candidates(store, "case", LIBRARY)
    # two effects on one valve port, one of which leaves the position feedback reading the command
    assert {"ValveLeakage", "ValveStuck", "SensorLag", "SensorOffset"} <= {c.signature.id for c in found}
    shared = shared_model(store, "case", LIBRARY, [EffectRequest(c.signature.id, c.node) for c in found])
    data = read_model_data(shared, path)
    base = assemble(store, "case", library=LIBRARY)
    coil_key = next(r.key for r in base.estimated_parameters
                    if r.key.endswith("/heating_coil_air_side#air_side_conductance"))
    models = [c.model for c in found] + [_with_drift(base, coil_key, "step", 1.5 * 86400.0, 1.0),
                                         _with_drift(base, coil_key, "linear", 86400.0, 2.0)]
    shared_data = ModelData(shared, data, 5)
    window = slice(150, 400)
    rng = np.random.default_rng(7)
    for model in models:
        own = ModelData(model, data, 5)
        lower, upper = own.bounds()
        theta = lower + rng.random((4, lower.size)) * (upper - lower)
        expected = own.simulate_targets(window, theta)
        got = SharedRuns(shared_data, 1).member_data(model, (0, 0)).simulate_targets(window, theta)
        assert expected.keys() == got.keys()
        for node in expected:
            np.testing.assert_allclose(got[node], expected[node], rtol=1e-12, atol=1e-12,
                                       err_msg=f"{model.estimated_parameters[-1].key} at {node}")


def test_candidates_evaluated_together_give_the_evidence_each_gives_alone(leaking, monkeypatch):
    store, path = leaking
    library = {name: s for name, s in LIBRARY.items()
               if s.kind != "effect" or name in ("ConstantHeatGain", "ValveLeakage", "ValveStuck")}
    base = calibrate(store, "case", path, train=("2026-01-12", "2026-01-13T23:59"), test=("2026-01-14", None), seed=0)
    coil = next(iri for iri, c in base.model.components.items() if c.node == f"{EX}heating_coil_air_side")
    noise = {node: 0.1 for node in base.model_data.target_nodes}

    def ranked():
        evidence, _ = rank_catalog(store, "case", library, base, seed=0, refit_max_nfev=12, workers=1,
                                   say=lambda message: None, drifting=[coil], failing_noise=noise)
        return {(e.effect, e.node): e for e in evidence}, [(e.effect, e.node) for e in evidence]

    together, order = ranked()
    alone_calls = []

    def each_alone(jobs, shared, tell):
        alone_calls.append(len(jobs))
        return [candidates_module._evaluate_candidate(job) for job in jobs]

    monkeypatch.setattr(candidates_module, "_evaluate_together", each_alone)
    alone, alone_order = ranked()
    assert alone_calls == [len(together)] and len(together) >= 4  # three effects and at least one drift
    assert order == alone_order
    for key, evidence in together.items():
        other = alone[key]
        assert evidence.estimates.keys() == other.estimates.keys()
        for name, value in evidence.estimates.items():
            assert value == pytest.approx(other.estimates[name], rel=1e-6, abs=1e-9), (key, name)
        assert evidence.delta_bic == pytest.approx(other.delta_bic, rel=1e-6, abs=1e-6), key
        assert evidence.test_improvement == pytest.approx(other.test_improvement, rel=1e-6, abs=1e-9), key
        assert evidence.demoted == other.demoted and evidence.significant == other.significant, key
