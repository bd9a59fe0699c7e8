"""Alignment: derive the canonical SAREF/FSO view the signatures match from what a model states.

Each rule is one SPARQL CONSTRUCT in ``queries/alignment/*.rq`` (its header says what it derives and
why): SAREF v3.1.1 spellings to the v3.2.1/v4 ones, SAREF4BLDG v1.1.2 nominal values to the v2.1.1
PropertyValue chain, QUDT quantity kinds to property classes, measuring-device classes from what a
device observes (the accepted spellings are listed in ``ontologies/README.md``).

The rules run in a scratch in-memory store holding the model, the ontology subsets and what has been
derived so far, in file-name order, each seeing what the rules before it derived. A rule runs again
only when a triple it could read was added after its last run (:func:`service.graph.sparql_reads.query_reads`:
the predicates of its patterns with the objects they can take, so ``?point gt:derivedByRule "02-…"``
is not woken by every rule's provenance), the earliest such rule first, until
none is left: a fixpoint (rules only add triples and mint IRIs from the nodes they read — never
blank nodes, which a CONSTRUCT makes anew on every run — so this terminates). On a Brick campus the 19
rules take 24 runs a part (one of them rule 11's, for a spelling Brick does not use), each costly one (point links, flow edges, sensor placement) one, where a
confirming round of every rule after the last addition doubled the time. The order makes the rules
stratified: a rule may test for the absence of a triple (``FILTER NOT EXISTS``, ``MINUS``) only when the triple
is stated in the model or derived by a rule earlier in the order, so that its answer cannot change
later. The Brick rules use this: the typing rules (``0N-brick-*.rq``) run first, the flow rules
(``5N-brick-*.rq``) after the device classes of ``50`` (whose entailed ``saref:Device`` types the
flow-edge rule reads), and the flow-edge and sensor placement rules read the units' parts at any
depth of ``51`` and served spaces of ``52`` (path closures several rules need, each computed once),
their supply outlets of ``53`` and the flow edges
and mixing boxes of the rules before them. A rule that names the classes it reads (``?property a saref:Temperature``, not
``?property a ?class . ?class rdfs:subClassOf* …``) is woken by those types only: rule 50 so runs once,
where reading every type it ran four times a part; and a rule that tests what another derives
rather than what it derives itself runs once (the mixing boxes of ``54`` were a branch of the
flow-edge rule, which their types then woke a second time).

A large model is cut into independent parts (:func:`independent_parts`: no rule joins across them)
aligned side by side, one scratch store per part, on a worker process per CPU
(:mod:`service.graph.alignment_workers`) or, for a smaller model, a thread per CPU (Oxigraph evaluates a
rule and writes its result without holding Python's lock, but the bookkeeping of new lines takes
turns on it); triples stay N-Triples lines from the model to the result (they hash and compare at C
speed; a term object per triple cost more than the rules). A part's result is sorted by who owns each
line's subject (:class:`_PartResult`): the few lines about a node another part owns — one both mint,
or one the other states — are settled after, so the parts' texts are handed over as they are
(:func:`inferred_ntriples`).

A derived triple no rule can read (by :func:`service.graph.sparql_reads.query_reads`: provenance, columns,
units, assumption texts, most derived classes) is kept in the result but not loaded into the scratch
store. The scratch store also holds, for every ``rdf:type`` triple of the model or derived, the types it
entails by ``rdfs:subClassOf`` in the ontology and the model — only those a rule names (:func:`rule_terms`), so a
rule writes ``?point a brick:Temperature_Sensor`` and matches every official subclass without a
property path (``a/rdfs:subClassOf*`` per node made the Brick rules minutes long at 10⁴ triples).
These entailed triples are not part of the result: the store's queries see the hierarchy in the
ontology graph. Computing locally keeps the store's write of the model and its
inferences one transaction, and works the same whatever the backend. The user's graph is never
changed: the result goes to the model's ``inferred`` graph (:meth:`service.graph.store.GraphStore.load_model`).

Rules that scale (tests/bench/bench_brick_alignment.py; Oxigraph plans a nested group without
knowing which of its variables the outer row binds, so it may evaluate it over the whole graph once
per outer row): inside ``OPTIONAL``, ``EXISTS`` and ``NOT EXISTS`` write ``FILTER(?c IN (…))``, not
``VALUES ?c {…}``, and test a second pattern with ``FILTER EXISTS`` rather than joining it; prefer
``MINUS`` to a ``NOT EXISTS`` that shares only bound variables with the outer pattern; filter a set of
anchors in a subquery before the patterns that read from it.
"""

