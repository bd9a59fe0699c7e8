"""The report page over HTTP is built once per state of what it shows: a second request is served from
the app's cache; a run or diagnosis written again, or deleted, or a new data file, builds it again."""

import os
import time

import pytest
from fastapi.testclient import TestClient
from test_report_page import TOKEN, diagnosed_case

from service.graph.store import GraphStore
from service.http.app import create_app
from service.report import page_cache
from service.report.page_cache import ReportPageCache
from service.settings import Settings

AUTH = {"Authorization": f"Bearer {TOKEN}"}


@pytest.fixture
def builds(monkeypatch):
    """The run ids of the pages built (report_html called)."""
    built = []
    build = page_cache.report_html

    def counted(store, run_id, **kwargs):
        built.append(run_id)
        return build(store, run_id, **kwargs)

    monkeypatch.setattr(page_cache, "report_html", counted)
    return built


@pytest.fixture
def served(tmp_path_factory, tmp_path):
    """A copy of the diagnosed case's store (this test writes and deletes), served with its data upload."""
    case = diagnosed_case(tmp_path_factory.getbasetemp() / "report-run")
    store = GraphStore.embedded(None)
    store.backend.store.extend(case.store.backend.store)
    settings = Settings(data_dir=tmp_path / "service", token=TOKEN, open_reads=False)
    uploads = settings.measurements_dir / "case"
    uploads.mkdir(parents=True)
    data = uploads / case.data.name
    data.write_bytes(case.data.read_bytes())
    with TestClient(create_app(settings, store=store)) as client:
        yield client, store, case, data


def test_the_second_request_is_served_from_the_cache_and_a_change_builds_the_page_again(served, builds):
    client, store, case, data = served
    run_id = case.report.run_id
    url = f"/runs/{run_id}/report"
    started = time.perf_counter()
    first = client.get(url, headers=AUTH)
    built_s = time.perf_counter() - started
    started = time.perf_counter()
    second = client.get(url, headers=AUTH)
    cached_s = time.perf_counter() - started
    assert first.status_code == second.status_code == 200 and second.text == first.text
    assert builds == [run_id]
    print(f"report page: built in {built_s * 1000:.0f} ms, served from the cache in {cached_s * 1000:.0f} ms")
    assert cached_s < 0.25 * built_s
    # the run written again (a comment added to its graph): built again
    run_graph = store.run_graph(run_id)
    store.backend.update(f'INSERT DATA {{ GRAPH <{run_graph.value}> {{ <{run_graph.value}> '
                         f'<http://www.w3.org/2000/01/rdf-schema#comment> "rewritten" }} }}')
    assert client.get(url, headers=AUTH).status_code == 200 and builds == [run_id] * 2
    assert client.get(url, headers=AUTH).status_code == 200 and builds == [run_id] * 2
    # the data file replaced (a newer modification time): built again
    os.utime(data, ns=(time.time_ns(), data.stat().st_mtime_ns + 10**9))
    assert client.get(url, headers=AUTH).status_code == 200 and builds == [run_id] * 3
    # its diagnosis deleted: built again, and says there is none
    store.backend.update(f"DROP GRAPH <{store.run_graph(run_id + '-diagnosis').value}>")
    without = client.get(url, headers=AUTH)
    assert builds == [run_id] * 4 and "No diagnosis is based on this run" in without.text
    # the run deleted: not found, however often asked
    store.backend.update(f"DROP GRAPH <{run_graph.value}>")
    assert [client.get(url, headers=AUTH).status_code for _ in range(2)] == [404, 404]


def test_the_cache_keeps_the_most_recently_used_pages(tmp_path_factory, builds):
    case = diagnosed_case(tmp_path_factory.getbasetemp() / "report-run")
    pages = ReportPageCache(max_pages=2)
    runs = [case.report.run_id, case.version.run_id, f"{case.report.run_id}-diagnosis"]
    for run_id in [runs[0], runs[1], runs[0], runs[2], runs[0], runs[1]]:
        pages.page(case.store, run_id)
    assert builds == [runs[0], runs[1], runs[2], runs[1]]  # runs[1] was the least recently used when runs[2] came
    with pytest.raises(LookupError):
        pages.page(case.store, "../etc/passwd")
