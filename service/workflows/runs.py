"""Assemble, calibrate and diagnose a model of the store from a typed request; what they write goes
to the store (the assembly graph, a run graph)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING
from urllib.parse import quote

from service.calibration.run import CalibrationOutcome, calibrate, prepare_calibration
from service.data.windows import parse_window
from service.graph.store import GraphStore
from service.model.assembled_model import AssembledModel
from service.model.assembly import assemble
from service.model.assembly_triples import assembly_triples
from service.workflows.requests import CalibrateRequest, DiagnoseRequest

if TYPE_CHECKING:  # the diagnosis (SciPy, scikit-learn, the effect catalog) loads only when one runs
    from service.diagnosis.report import DiagnosisReport

__all__ = ["assemble_model", "calibrate_model", "diagnose_model", "check_fit_request", "result_links"]


def assemble_model(store: GraphStore, model: str, *, max_complexity: int | None = None) -> AssembledModel:
    """Assemble ``model`` and write its assembly graph.

    :raises AssemblyError: as :func:`~service.model.assembly.assemble`.
    """
    assembled = assemble(store, model, max_complexity=max_complexity)
    store.write_graph(store.assembly_graph(model), assembly_triples(assembled, model))
    return assembled


def calibrate_model(store: GraphStore, request: CalibrateRequest, data: Path, *, progress: bool = False,
                    on_progress: Callable[[str], None] | None = None) -> CalibrationOutcome:
    """Calibrate ``request.model`` against the CSV ``data`` (:func:`~service.calibration.run.calibrate`);
    ``progress``: a progress bar on the terminal; ``on_progress`` hears how far sampling is."""
    return calibrate(store, request.model, data, train=parse_window(request.train),
                     test=parse_window(request.test) if request.test else None, method=request.method,
                     seed=request.seed, progress=progress, on_progress=on_progress, only_when=request.only_when,
                     gp_inputs=request.gp_inputs, start_from=request.start_from,
                     bayes_settings={"max_steps": request.max_steps} if request.max_steps else None)


def diagnose_model(store: GraphStore, request: DiagnoseRequest, data: Path, *,
                   on_progress: Callable[[str], None] | None = None, workers: int | None = None,
                   rank_effects: bool = True) -> DiagnosisReport:
    """Diagnose ``request.model`` on the CSV ``data`` (:func:`~service.diagnosis.loop.diagnose`):
    ``on_progress`` hears each phase; ``rank_effects`` False stops after locating the failures."""
    from service.diagnosis.loop import diagnose

    return diagnose(store, request.model, data, train=parse_window(request.train), test=parse_window(request.test),
                    seed=request.seed, on_progress=on_progress, workers=workers, only_when=request.only_when,
                    start_from=request.start_from, rank_effects=rank_effects)


def check_fit_request(store: GraphStore, request: CalibrateRequest | DiagnoseRequest, data: Path, *,
                      data_name: str | None = None) -> None:
    """What can be checked of a calibration or diagnosis before it runs, as its run checks it: the
    model assembles, the data fit it, the windows lie inside the data and hold enough steps, the
    operating conditions and the GP inputs name columns, the model it starts from has a calibration
    (:func:`~service.calibration.run.prepare_calibration`; ``data_name``: what messages call ``data``).

    :raises GraphtwinError: the first problem found.
    """
    from service.diagnosis.loop import MIN_TEST_STEPS

    diagnosis = isinstance(request, DiagnoseRequest)
    prepare_calibration(store, request.model, data, train=parse_window(request.train),
                        test=parse_window(request.test) if request.test else None,
                        method="point" if diagnosis else request.method, only_when=request.only_when,
                        min_test_steps=MIN_TEST_STEPS if diagnosis else 1,
                        gp_inputs=None if diagnosis else request.gp_inputs,
                        start_from=request.start_from, data_name=data_name)


def result_links(store: GraphStore, model: str, run_id: str, *, page: str | None = None) -> dict[str, str]:
    """Where a run's results are: its graph, its report page (``page``'s, a diagnosis graph's, when
    given) and the named queries that read them (a '+' in a model name is quoted: it would read as a
    space)."""
    return {
        "run_graph": store.run_graph(run_id).value,
        "report": f"/runs/{quote(page or run_id, safe='')}/report",
        "calibrated_parameters": f"/queries/calibrated-parameters?model={quote(model, safe='')}",
        "sensor_metrics": f"/queries/sensor-metrics?model={quote(model, safe='')}",
    }
