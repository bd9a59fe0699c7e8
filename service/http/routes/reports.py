"""``GET /runs/{run_id}/report``: a run's report page (:mod:`service.report.page`) over HTTP.

The run's data file is the measurement upload its ``gt:dataSource`` names (``<upload id>.csv``);
when that upload is gone, the page shows the stored numbers without the measured-vs-model figures
and says why. The page is built on a worker thread (it simulates the model once) and kept in the
app's :class:`~service.report.page_cache.ReportPageCache` until the run, its diagnosis, the store's
graphs or the data file change.
"""

from __future__ import annotations

from pathlib import Path

from fastapi import APIRouter, Request
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import HTMLResponse

from service.http.deps import ReadAccess, Service, ServiceDep
from service.http.errors import error_responses
from service.report.page import CONTENT_SECURITY_POLICY
from service.report.page_cache import ReportPageCache

__all__ = ["router", "REPORT_PAGES_KEPT"]

router = APIRouter(tags=["reports"])
SECURITY_HEADERS = {"Content-Security-Policy": CONTENT_SECURITY_POLICY, "X-Content-Type-Options": "nosniff",
                    "Referrer-Policy": "no-referrer"}
#: Report pages an app keeps built (least recently used dropped first).
REPORT_PAGES_KEPT = 16


def _pages(request: Request) -> ReportPageCache:
    """The app's page cache, made on first use."""
    if not hasattr(request.app.state, "report_pages"):
        request.app.state.report_pages = ReportPageCache(REPORT_PAGES_KEPT)
    return request.app.state.report_pages


def _page(pages: ReportPageCache, service: Service, run_id: str) -> str:
    return pages.page(service.store, run_id, locate_data=lambda source: service.uploads.locate(Path(source).stem))


@router.get("/runs/{run_id}/report", response_class=HTMLResponse, dependencies=[ReadAccess],
            responses={**error_responses(404, 401, 403),
                       200: {"content": {"text/html": {}}, "description": "the report page"}})
async def run_report(run_id: str, service: ServiceDep, request: Request) -> HTMLResponse:
    """One self-contained HTML page for calibration run ``run_id`` (or diagnosis graph
    ``<run_id>-diagnosis``): measured vs model with intervals per sensor, the failure located on the
    flow topology, the operating regimes, the ranked missing effects with their evidence, and the
    error across the model's versions. Its security policy comes as headers (the page also states
    it in a ``<meta>``): nothing but its own inline styles and images loads, nothing is sniffed. A
    page is built once and served again until what it shows changes."""
    return HTMLResponse(await run_in_threadpool(_page, _pages(request), service, run_id), headers=SECURITY_HEADERS)