from __future__ import annotations

import re
from collections import defaultdict
from collections.abc import Iterable, Sized
from concurrent.futures import ThreadPoolExecutor
from contextlib import nullcontext
from dataclasses import dataclass, replace
from functools import lru_cache, partial
from itertools import chain
from typing import NamedTuple

import numpy as np
import pyoxigraph as ox

from service.graph.alignment_workers import AlignmentWorkers
from service.graph.blank_nodes import skolemize
from service.runtime import usable_cpu_count
from service.runtime import cyclic_gc_paused
from service.graph.namespaces import GT, GTR, RDF, RDFS, namespace_of
from service.graph.ntriples import triple_list
from service.resources import queries_dir
from service.graph.sparql_reads import QueryReads, query_reads

__all__ = ["MAX_ROUNDS", "PART_TRIPLES", "PROCESS_TRIPLES", "BlankNodeError", "ModelParts", "alignment_rules", "independent_parts", "inferred_ntriples", "inferred_triples", "rule_terms"]

_RDF_TYPE = ox.NamedNode("http://www.w3.org/1999/02/22-rdf-syntax-ns#type")
_TYPE = str(_RDF_TYPE).encode()
_TYPE_INFIX = b" %s " % _TYPE
_TYPE_OBJECT = re.compile(re.escape(_TYPE_INFIX) + rb"(<[^>\n]*>) \.")
_BLANK_NODE_NAMESPACE = "urn:graphtwin:alignment:blank-node:"
_SUBCLASS_OF = ox.NamedNode("http://www.w3.org/2000/01/rdf-schema#subClassOf")
_EQUIVALENT_CLASS = ox.NamedNode("http://www.w3.org/2002/07/owl#equivalentClass")
_CLASS_AXIOM_PREDICATES = frozenset(str(p).encode() for p in (_SUBCLASS_OF, _EQUIVALENT_CLASS))
_CLASS_AXIOM_INFIXES = tuple(b" %s " % p for p in sorted(_CLASS_AXIOM_PREDICATES))
_SCHEMA_PREDICATES = (b"<http://www.w3.org/2002/07/owl#", *(b"<http://www.w3.org/2000/01/rdf-schema#%s>" % p for p in (
    b"subClassOf", b"subPropertyOf", b"domain", b"range")))
_QUDT_NAMESPACE = "http://qudt.org/vocab/"
_DECLARATIONS = frozenset(ox.NamedNode(iri) for iri in (
    "http://www.w3.org/2002/07/owl#Class", "http://www.w3.org/2000/01/rdf-schema#Class",
    "http://www.w3.org/1999/02/22-rdf-syntax-ns#Property", "http://www.w3.org/2002/07/owl#ObjectProperty",
    "http://www.w3.org/2002/07/owl#DatatypeProperty", "http://www.w3.org/2002/07/owl#AnnotationProperty"))
_PREFIX = re.compile(r"PREFIX\s+([\w-]*):\s*<([^>]+)>", re.IGNORECASE)
_TERM = re.compile(r"<([^>\s]+)>|(?<![\w?$])([A-Za-z][\w-]*):([A-Za-z_][\w-]*)")
_COMMENT = re.compile(r"(^|\s)#[^\n]*")

#: Safety cap on the fixpoint: at most this many runs per rule on average (the shipped rules reach it
#: in one run each, and a second of the few that read what the last ones added).
MAX_ROUNDS = 8

