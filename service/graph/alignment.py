"""Alignment: derive the canonical SAREF/FSO view the signatures match from what a model states.

The rules (``queries/alignment/*.rq``, run by :mod:`service.graph.alignment_derivation`) map SAREF
v3.1.1 spellings to v3.2.1/v4, SAREF4BLDG v1.1.2 nominal values to the v2.1.1 PropertyValue chain,
QUDT quantity kinds to property classes, device classes from what a device observes, Brick's typing
and flow path to the SAREF/FSO view.
A large model is cut into independent parts (:func:`independent_parts`: no rule joins across them),
aligned side by side on threads or worker processes (:mod:`service.graph.alignment_workers`); the
result, every derived triple the model does not state, goes to the model's ``inferred`` graph.
Rule ordering, the fixpoint, parts and timings: ``docs/alignment.md``.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Sized
from concurrent.futures import ThreadPoolExecutor
from contextlib import nullcontext
from dataclasses import dataclass
from functools import partial
from itertools import chain
from typing import NamedTuple

import numpy as np
import pyoxigraph as ox

from service.graph.alignment_derivation import (
    _EQUIVALENT_CLASS,
    _RDF_TYPE,
    _SUBCLASS_OF,
    _TYPE,
    _TYPE_INFIX,
    BlankNodeError,
    _aligned_part,
    _Context,
    _derived,
    _has_blank_node,
    _ntriples,
    alignment_rules,
)
from service.graph.alignment_workers import AlignmentWorkers
from service.graph.blank_nodes import skolemize
from service.graph.namespaces import GT, GTR, RDF, RDFS, namespace_of
from service.graph.ntriples import triple_list
from service.runtime import cyclic_gc_paused, usable_cpu_count

__all__ = [
    "PART_TRIPLES", "PROCESS_TRIPLES", "ModelParts", "alignment_rule_triples", "independent_parts", "inferred_ntriples",
    "inferred_triples",
]

_TYPE_OBJECT = re.compile(re.escape(_TYPE_INFIX) + rb"(<[^>\n]*>) \.")
_BLANK_NODE_NAMESPACE = "urn:graphtwin:alignment:blank-node:"
_CLASS_AXIOM_PREDICATES = frozenset(str(p).encode() for p in (_SUBCLASS_OF, _EQUIVALENT_CLASS))
_CLASS_AXIOM_INFIXES = tuple(b" %s " % p for p in sorted(_CLASS_AXIOM_PREDICATES))
_SCHEMA_PREDICATES = (b"<http://www.w3.org/2002/07/owl#", *(b"<http://www.w3.org/2000/01/rdf-schema#%s>" % p for p in (
    b"subClassOf", b"subPropertyOf", b"domain", b"range")))
_QUDT_NAMESPACE = "http://qudt.org/vocab/"
_DECLARATIONS = frozenset(ox.NamedNode(iri) for iri in (
    "http://www.w3.org/2002/07/owl#Class", "http://www.w3.org/2000/01/rdf-schema#Class",
    "http://www.w3.org/1999/02/22-rdf-syntax-ns#Property", "http://www.w3.org/2002/07/owl#ObjectProperty",
    "http://www.w3.org/2002/07/owl#DatatypeProperty", "http://www.w3.org/2002/07/owl#AnnotationProperty"))

#: A model is aligned in independent parts of about this many triples (:func:`independent_parts`),
#: side by side (the measured choice: ``docs/alignment.md``, Part size).
PART_TRIPLES = 10_000

#: A model of at least this many triples is aligned in worker processes rather than threads (see
#: :func:`inferred_ntriples`; the measured choice: ``docs/alignment.md``, Threads or processes).
PROCESS_TRIPLES = 200_000


def alignment_rule_triples() -> list[ox.Triple]:
    """The rules as triples: each a ``gt:AlignmentRule`` ``gtr:alignment/rule/<file name>`` with its
    file name (``rdfs:label``) and text (``gt:queryText``). The store keeps them beside the inferred
    graphs they derived (:meth:`service.graph.store.GraphStore.ensure_ontologies`)."""
    triples = []
    for name, text in alignment_rules():
        rule = GTR[f"alignment/rule/{name}"]
        triples += [ox.Triple(rule, RDF.type, GT.AlignmentRule), ox.Triple(rule, RDFS.label, ox.Literal(name)),
                    ox.Triple(rule, GT.queryText, ox.Literal(text))]
    return triples


def inferred_ntriples(model: Iterable[ox.Triple], ontology: Iterable[ox.Triple], *, workers: int | None = None,
                      part_triples: int = PART_TRIPLES, processes: bool | None = None) -> list[bytes]:
    """What the alignment rules derive from ``model`` with the class hierarchy of the ``ontology``
    and of the model's own ``rdfs:subClassOf`` triples, as N-Triples text in chunks of whole lines
    (one per independent part, in the order of the model; the store loads them without joining
    them): every derived triple not already stated in either.

    :param workers: threads or processes aligning independent parts side by side (default: one per
        CPU this process may run on).
    :param part_triples: the size the model's independent parts are packed into (see
        :func:`independent_parts`); a model smaller than two parts is aligned whole.
    :param processes: align the parts in worker processes (:class:`service.graph.alignment_workers.AlignmentWorkers`)
        rather than threads (default: with more than one worker, for a model of
        :data:`PROCESS_TRIPLES` or more; threads otherwise). Threads share Python's lock for the
        rules' bookkeeping of new lines; processes do not, but each part's text and result cross a
        pipe, and the workers start anew on each call (``docs/alignment.md``).
    :raises BlankNodeError: when the model or the ontology holds a blank node (a load into the scratch
        store would rename it; skolemise first, as :meth:`service.graph.store.GraphStore.load_model` does,
        or call :func:`inferred_triples`).
    :raises RuntimeError: when the rules have not reached a fixpoint in
        :data:`~service.graph.alignment_derivation.MAX_ROUNDS` runs per rule (a rule that keeps minting new terms).
    """
    text = ox.serialize(model, format=ox.RdfFormat.N_TRIPLES)
    ontology = list(ontology)
    n_triples = len(model) if isinstance(model, Sized) else text.count(b"\n")
    with cyclic_gc_paused():
        if n_triples < 2 * part_triples:
            if _has_blank_node(text):
                raise BlankNodeError()
            context = _Context.of(ontology, _lines_with(text, _CLASS_AXIOM_INFIXES))
            return [_ntriples(_derived(text, context).lines)]
        workers = workers or usable_cpu_count()
        worker_processes = None
        if processes or processes is None and workers > 1 and n_triples >= PROCESS_TRIPLES:
            # they start (importing the derivation) on the other CPU while this one cuts the model
            try:
                worker_processes = AlignmentWorkers(workers)
            except OSError:
                if processes:  # asked for, not chosen: say why not
                    raise
        with worker_processes or nullcontext():
            # a large model's pass over its lines finds its blank nodes and its class axioms (among the
            # shared schema lines) on the way: three scans of its text fewer
            model_parts = independent_parts(text, _vocabulary(ontology), part_triples)
            context = _Context.of(ontology, [line for line in model_parts.shared if line.split(b" ", 2)[1] in _CLASS_AXIOM_PREDICATES])
            texts = (_ntriples(model_parts.shared + part) for part in model_parts.parts)
            if worker_processes is not None:
                aligned = worker_processes.map(context, texts)
            else:
                with ThreadPoolExecutor(workers) as pool:
                    aligned = list(pool.map(partial(_aligned_part, context=context), texts))
        minted: dict[bytes, int] = {}
        results = [_PartResult.of(model_parts, k, minted, *part) for k, part in enumerate(aligned)]
        return [*(result.text for result in results), _ntriples(_uncontested(model_parts, minted, results))]


class _PartResult(NamedTuple):
    """What one part derived: the lines about nodes it owns as N-Triples ``text``, and the
    ``contested`` ones, about a node another part owns, which that part may state or derive too.

    A part owns the nodes its triples link (:attr:`ModelParts.node_part`) and the nodes its rules
    mint — or name outside the model, such as classes and vocabulary — before any later part does."""

    text: bytes
    contested: list[bytes]

    @classmethod
    def of(cls, model_parts: ModelParts, k: int, minted: dict[bytes, int], text: bytes, subjects: list[bytes]) -> _PartResult:
        """Part ``k``'s derived N-Triples ``text`` (lines about ``subjects``) sorted by their subject's
        owner; ``minted``: the owner of every subject outside the model so far (the parts are settled
        in order, once per distinct subject). The text is split into lines only when some are
        contested (none on a campus of independent units)."""
        node_ids, node_part, claim = model_parts.node_ids, model_parts.node_part, minted.setdefault
        contested_subjects = set()
        for subject in subjects:
            node = node_ids.get(subject)
            if (claim(subject, k) if node is None else node_part[node]) != k:
                contested_subjects.add(subject)
        if not contested_subjects:
            return cls(text, [])
        owned, contested = [], []
        for line in text.split(b"\n")[:-1]:
            (contested if line[: line.index(b" ")] in contested_subjects else owned).append(line)
        return cls(_ntriples(owned), contested)


def _uncontested(model_parts: ModelParts, minted: dict[bytes, int], results: list[_PartResult]) -> list[bytes]:
    """The contested lines that the owner of their subject neither states nor derives, each once."""
    kept: dict[bytes, None] = {}
    known_of: dict[int, set[bytes]] = {}
    for line in chain.from_iterable(result.contested for result in results):
        subject = line[: line.index(b" ")]
        node = model_parts.node_ids.get(subject)
        owner = minted[subject] if node is None else model_parts.node_part[node]
        if owner not in known_of:
            known_of[owner] = set(model_parts.parts[owner]) | set(results[owner].text.split(b"\n"))
        if line not in known_of[owner]:
            kept.setdefault(line)
    return list(kept)


def _lines_with(text: bytes, infixes: tuple[bytes, ...]) -> list[bytes]:
    """The lines of ``text`` holding one of ``infixes``, found by searching the text (C speed) rather
    than testing every line: a model states few class axioms."""
    found = {}
    for infix in infixes:
        at = text.find(infix)
        while at >= 0:
            start, end = text.rfind(b"\n", 0, at) + 1, text.find(b"\n", at)
            found[start] = text[start:end if end >= 0 else len(text)]
            at = text.find(infix, end) if end >= 0 else -1
    return [found[start] for start in sorted(found)]


def inferred_triples(model: Iterable[ox.Triple], ontology: Iterable[ox.Triple], **options) -> list[ox.Triple]:
    """:func:`inferred_ntriples` as triples (``options`` as there); blank nodes are allowed: they
    are aligned as IRIs and named back."""
    names: dict[ox.BlankNode, ox.NamedNode] = {}
    model, ontology = (skolemize(triples, _BLANK_NODE_NAMESPACE, names) for triples in (model, ontology))
    triples = triple_list(inferred_ntriples(model, ontology, **options))
    if names:
        blank = {iri: node for node, iri in names.items()}

        def named_back(term):
            return blank.get(term, term)

        triples = [ox.Triple(named_back(t.subject), t.predicate, named_back(t.object)) for t in triples]
    return triples


@dataclass(frozen=True)
class ModelParts:
    """A model cut into independent parts (:func:`independent_parts`)."""

    #: the model's own schema, which every part needs (N-Triples lines)
    shared: list[bytes]
    #: the other lines, part by part
    parts: list[list[bytes]]
    #: node (an N-Triples term) → its index in :attr:`node_part`, for every node that links triples
    node_ids: dict[bytes, int]
    #: node index → the part whose triples name it
    node_part: list[int]


def independent_parts(text: bytes, vocabulary: tuple[bytes, ...], part_triples: int) -> ModelParts:
    """A model's N-Triples ``text`` (one triple a line, as Oxigraph writes it) cut where no rule can
    join across, so that each part aligned with the shared lines derives what the whole model
    derives about it: the connected components of its triples, linked by the nodes they name except
    literals, classes (objects of ``rdf:type``) and ``vocabulary`` (IRIs starting with one of those
    N-Triples prefixes), packed in model order into parts of at least ``part_triples`` triples; the
    model's own schema is ``shared`` by every part (``docs/alignment.md``, Independent parts).

    :raises BlankNodeError: when a line holds a blank node.
    """
    # imported on first use, not with the module (which every user of the store imports): only a
    # model large enough to cut into parts needs SciPy
    from scipy.sparse import coo_array
    from scipy.sparse.csgraph import connected_components

    classes = set(_TYPE_OBJECT.findall(text))  # a search of the text (C speed), not a test per line
    shared, body, subject_ids, starts, ends = [], [], [], [], []
    node_ids: dict[bytes, int] = {}
    node_id = node_ids.setdefault
    schema: dict[bytes, bool] = {}
    # a subject's lines follow one another (Oxigraph writes a parsed model in its order), so what
    # decides on the subject is decided once per run of lines, and on the predicate once per predicate
    subject_of_run, run_shared, start, blank = None, False, -1, False
    for line in text.split(b"\n")[:-1]:
        subject, predicate, obj = line.split(b" ", 2)
        if subject != subject_of_run:
            subject_of_run, start = subject, -1
            run_shared = subject in classes or subject.startswith(vocabulary)
            blank = blank or subject[0] == 95  # 95: '_' opens a blank node
        blank = blank or obj[0] == 95
        if (is_schema := schema.get(predicate)) is None:
            is_schema = schema[predicate] = predicate.startswith(_SCHEMA_PREDICATES)
        if run_shared or is_schema:
            shared.append(line)
            continue
        body.append(line)
        if start < 0:
            start = node_id(subject, len(node_ids))
        subject_ids.append(start)
        if predicate != _TYPE and obj[0] != 34 and not obj.startswith(vocabulary):  # 34: '"' opens a literal
            starts.append(start)
            ends.append(node_id(obj[:-2], len(node_ids)))
    if blank:
        raise BlankNodeError()
    adjacency = coo_array((np.ones(len(starts), dtype=np.int8), (starts, ends)), shape=(len(node_ids), len(node_ids)))
    _count, node_component = connected_components(adjacency, directed=False)
    triple_component = node_component[np.asarray(subject_ids, dtype=np.int64)]
    # components in order of their first triple, packed into parts of at least part_triples
    components, first_triple = np.unique(triple_component, return_index=True)
    sizes = np.bincount(triple_component)
    component_part = np.zeros(len(sizes), dtype=np.int64)
    part, filled = 0, 0
    for c in components[np.argsort(first_triple)].tolist():
        if filled >= part_triples:
            part, filled = part + 1, 0
        component_part[c] = part
        filled += sizes[c]
    triple_part = component_part[triple_component]
    order = np.argsort(triple_part, kind="stable").tolist()
    ends_at = np.cumsum(np.bincount(triple_part, minlength=part + 1)).tolist()
    in_order = [body[i] for i in order]
    parts = [in_order[start:end] for start, end in zip([0, *ends_at[:-1]], ends_at, strict=True)]
    return ModelParts(shared, parts, node_ids, component_part[node_component].tolist())


def _vocabulary(ontology: list[ox.Triple]) -> tuple[bytes, ...]:
    """N-Triples prefixes of the namespaces of the classes and properties the ``ontology`` declares,
    and QUDT's (see :func:`independent_parts`)."""
    declared = {t.subject.value for t in ontology if t.predicate == _RDF_TYPE and t.object in _DECLARATIONS}
    return tuple(sorted({f"<{namespace_of(iri)}".encode() for iri in declared | {_QUDT_NAMESPACE}}))
