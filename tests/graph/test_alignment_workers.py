"""Alignment worker processes (service/graph/alignment_workers.py): parts aligned in fresh interpreters
give what the parent's own alignment gives, and a failing or dead worker is a clear error."""

import dataclasses
import os
import signal
import subprocess

import pyoxigraph as ox
import pytest
from brick_models import campus_triples, ontology_triples

import service.graph.alignment
from service.graph.alignment import _vocabulary, independent_parts, inferred_triples
from service.graph.alignment_derivation import _aligned_part, _Context, _ntriples
from service.graph.alignment_workers import AlignmentWorkerError, AlignmentWorkers


@pytest.fixture(scope="module")
def ontology():
    return ontology_triples()


@pytest.fixture(scope="module")
def context(ontology):
    return _Context.of(ontology)


@pytest.fixture(scope="module")
def unit_texts(ontology) -> list[bytes]:
    """The N-Triples texts of the independent parts of a small Brick campus, one per unit."""
    parts = independent_parts(ox.serialize(campus_triples(4), format=ox.RdfFormat.N_TRIPLES), _vocabulary(ontology), part_triples=1)
    return [_ntriples(parts.shared + part) for part in parts.parts]


def test_workers_answer_each_part_in_order_as_the_parent_would(context, unit_texts):
    texts = unit_texts
    assert len(texts) == 4
    with AlignmentWorkers(2) as workers:
        aligned = workers.map(context, texts)
        again = workers.map(context, texts[::-1])  # a second call on the same workers
    mine = [_aligned_part(text, context) for text in texts]
    assert len(aligned) == len(texts) and all(text for text, _subjects in aligned)
    for (text, subjects), (my_text, my_subjects) in zip(aligned, mine, strict=True):
        assert set(text.split(b"\n")) == set(my_text.split(b"\n")) and set(subjects) == set(my_subjects)
    assert [set(text.split(b"\n")) for text, _ in again] == [set(text.split(b"\n")) for text, _ in aligned[::-1]]


def test_a_rule_failing_in_a_worker_is_raised_with_the_workers_traceback(context):
    broken = dataclasses.replace(context, rules=("CONSTRUCT { ?s ?p ?o } WHERE { ?s ?p }",) * len(context.rules))
    with AlignmentWorkers(2) as workers, pytest.raises(AlignmentWorkerError, match=r"(?s)failed:.*Traceback.*SyntaxError"):
        workers.map(broken, [_ntriples([b"<urn:a> <urn:b> <urn:c> ."])] * 3)


def test_a_worker_that_died_is_reported_with_its_exit_status(context, unit_texts):
    with AlignmentWorkers(1) as workers:
        process = workers._processes[0]
        os.kill(process.pid, signal.SIGKILL)
        process.wait()
        with pytest.raises(AlignmentWorkerError, match=rf"worker {process.pid} exited with status -{int(signal.SIGKILL)}"):
            workers.map(context, unit_texts)


def test_workers_that_cannot_start_leave_none_running_and_the_alignment_falls_back_to_threads(monkeypatch, ontology):
    started = []
    real_popen = subprocess.Popen

    def second_fails(*args, **kwargs):
        if started:
            raise OSError("process limit reached")
        started.append(real_popen(*args, **kwargs))
        return started[0]

    monkeypatch.setattr(subprocess, "Popen", second_fails)
    with pytest.raises(OSError, match="process limit"):
        AlignmentWorkers(2)
    assert started and started[0].poll() is not None  # the one started was ended

    campus = campus_triples(4)
    whole = set(inferred_triples(campus, ontology))
    monkeypatch.setattr(service.graph.alignment, "PROCESS_TRIPLES", 1)  # processes chosen: they fail to start, threads align
    assert set(inferred_triples(campus, ontology, part_triples=1, workers=2)) == whole
    with pytest.raises(OSError, match="process limit"):  # asked for: the reason is raised
        inferred_triples(campus, ontology, part_triples=1, workers=2, processes=True)