#: A model is aligned in independent parts of about this many triples (:func:`independent_parts`),
#: side by side on threads (Oxigraph evaluates a query without holding Python's lock). On the
#: 1M-triple campus (2 CPUs, 2026-11-26), CPU and wall: 3k 17.7 s and 11.0 s, 5k 16.2 and 10.1,
#: 10k 15.5–16.2 and 9.6–10.1, 12.5k 15.6–16.2 and 9.5–10.4, 25k 17.2–18.6 and 10.6–12.0, 35k 17.9
#: and 11.8: the rules' path and join queries cost more than in proportion to a part's size, and
#: below 10k the per-part set-up and rule runs add up (25k was best when each part's Python work
#: was heavier).
PART_TRIPLES = 10_000

#: A model of at least this many triples is aligned in worker processes rather than threads (see
#: :func:`inferred_ntriples`). Brick campus on 2 CPUs (2026-11-27), threads and processes: 100k
#: 0.89 and 1.25–1.30 s (the workers' start is not hidden yet), 200k 1.83–2.00 and 1.78, 300k
#: 2.82–2.91 and 2.65–2.70, 1M 8.79–8.91 and 7.99–8.17.
PROCESS_TRIPLES = 200_000


@lru_cache(maxsize=1)
def alignment_rules() -> tuple[tuple[str, str], ...]:
    """``(file name, query text)`` of every rule in ``queries/alignment``, in file-name order."""
    return tuple((p.name, p.read_text(encoding="utf-8")) for p in sorted((queries_dir() / "alignment").glob("*.rq")))


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


@lru_cache(maxsize=1)
def rule_terms() -> frozenset[str]:
    """Every IRI the rules name (full or prefixed, prefixes expanded per rule; comments ignored)."""
    terms = set()
    for _name, text in alignment_rules():
        prefixes = dict(_PREFIX.findall(text))
        for full, prefix, local in _TERM.findall(_COMMENT.sub(" ", text)):
            if full:
                terms.add(full)
            elif prefix in prefixes:
                terms.add(prefixes[prefix] + local)
    return frozenset(terms)


def _named_superclasses(ontology: Iterable[ox.Triple]) -> dict[ox.NamedNode, tuple[ox.NamedNode, ...]]:
    """class → its strict superclasses that a rule names: the closure of ``rdfs:subClassOf`` and of
    ``owl:equivalentClass`` read both ways (an instance of the alias ``brick:AHU`` is one of
    ``brick:Air_Handling_Unit``, and the other way round)."""
    parents: dict[ox.NamedNode, set[ox.NamedNode]] = defaultdict(set)
    for t in ontology:
        if isinstance(t.object, ox.NamedNode) and isinstance(t.subject, ox.NamedNode):
            if t.predicate == _SUBCLASS_OF:
                parents[t.subject].add(t.object)
            elif t.predicate == _EQUIVALENT_CLASS:
                parents[t.subject].add(t.object)
                parents[t.object].add(t.subject)
    named = rule_terms()
    result = {}
    for cls in list(parents):
        seen, todo = set(), list(parents[cls])
        while todo:
            node = todo.pop()
            if node not in seen and node != cls:
                seen.add(node)
                todo += parents.get(node, ())
        supers = tuple(sorted((c for c in seen if c.value in named), key=str))
        if supers:
            result[cls] = supers
    return result


