"""Alignment: derive the canonical SAREF/FSO view the signatures match from what a model states.

Each rule is one SPARQL CONSTRUCT in ``queries/alignment/*.rq`` (its header says what it derives and
why): SAREF v3.1.1 spellings to the v3.2.1/v4 ones, SAREF4BLDG v1.1.2 nominal values to the v2.1.1
PropertyValue chain, QUDT quantity kinds to property classes, measuring-device classes from what a
device observes (the accepted spellings are listed in ``ontologies/README.md``).

The rules run in a scratch in-memory store holding the model, the ontology subsets and what has been
derived so far, in file-name order, each seeing what the rules before it derived. A rule runs again
only when a triple it could read was added after its last run (:func:`service.sparql_reads.query_reads`:
the predicates of its patterns with the objects they can take, so ``VALUES ?rule {"02-…"}`` on
``gt:derivedByRule`` is not woken by every rule's provenance), the earliest such rule first, until
none is left: a fixpoint (rules only add triples and mint IRIs from the nodes they read — never
blank nodes, which a CONSTRUCT makes anew on every run — so this terminates). On a Brick campus the 14
rules take about 25 runs, the costly point-link and sensor-placement rules one each, where a
confirming round of every rule after the last addition doubled the time. The order makes the rules
stratified: a rule may test for the absence of a triple (``FILTER NOT EXISTS``) only when the triple
is stated in the model or derived by a rule earlier in the order, so that its answer cannot change
later. The Brick rules use this: the typing rules (``0N-brick-*.rq``) run first, the flow rules
(``5N-brick-*.rq``) after the device classes of ``50`` (whose entailed ``saref:Device`` types the
flow-edge rule reads; either order re-runs one of the two once), and the sensor placement rule reads
the flow edges and mixing boxes of the rule before it.

A large model is cut into independent parts (:func:`independent_parts`: no rule joins across them)
aligned side by side, one scratch store per part on a thread per CPU: Oxigraph evaluates a rule and
writes its result without holding Python's lock, and triples stay N-Triples lines from the model to
the result (they hash and compare at C speed; a term object per triple cost more than the rules).

The scratch store also holds, for every ``rdf:type`` triple of the model or derived, the types it
entails by ``rdfs:subClassOf`` in the ontology — only those a rule names (:func:`rule_terms`), so a
rule writes ``?point a brick:Temperature_Sensor`` and matches every official subclass without a
property path (``a/rdfs:subClassOf*`` per node made the Brick rules minutes long at 10⁴ triples).
These entailed triples are not part of the result: the store's queries see the hierarchy in the
ontology graph. Computing locally keeps the store's write of the model and its
inferences one transaction, and works the same whatever the backend. The user's graph is never
changed: the result goes to the model's ``inferred`` graph (:meth:`service.store.GraphStore.load_model`).

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
from collections.abc import Iterable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from functools import lru_cache
from itertools import chain

import numpy as np
import pyoxigraph as ox
from scipy.sparse import coo_array
from scipy.sparse.csgraph import connected_components

from .blank_nodes import skolemize
from .cpu_count import usable_cpu_count
from .cyclic_gc import cyclic_gc_paused
from .resources import queries_dir
from .sparql_reads import QueryReads, query_reads

__all__ = ["MAX_ROUNDS", "PART_TRIPLES", "alignment_rules", "independent_parts", "inferred_ntriples", "inferred_triples", "rule_terms"]

_RDF_TYPE = ox.NamedNode("http://www.w3.org/1999/02/22-rdf-syntax-ns#type")
_TYPE = str(_RDF_TYPE).encode()
_TYPE_INFIX = b" %s " % _TYPE
_BLANK_NODE_NAMESPACE = "urn:graphtwin:alignment:blank-node:"
_SUBCLASS_OF = ox.NamedNode("http://www.w3.org/2000/01/rdf-schema#subClassOf")
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
#: side by side on threads (Oxigraph evaluates a query without holding Python's lock). Of 5k, 12k,
#: 25k and 60k, 25k cost the least CPU on the 1M-triple campus (29.5 s; 34.6 s at 5k, where the
#: per-part set-up and rule runs add up; 30.8 s at 60k).
PART_TRIPLES = 25_000


@lru_cache(maxsize=1)
def alignment_rules() -> tuple[tuple[str, str], ...]:
    """``(file name, query text)`` of every rule in ``queries/alignment``, in file-name order."""
    return tuple((p.name, p.read_text(encoding="utf-8")) for p in sorted((queries_dir() / "alignment").glob("*.rq")))


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
    """class → its strict superclasses (``rdfs:subClassOf`` closure) that a rule names."""
    parents: dict[ox.NamedNode, set[ox.NamedNode]] = defaultdict(set)
    for t in ontology:
        if t.predicate == _SUBCLASS_OF and isinstance(t.object, ox.NamedNode) and isinstance(t.subject, ox.NamedNode):
            parents[t.subject].add(t.object)
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


def inferred_ntriples(model: Iterable[ox.Triple], ontology: Iterable[ox.Triple], *,
                      workers: int | None = None, part_triples: int = PART_TRIPLES) -> bytes:
    """What the alignment rules derive from ``model`` with the ``ontology`` class hierarchy, as
    N-Triples: every derived triple not already stated in either (each independent part's in the
    order its rules derived them, the parts in the order of the model).

    :param workers: threads aligning independent parts side by side (default: one per CPU this
        process may run on).
    :param part_triples: the size the model's independent parts are packed into (see
        :func:`independent_parts`); a model smaller than two parts is aligned whole.
    :raises ValueError: when the model or the ontology holds a blank node (a load into the scratch
        store would rename it; skolemise first, as :meth:`service.store.GraphStore.load_model` does,
        or call :func:`inferred_triples`).
    :raises RuntimeError: when the rules have not reached a fixpoint in :data:`MAX_ROUNDS` runs per
        rule (a rule that keeps minting new terms).
    """
    text = ox.serialize(model, format=ox.RdfFormat.N_TRIPLES)
    context = _Context.of(list(ontology))
    if _has_blank_node(text) or _has_blank_node(context.ontology):
        raise ValueError("the alignment needs a model and ontology without blank nodes: skolemise them first")
    lines = text.split(b"\n")[:-1]
    with cyclic_gc_paused():
        if len(lines) < 2 * part_triples:
            return _ntriples(_derived(text, context))
        shared, parts = independent_parts(lines, context.vocabulary, part_triples)
        with ThreadPoolExecutor(workers or usable_cpu_count()) as pool:
            derived = dict.fromkeys(chain.from_iterable(pool.map(
                lambda part: _derived(_ntriples(shared + part), context), parts)))
        stated = set(lines)  # a term one part mints may be stated in another
        return _ntriples([line for line in derived if line not in stated])


def _ntriples(lines: list[bytes]) -> bytes:
    """N-Triples text of ``lines`` (each line ends with a newline)."""
    return b"\n".join(lines) + b"\n" if lines else b""


def inferred_triples(model: Iterable[ox.Triple], ontology: Iterable[ox.Triple], **options) -> list[ox.Triple]:
    """:func:`inferred_ntriples` as triples (``options`` as there); blank nodes are allowed: they
    are aligned as IRIs and named back."""
    names: dict[ox.BlankNode, ox.NamedNode] = {}
    model, ontology = (skolemize(triples, _BLANK_NODE_NAMESPACE, names) for triples in (model, ontology))
    triples = [t.triple for t in ox.parse(inferred_ntriples(model, ontology, **options), format=ox.RdfFormat.N_TRIPLES)]
    if names:
        blank = {iri: node for node, iri in names.items()}

        def named_back(term):
            return blank.get(term, term)

        triples = [ox.Triple(named_back(t.subject), t.predicate, named_back(t.object)) for t in triples]
    return triples


def independent_parts(lines: list[bytes], vocabulary: tuple[bytes, ...],
                      part_triples: int) -> tuple[list[bytes], list[list[bytes]]]:
    """``(shared, parts)`` of a model's N-Triples ``lines``: the model cut where no rule can join
    across, so that each part aligned with ``shared`` derives what the whole model derives about it.

    The rules join model resources only through model resources: a node links the triples that name
    it unless it is a literal, a class (the object of ``rdf:type``), or ``vocabulary`` (IRIs starting
    with one of those N-Triples prefixes: the namespaces of the classes and properties the ontology
    declares, and QUDT's). The parts are the connected components of the model's triples under that
    linking, packed in model order into parts of at least ``part_triples`` triples (a component is
    never split: a campus whose units share a plant is one component). ``shared``: the model's own
    schema — triples whose predicate is OWL's or ``rdfs:subClassOf``, ``subPropertyOf``, ``domain``
    or ``range``, or whose subject is a class or vocabulary — that every part needs, as it needs the
    ontology.
    """
    triples = [line.split(b" ", 2) for line in lines]
    classes = {o[:-2] for _s, p, o in triples if p == _TYPE}
    schema = [p.startswith(_SCHEMA_PREDICATES) or s in classes or s.startswith(vocabulary) for s, p, _o in triples]
    shared = [line for line, is_schema in zip(lines, schema, strict=True) if is_schema]
    body = [(line, t) for line, t, is_schema in zip(lines, triples, schema, strict=True) if not is_schema]
    ids: dict[bytes, int] = {}
    subject_ids = [ids.setdefault(s, len(ids)) for _line, (s, _p, _o) in body]
    links = [(i, ids.setdefault(o[:-2], len(ids))) for i, (_line, (_s, p, o)) in zip(subject_ids, body, strict=True)
             if p != _TYPE and not o.startswith(b'"') and not o.startswith(vocabulary)]
    starts, ends = np.array(links, dtype=np.int64).reshape(-1, 2).T
    adjacency = coo_array((np.ones(len(starts), dtype=np.int8), (starts, ends)), shape=(len(ids), len(ids)))
    _count, component = connected_components(adjacency, directed=False)
    triple_component = component[np.asarray(subject_ids, dtype=np.int64)]
    # components in order of their first triple, packed into parts of at least part_triples
    components, first_triple = np.unique(triple_component, return_index=True)
    sizes = np.bincount(triple_component)
    part_of, part, filled = {}, 0, 0
    for c in components[np.argsort(first_triple)].tolist():
        if filled >= part_triples:
            part, filled = part + 1, 0
        part_of[c] = part
        filled += sizes[c]
    parts: list[list[bytes]] = [[] for _ in range(part + 1)]
    for (line, _t), c in zip(body, triple_component.tolist(), strict=True):
        parts[part_of[c]].append(line)
    return shared, parts


def _has_blank_node(text: bytes) -> bool:
    """Whether N-Triples ``text`` has a blank node (``_:`` opening a line or after a space; inside a
    literal it may be a false alarm, which only costs the caller a skolemisation)."""
    return text.startswith(b"_:") or b" _:" in text or b"\n_:" in text


def _namespace(iri: str) -> str:
    """The IRI up to and including its last ``#`` or ``/``."""
    return iri[: max(iri.rfind("#"), iri.rfind("/")) + 1]


@dataclass(frozen=True)
class _Context:
    """What every part's alignment shares (read-only, so threads share it): the ontology as N-Triples
    and as lines; for each class (N-Triples) the lines `` <rdf:type> <super> .`` of its rule-named
    superclasses (each line without its subject); what each rule reads, and the predicates
    (N-Triples) some rule reads only some objects of; the rules' texts; the vocabulary prefixes of
    :func:`independent_parts`."""

    ontology: bytes
    ontology_lines: frozenset[bytes]
    type_lines: dict[bytes, tuple[bytes, ...]]
    reads: tuple[QueryReads, ...]
    restricted: frozenset[bytes]
    rules: tuple[str, ...]
    vocabulary: tuple[bytes, ...]

    @classmethod
    def of(cls, ontology: list[ox.Triple]) -> _Context:
        text = ox.serialize(ontology, format=ox.RdfFormat.N_TRIPLES)
        type_lines = {str(c).encode(): tuple(b" %s %s ." % (_TYPE, str(s).encode()) for s in supers)
                      for c, supers in _named_superclasses(ontology).items()}
        rules = tuple(text for _name, text in alignment_rules())
        reads = tuple(map(query_reads, rules))  # parsed here, not on the threads
        restricted = frozenset(f"<{p}>".encode() for r in reads for p, objects in r.objects.items() if objects is not None)
        declared = {t.subject.value for t in ontology if t.predicate == _RDF_TYPE and t.object in _DECLARATIONS}
        vocabulary = tuple(sorted({f"<{_namespace(iri)}".encode() for iri in declared | {_QUDT_NAMESPACE}}))
        return cls(text, frozenset(text.split(b"\n")), type_lines, reads, restricted, rules, vocabulary)


def _derived(model_text: bytes, context: _Context) -> list[bytes]:
    """The rules run to their fixpoint on the N-Triples ``model_text`` (see :func:`inferred_ntriples`):
    the lines derived, in order. Triples are lines of N-Triples throughout — the store evaluates a
    rule and writes its result without Python's lock, and lines hash and compare at C speed."""
    scratch = ox.Store()
    scratch.load(model_text + context.ontology, ox.RdfFormat.N_TRIPLES, lenient=True)  # Oxigraph wrote it
    stated = model_text.split(b"\n")
    known = set(stated)  # stated, derived or entailed
    known |= context.ontology_lines
    derived: list[bytes] = []

    def add(text: bytes) -> list[bytes]:
        """Add to the scratch store the lines of ``text`` not known yet, with the types they entail;
        returns those added (entailed ones not among them) and extends ``added``."""
        fresh = [line for line in dict.fromkeys(text.split(b"\n")) if line not in known]
        known.update(fresh)
        entailed = [line for line in _entailed(fresh, context.type_lines) if line not in known]
        known.update(entailed)
        scratch.load(b"\n".join(fresh + entailed), ox.RdfFormat.N_TRIPLES, lenient=True)
        for line in fresh + entailed:
            _subject, predicate, obj = line.split(b" ", 2)
            added[predicate].add(obj[:-2])
        return fresh

    added: defaultdict[bytes, set[bytes]] = defaultdict(set)
    add(b"\n".join(_entailed(stated, context.type_lines)))
    texts = context.rules
    # A rule's answer is a function of what it reads, so it need not run again until a triple it could
    # read was added (by any rule, itself included) since its last run.
    pending = [True] * len(texts)
    for _run in range(MAX_ROUNDS * len(texts)):
        if True not in pending:
            return derived
        rule = pending.index(True)
        pending[rule] = False
        added.clear()
        derived += add(scratch.query(texts[rule]).serialize(format=ox.RdfFormat.N_TRIPLES))
        values = {p[1:-1].decode(): ({_object_value(o) for o in objects} if p in context.restricted else ())
                  for p, objects in added.items()}
        pending = [waiting or other.may_read(values) for waiting, other in zip(pending, context.reads, strict=True)]
    raise RuntimeError(f"alignment rules in {queries_dir() / 'alignment'} did not reach a fixpoint in {MAX_ROUNDS} runs per rule")


def _entailed(lines: Iterable[bytes], type_lines: dict[bytes, tuple[bytes, ...]]) -> list[bytes]:
    """The ``rdf:type`` lines that the type lines among ``lines`` entail (rule-named superclasses)."""
    entailed = []
    for line in lines:
        if _TYPE_INFIX in line:
            subject, predicate, obj = line.split(b" ", 2)
            if predicate == _TYPE and obj[:-2] in type_lines:
                entailed += [subject + suffix for suffix in type_lines[obj[:-2]]]
    return entailed


@lru_cache(maxsize=4096)
def _object_value(text: bytes) -> str:
    """The IRI, blank node id or lexical form of an N-Triples object term."""
    if text.startswith(b"<"):
        return text[1:-1].decode()
    return next(iter(ox.parse(b"<urn:s> <urn:p> %s ." % text, format=ox.RdfFormat.N_TRIPLES))).object.value


