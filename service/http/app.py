"""The HTTP service (FastAPI; OpenAPI at ``/docs``): building models and their measurements, SPARQL,
named queries, jobs and report pages. ``create_app(settings)`` builds it; ``graphtwin serve`` runs it
with uvicorn. Writes need ``Authorization: Bearer <GRAPHTWIN_TOKEN>``; reads too unless
``open_reads``. Resources, limits and deployment: ``docs/http.md``.
"""

from __future__ import annotations

import logging
from contextlib import asynccontextmanager

from fastapi import FastAPI

from service import __version__
from service.graph.query_reader import QueryReader
from service.graph.store import GraphStore
from service.http.deps import ReadAdmission, Service
from service.http.errors import EXCEPTION_HANDLERS, error_responses
from service.http.gate import RequestGate
from service.http.routes import jobs, models, reports, sparql
from service.http.uploads import MeasurementUploads
from service.jobs.executors import job_executor
from service.jobs.kinds import JOB_KINDS
from service.jobs.records import JobRecords
from service.jobs.runner import JobRunner
from service.report.brick import official_brick_classes
from service.runtime import lock_folder
from service.settings import Settings, load_settings

__all__ = ["create_app"]

log = logging.getLogger("graphtwin.api")


def _open_store(settings: Settings) -> GraphStore:
    if settings.sparql_endpoint:
        token = settings.endpoint_token.get_secret_value() if settings.endpoint_token is not None else None
        return GraphStore.remote(settings.sparql_endpoint, token=token, query_timeout_s=settings.query_timeout_s)
    return GraphStore.embedded(settings.store_path)


def create_app(settings: Settings | None = None, *, store: GraphStore | None = None) -> FastAPI:
    """The service for ``settings`` (from the environment when None).

    :param store: use this store instead of the one ``settings`` describe (tests: an in-memory one).
    Job records a stopped process left queued or running are marked ``interrupted`` here.
    """
    settings = settings or load_settings()
    data_lock = lock_folder(settings.data_dir, "graphtwin serve")  # before anything of a live service is touched
    try:
        brick_classes = official_brick_classes(settings.brick_ontology) if settings.brick_ontology is not None else None
        store = store if store is not None else _open_store(settings)
        records = JobRecords(settings.jobs_dir)
        interrupted = records.mark_interrupted()
        if interrupted:
            log.warning("%d job(s) were interrupted by the last stop: %s", len(interrupted), ", ".join(interrupted))
        uploads = MeasurementUploads(settings.measurements_dir)
        executor = job_executor(settings.executor, max_workers=settings.job_workers)
    except BaseException:
        data_lock.close()
        raise
    runner = JobRunner(store, records, JOB_KINDS, max_workers=settings.job_workers, locate_measurements=uploads.locate,
                       executor=executor)
    reads = QueryReader(store.backend, workers=settings.query_workers, timeout_s=settings.query_timeout_s,
                        max_rows=settings.max_result_rows)  # on disk: worker processes, started now
    admission = ReadAdmission(settings.query_workers + settings.query_queue, settings.max_queries_per_client)

    @asynccontextmanager
    async def lifespan(app: FastAPI):
        yield
        runner.shutdown(interrupt=True)  # a stopping service ends now: running jobs are marked interrupted
        reads.close()
        data_lock.close()

    app = FastAPI(
        title="graphtwin", version=__version__, lifespan=lifespan,
        description="Semantic HVAC models in, calibrated simulation models and missing-physics diagnoses out. "
                    "Writes need `Authorization: Bearer <token>`.",
    )
    app.state.graphtwin = Service(settings, store, runner, uploads, reads, admission, brick_classes)
    for error, handler in EXCEPTION_HANDLERS.items():
        app.add_exception_handler(error, handler)
    app.add_middleware(RequestGate, settings=settings)
    for routes in (models, sparql, jobs, reports):
        app.include_router(routes.router, responses=error_responses(422))  # every validation error has the ErrorBody shape
    return app
