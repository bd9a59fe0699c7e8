"""``/jobs``: assemble, calibrate, compare, diagnose and add-effect run as jobs (202 and the job at once;
its status, progress, result and links at ``/jobs/{id}``), cancelled or resubmitted by id."""

from __future__ import annotations

from fastapi import APIRouter, Response

from service.components.library import SignatureLibrary
from service.errors import NotFoundError
from service.http.deps import ReadAccess, Service, ServiceDep, WriteAccess, require_fit_models, require_model
from service.http.errors import ApiError, error_responses
from service.http.schemas import JobList, JobPublic
from service.jobs.records import JobRecord
from service.workflows.effects import check_effect_version, checked_effect_triples
from service.workflows.requests import AddEffectRequest, AssembleRequest, CalibrateRequest, DiagnoseRequest, JobRequest
from service.workflows.runs import check_fit_request

__all__ = ["router"]

router = APIRouter(tags=["jobs"])
_JOB_ERRORS = error_responses(401, 403, 404, 422)


def _public(record: JobRecord) -> dict:
    data = record.to_dict()
    data["links"] = {"self": f"/jobs/{record.id}", **record.links}
    return data


def _job(service: Service, job_id: str) -> JobRecord:
    record = service.runner.get(job_id)
    if record is None:
        raise NotFoundError(f"no job {job_id!r}")
    return record


def _check_fit(service: Service, request: CalibrateRequest | DiagnoseRequest) -> None:
    """404 for a model, start model or upload that does not exist; 422 for what the run would refuse."""
    check_fit_request(service.store, request, require_fit_models(service, request),
                      data_name=f"upload {request.measurements}")


def _submit(service: Service, kind: str, request: JobRequest, response: Response) -> dict:
    record = service.runner.submit(kind, request)
    response.headers["Location"] = f"/jobs/{record.id}"
    return _public(record)


@router.post("/jobs/assemble", response_model=JobPublic, status_code=202, dependencies=[WriteAccess],
             responses=_JOB_ERRORS)
def submit_assemble(body: AssembleRequest, response: Response, service: ServiceDep) -> dict:
    """Assemble a model's simulation model and write it as triples (its assembly graph)."""
    require_model(service.store, body.model)
    return _submit(service, "assemble", body, response)


@router.post("/jobs/calibrate", response_model=JobPublic, status_code=202, dependencies=[WriteAccess],
             responses=_JOB_ERRORS)
def submit_calibrate(body: CalibrateRequest, response: Response, service: ServiceDep) -> dict:
    """Calibrate a model against a measurement upload; estimates and metrics go to a run graph.
    The request is checked as the run would check it before anything is queued."""
    _check_fit(service, body)
    return _submit(service, "calibrate", body, response)


@router.post("/jobs/compare", response_model=JobPublic, status_code=202, dependencies=[WriteAccess],
             responses=_JOB_ERRORS)
def submit_compare(body: DiagnoseRequest, response: Response, service: ServiceDep) -> dict:
    """Calibrate on train, compare on test and locate the failures (sensor, flow path, regime, time)
    without testing the effect catalog: a diagnosis's first two steps, in seconds. Checked as a
    diagnosis is before anything is queued."""
    _check_fit(service, body)
    return _submit(service, "compare", body, response)


@router.post("/jobs/diagnose", response_model=JobPublic, status_code=202, dependencies=[WriteAccess],
             responses=_JOB_ERRORS)
def submit_diagnose(body: DiagnoseRequest, response: Response, service: ServiceDep) -> dict:
    """Calibrate on train, compare on test, locate the failures and rank the missing effects. The
    request is checked as the run would check it before anything is queued."""
    _check_fit(service, body)
    return _submit(service, "diagnose", body, response)


@router.post("/jobs/add-effect", response_model=JobPublic, status_code=202, dependencies=[WriteAccess],
             responses=error_responses(401, 403, 404, 409, 422))
def submit_add_effect(body: AddEffectRequest, response: Response, service: ServiceDep) -> dict:
    """Record an effect at a building node as a new model version (``version``, by default
    ``<model>+<effect>``); 409 when that version exists with other effects, 422 when the effect does
    not apply at the node."""
    require_model(service.store, body.model)
    library = SignatureLibrary.load()
    library.effect(body.effect)
    check_effect_version(service.store, body, library)
    # a target that is no node of the model (``supply_fan`` for its IRI) is named with the IRIs it may stand for
    checked_effect_triples(service.store, body.model, body.effect, body.target, library)
    return _submit(service, "add-effect", body, response)


@router.post("/jobs/{kind}", include_in_schema=False, responses=error_responses(404))
def unknown_job_kind(kind: str) -> None:
    """A job kind the service does not run (it was a 405 naming nothing)."""
    raise ApiError(404, f"no job kind {kind!r}: POST /jobs/assemble, /jobs/calibrate, /jobs/compare, "
                        "/jobs/diagnose or /jobs/add-effect")


@router.get("/jobs", response_model=JobList, dependencies=[ReadAccess], responses=error_responses(401, 403))
def list_jobs(service: ServiceDep) -> dict:
    """Every job, oldest first."""
    records = service.runner.list()
    return {"data": [_public(r) for r in records], "count": len(records)}


@router.get("/jobs/{job_id}", response_model=JobPublic, dependencies=[ReadAccess],
            responses=error_responses(401, 403, 404))
def get_job(job_id: str, service: ServiceDep) -> dict:
    """A job's status, progress messages, result and links."""
    return _public(_job(service, job_id))


@router.post("/jobs/{job_id}/cancel", response_model=JobPublic, dependencies=[WriteAccess],
             responses=error_responses(401, 403, 404, 409))
def cancel_job(job_id: str, service: ServiceDep) -> dict:
    """Cancel a queued job at once; flag a running one (its results are discarded when it stops)."""
    _job(service, job_id)
    return _public(service.runner.cancel(job_id))


@router.post("/jobs/{job_id}/resubmit", response_model=JobPublic, status_code=202, dependencies=[WriteAccess],
             responses=error_responses(401, 403, 404, 409))
def resubmit_job(job_id: str, response: Response, service: ServiceDep) -> dict:
    """Run an ended job (interrupted, failed, cancelled…) again with the same parameters: a new job."""
    request = service.runner.request_of(_job(service, job_id))
    if isinstance(request, (CalibrateRequest, DiagnoseRequest)):  # its upload or model may be gone since
        _check_fit(service, request)
    record = service.runner.resubmit(job_id)
    response.headers["Location"] = f"/jobs/{record.id}"
    return _public(record)
