"""The job kinds of the HTTP service — assemble, calibrate, compare, diagnose, add-effect — each a thin
wrapper of its workflow (:mod:`service.workflows`) that reports progress and names its results."""

from __future__ import annotations

from service.components.library import SignatureLibrary
from service.graph.store import GraphStore
from service.jobs.work import JobKind, JobResult, WorkContext
from service.model.summary import assembly_to_dict
from service.workflows.effects import add_effect_version
from service.workflows.requests import AddEffectRequest, AssembleRequest, CalibrateRequest, DiagnoseRequest
from service.workflows.runs import assemble_model, calibrate_model, diagnose_model, result_links

__all__ = ["assemble_job", "calibrate_job", "compare_job", "diagnose_job", "add_effect_job", "JOB_KINDS"]


def assemble_job(store: GraphStore, request: AssembleRequest, context: WorkContext) -> JobResult:
    """Assemble the model and write its assembly graph."""
    context.report("matching the signature library")
    assembled = assemble_model(store, request.model)
    return JobResult(assembly_to_dict(assembled), {
        "model": f"/models/{request.model}", "assembly_graph": store.assembly_graph(request.model).value,
    })


def calibrate_job(store: GraphStore, request: CalibrateRequest, context: WorkContext) -> JobResult:
    """Calibrate the model on its measurement upload; the run goes to a run graph."""
    data = context.measurements(request.measurements)
    context.report(f"calibrating ({request.method})")
    outcome = calibrate_model(store, request, data, on_progress=context.report)
    context.report("calibrated; writing the run")
    return JobResult(outcome.record.to_dict(), result_links(store, request.model, outcome.record.run_id))


def diagnose_job(store: GraphStore, request: DiagnoseRequest, context: WorkContext, *,
                 rank_effects: bool = True) -> JobResult:
    """Diagnose the model on its measurement upload, its phases reported as progress (a cancel stops
    it at the next phase). One worker process: the job already runs beside the server's other work
    (or in a pool process, or on a Dask worker). ``rank_effects`` False: compare and locate only."""
    data = context.measurements(request.measurements)
    report = diagnose_model(store, request, data, on_progress=context.report, workers=1, rank_effects=rank_effects)
    diagnosis = f"{report.run_id}-diagnosis"  # its page shows the fit, the failures and the effects
    links = result_links(store, request.model, report.run_id, page=diagnosis)
    return JobResult(report.to_dict(), links | {"diagnosis_graph": store.run_graph(diagnosis).value})


def compare_job(store: GraphStore, request: DiagnoseRequest, context: WorkContext) -> JobResult:
    """Calibrate on train, compare on test and locate the failures, without testing the effect
    catalog (``graphtwin compare``): a diagnosis's first two steps, written as a diagnosis is."""
    return diagnose_job(store, request, context, rank_effects=False)


def add_effect_job(store: GraphStore, request: AddEffectRequest, context: WorkContext) -> JobResult:
    """A new model version with the effect recorded (the model itself is not changed; a version
    recorded with other effects is not overwritten)."""
    added = add_effect_version(store, request, SignatureLibrary.load(), report=context.report)
    return JobResult(added.to_dict(), {"model": f"/models/{added.version}",
                                       "model_graph": store.model_graph(added.version).value})


#: Every job kind of the service, by the name its route and records use.
JOB_KINDS = {
    "assemble": JobKind(AssembleRequest, assemble_job), "calibrate": JobKind(CalibrateRequest, calibrate_job),
    "compare": JobKind(DiagnoseRequest, compare_job), "diagnose": JobKind(DiagnoseRequest, diagnose_job),
    "add-effect": JobKind(AddEffectRequest, add_effect_job),
}