def inferred_ntriples(model: Iterable[ox.Triple], ontology: Iterable[ox.Triple], *, workers: int | None = None,
                      part_triples: int = PART_TRIPLES, processes: bool | None = None) -> list[bytes]:
    """What the alignment rules derive from ``model`` with the class hierarchy of the ``ontology``
    and of the model's own ``rdfs:subClassOf`` triples, as N-Triples text in chunks of whole lines
    (one per independent part, in the order of the model; joined, a million lines are a copy of
    ~200 MB the store's load does not need): every derived triple not already stated in either.

    :param workers: threads or processes aligning independent parts side by side (default: one per
        CPU this process may run on).
    :param part_triples: the size the model's independent parts are packed into (see
        :func:`independent_parts`); a model smaller than two parts is aligned whole.
    :param processes: align the parts in worker processes (:class:`service.graph.alignment_workers.AlignmentWorkers`)
        rather than threads (default: with more than one worker, for a model of
        :data:`PROCESS_TRIPLES` or more, where a worker process starts; threads otherwise). Threads share Python's lock for the rules' bookkeeping of
        new lines (two reach 1.7x one); processes do not, but each part's text and result cross a
        pipe, and the workers start anew on each call (~0.5 s, while this process cuts the model).
    :raises BlankNodeError: when the model or the ontology holds a blank node (a load into the scratch
        store would rename it; skolemise first, as :meth:`service.graph.store.GraphStore.load_model` does,
        or call :func:`inferred_triples`).
    :raises RuntimeError: when the rules have not reached a fixpoint in :data:`MAX_ROUNDS` runs per
        rule (a rule that keeps minting new terms).
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
            # they start (importing this module) on the other CPU while this one cuts the model
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


def _aligned_part(text: bytes, context: _Context) -> tuple[bytes, list[bytes]]:
    """A part's N-Triples ``text`` aligned: what the rules derive as N-Triples text, and the
    subjects of its lines (on a worker thread, or in an alignment worker process)."""
    derived = _derived(text, context)
    return _ntriples(derived.lines), list(derived.subjects)


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
    than testing every line: a model states few class axioms (a million-line campus took 0.4 s)."""
    found = {}
    for infix in infixes:
        at = text.find(infix)
        while at >= 0:
            start, end = text.rfind(b"\n", 0, at) + 1, text.find(b"\n", at)
            found[start] = text[start:end if end >= 0 else len(text)]
            at = text.find(infix, end) if end >= 0 else -1
    return [found[start] for start in sorted(found)]


def _ntriples(lines: list[bytes]) -> bytes:
    """N-Triples text of ``lines`` (each line ends with a newline)."""
    return b"\n".join(lines) + b"\n" if lines else b""


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
    derives about it.

    The rules join model resources only through model resources: a node links the triples that name
    it unless it is a literal, a class (the object of ``rdf:type``), or ``vocabulary`` (IRIs starting
    with one of those N-Triples prefixes: the namespaces of the classes and properties the ontology
    declares, and QUDT's). The parts are the connected components of the model's triples under that
    linking, packed in model order into parts of at least ``part_triples`` triples (a component is
    never split: a campus whose units share a plant is one component). Shared: the model's own
    schema — triples whose predicate is OWL's or ``rdfs:subClassOf``, ``subPropertyOf``, ``domain``
    or ``range``, or whose subject is a class or vocabulary — that every part needs, as it needs the
    ontology.

    :raises BlankNodeError: when a line holds a blank node.
    """
    # imported here: an alignment worker process (service.graph.alignment_workers) needs none of SciPy,
    # and importing it would add a fifth to the worker's start
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


class BlankNodeError(ValueError):
    """A model or ontology given to the alignment holds a blank node."""

    def __init__(self) -> None:
        super().__init__("the alignment needs a model and ontology without blank nodes: skolemise them first")


def _vocabulary(ontology: list[ox.Triple]) -> tuple[bytes, ...]:
    """N-Triples prefixes of the namespaces of the classes and properties the ``ontology`` declares,
    and QUDT's (see :func:`independent_parts`)."""
    declared = {t.subject.value for t in ontology if t.predicate == _RDF_TYPE and t.object in _DECLARATIONS}
    return tuple(sorted({f"<{namespace_of(iri)}".encode() for iri in declared | {_QUDT_NAMESPACE}}))


def _has_blank_node(text: bytes) -> bool:
    """Whether N-Triples ``text`` has a blank node (``_:`` opening a line or after a space; inside a
    literal it may be a false alarm, which only costs the caller a skolemisation)."""
    return b"_:" in text and (text.startswith(b"_:") or b" _:" in text or b"\n_:" in text)


@dataclass(frozen=True)
class _Context:
    """What every part's alignment shares (read-only, so threads share it): the ontology as N-Triples
    and as lines, and the lines of it some rule can read (:meth:`unread`: what a part's scratch store
    loads; a third of the ontology subsets); for each class (N-Triples) the lines
    `` <rdf:type> <super> .`` of its rule-named superclasses by the ontology's and the model's
    ``rdfs:subClassOf``, each without its subject and with its object ``<super> .``; what each rule reads, and the predicates (N-Triples) some rule reads only some objects
    of; what any rule reads (:meth:`unread`); the rules' texts."""

    ontology: bytes
    ontology_lines: frozenset[bytes]
    ontology_read: bytes
    type_lines: dict[bytes, tuple[tuple[bytes, bytes], ...]]
    reads: tuple[QueryReads, ...]
    restricted: frozenset[bytes]
    read_objects: dict[bytes, frozenset[str] | None]
    read_prefixes: tuple[bytes, ...] | None
    rules: tuple[str, ...]

    def unread(self, predicates: set[bytes], pairs: set[tuple[bytes, bytes]]) -> tuple[frozenset, frozenset]:
        """Of some lines' ``predicates`` and the ``(predicate, object + " .")`` pairs of their
        restricted predicates (N-Triples), those no rule can read: lines with them need not be in
        the scratch store (provenance, columns, units, assumption texts and most derived classes:
        about 40 % of what the Brick rules derive). Decided once per distinct predicate or pair."""
        unread_predicates = frozenset(p for p in predicates if p not in self.read_objects and not (
            self.read_prefixes is None or p.startswith(self.read_prefixes)))
        unread_pairs = frozenset((p, o) for p, o in pairs
                                 if (objects := self.read_objects.get(p)) is not None and _object_value(o[:-2]) not in objects)
        return unread_predicates, unread_pairs

    @classmethod
    def of(cls, ontology: list[ox.Triple], model_class_axioms: list[bytes] = ()) -> _Context:
        """The context of the ``ontology`` and the model's class axioms (N-Triples lines).

        :raises BlankNodeError: when the ontology holds a blank node."""
        text = ox.serialize(ontology, format=ox.RdfFormat.N_TRIPLES)
        if _has_blank_node(text):
            raise BlankNodeError()
        model_class_axioms = [t.triple for t in ox.parse(b"\n".join(model_class_axioms), format=ox.RdfFormat.N_TRIPLES)]
        type_lines = {str(c).encode(): tuple((b" %s %s ." % (_TYPE, str(s).encode()), b"%s ." % str(s).encode()) for s in supers)
                      for c, supers in _named_superclasses([*ontology, *model_class_axioms]).items()}
        rules = tuple(text for _name, text in alignment_rules())
        reads = tuple(map(query_reads, rules))  # parsed here, not on the threads
        restricted = frozenset(f"<{p}>".encode() for r in reads for p, objects in r.objects.items() if objects is not None)
        read_objects: dict[bytes, frozenset[str] | None] = {}
        for predicate, objects in ((f"<{p}>".encode(), o) for r in reads for p, o in r.objects.items()):
            known = read_objects.get(predicate, frozenset())
            read_objects[predicate] = None if known is None or objects is None else known | objects
        read_prefixes = None if any(r.any_predicate for r in reads) else tuple(
            f"<{prefix}".encode() for r in reads for prefix in r.predicate_prefixes)
        lines = text.split(b"\n")
        context = cls(text, frozenset(lines), text, type_lines, reads, restricted, read_objects, read_prefixes, rules)
        lines.pop()  # the empty string after the last newline
        terms = [line.split(b" ", 2) for line in lines]
        unread_predicates, unread_pairs = context.unread({t[1] for t in terms}, {(t[1], t[2]) for t in terms if t[1] in restricted})
        return replace(context, ontology_read=_ntriples([line for line, (_s, p, o) in zip(lines, terms, strict=True)
                                                          if p not in unread_predicates and (p, o) not in unread_pairs]))


class _Derived(NamedTuple):
    """What the rules derive from a model: N-Triples ``lines`` in order, and their ``subjects``."""

    lines: list[bytes]
    subjects: set[bytes]


def _derived(model_text: bytes, context: _Context) -> _Derived:
    """The rules run to their fixpoint on the N-Triples ``model_text`` (see :func:`inferred_ntriples`):
    the lines derived, in order, and their subjects. Triples are lines of N-Triples throughout — the store evaluates a
    rule and writes its result without Python's lock, and lines hash and compare at C speed; a line
    is split once, when it is new."""
    scratch = ox.Store()
    scratch.load(model_text + context.ontology_read, ox.RdfFormat.N_TRIPLES, lenient=True)  # Oxigraph wrote it
    stated = model_text.split(b"\n")
    known = set(stated)  # stated, derived or entailed
    known |= context.ontology_lines
    known.add(b"")
    derived: list[bytes] = []
    subjects: set[bytes] = set()
    added: defaultdict[bytes, set[bytes]] = defaultdict(set)

    def load(new: list[bytes], terms: list[list[bytes]]) -> None:
        """Load the ``new`` lines (split: ``terms``) that a rule can read into the scratch store, and
        record in ``added`` their predicates, with the objects of the restricted ones."""
        predicates = {t[1] for t in terms}
        restricted = predicates & context.restricted
        pairs = {(t[1], t[2]) for t in terms if t[1] in restricted} if restricted else set()
        for predicate in predicates:
            added[predicate]  # noqa: B018 (the predicate is added even when no object is kept)
        for predicate, obj in pairs:
            added[predicate].add(obj[:-2])
        unread_predicates, unread_pairs = context.unread(predicates, pairs)
        if unread_predicates or unread_pairs:
            new = [line for line, (_s, p, o) in zip(new, terms, strict=True)
                   if p not in unread_predicates and (p, o) not in unread_pairs]
        scratch.load(b"\n".join(new), ox.RdfFormat.N_TRIPLES, lenient=True)

    entailed = _entailed([line.split(b" ", 2) for line in stated if _TYPE_INFIX in line], context.type_lines, known)
    load(list(entailed), list(entailed.values()))
    texts = context.rules
    # A rule's answer is a function of what it reads, so it need not run again until a triple it could
    # read was added (by any rule, itself included) since its last run.
    pending = [True] * len(texts)
    for _run in range(MAX_ROUNDS * len(texts)):
        if True not in pending:
            return _Derived(derived, subjects)
        rule = pending.index(True)
        pending[rule] = False
        added.clear()
        answer = scratch.query(texts[rule]).serialize(format=ox.RdfFormat.N_TRIPLES)
        fresh = [line for line in dict.fromkeys(answer.split(b"\n")) if line not in known]
        known.update(fresh)
        terms = [line.split(b" ", 2) for line in fresh]  # one comprehension per step: C loops
        entailed = _entailed(terms, context.type_lines, known)
        load(fresh + list(entailed), terms + list(entailed.values()))
        derived += fresh
        subjects.update([t[0] for t in terms])
        values = {p[1:-1].decode(): ({_object_value(o) for o in objects} if p in context.restricted else ())
                  for p, objects in added.items()}
        pending = [waiting or other.may_read(values) for waiting, other in zip(pending, context.reads, strict=True)]
    raise RuntimeError(f"alignment rules in {queries_dir() / 'alignment'} did not reach a fixpoint in {MAX_ROUNDS} runs per rule")


def _entailed(terms: list[list[bytes]], type_lines: dict[bytes, tuple[tuple[bytes, bytes], ...]],
              known: set[bytes]) -> dict[bytes, list[bytes]]:
    """The ``rdf:type`` lines not ``known`` (they join it) that the split lines ``terms`` entail
    (rule-named superclasses), each with its terms."""
    entailed = {line: [subject, _TYPE, obj] for subject, predicate, stated in terms if predicate == _TYPE
                for suffix, obj in type_lines.get(stated[:-2], ()) if (line := subject + suffix) not in known}
    known.update(entailed)
    return entailed


@lru_cache(maxsize=4096)
def _object_value(text: bytes) -> str:
    """The IRI, blank node id or lexical form of an N-Triples object term."""
    if text.startswith(b"<"):
        return text[1:-1].decode()
    return next(iter(ox.parse(b"<urn:s> <urn:p> %s ." % text, format=ox.RdfFormat.N_TRIPLES))).object.value


