"""Alignment of one part: the rules of ``queries/alignment`` run to their fixpoint on a model's N-Triples.

Each rule is one SPARQL CONSTRUCT, run in file-name order in a scratch in-memory store holding the
part, the ontology lines some rule can read and what has been derived so far; a rule runs again only
when a triple it could read (:func:`service.graph.sparql_reads.query_reads`) was added since its last
run, until none is left or :data:`MAX_ROUNDS` runs per rule. The store also holds the ``rdf:type``
lines each type entails by ``rdfs:subClassOf``/``owl:equivalentClass`` (superclasses a rule names);
those are not part of the result. What a worker thread or process runs (:func:`_aligned_part`);
:mod:`service.graph.alignment` cuts the model and gathers the parts. Why: ``docs/alignment.md``.
"""

from __future__ import annotations

import re
from collections import defaultdict
from collections.abc import Iterable
from dataclasses import dataclass, replace
from functools import lru_cache
from typing import NamedTuple

import pyoxigraph as ox

from service.graph.sparql_reads import QueryReads, query_reads
from service.resources import queries_dir

__all__ = ["MAX_ROUNDS", "BlankNodeError", "alignment_rules", "rule_terms"]

_RDF_TYPE = ox.NamedNode("http://www.w3.org/1999/02/22-rdf-syntax-ns#type")
_TYPE = str(_RDF_TYPE).encode()
_TYPE_INFIX = b" %s " % _TYPE
_SUBCLASS_OF = ox.NamedNode("http://www.w3.org/2000/01/rdf-schema#subClassOf")
_EQUIVALENT_CLASS = ox.NamedNode("http://www.w3.org/2002/07/owl#equivalentClass")
_PREFIX = re.compile(r"PREFIX\s+([\w-]*):\s*<([^>]+)>", re.IGNORECASE)
_TERM = re.compile(r"<([^>\s]+)>|(?<![\w?$])([A-Za-z][\w-]*):([A-Za-z_][\w-]*)")
_COMMENT = re.compile(r"(^|\s)#[^\n]*")

#: Safety cap on the fixpoint: at most this many runs per rule on average (the shipped rules reach it
#: in one run each, and a second of the few that read what the last ones added).
MAX_ROUNDS = 8


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


class BlankNodeError(ValueError):
    """A model or ontology given to the alignment holds a blank node."""

    def __init__(self) -> None:
        super().__init__("the alignment needs a model and ontology without blank nodes: skolemise them first")


def _has_blank_node(text: bytes) -> bool:
    """Whether N-Triples ``text`` has a blank node (``_:`` opening a line or after a space; inside a
    literal it may be a false alarm, which only costs the caller a skolemisation)."""
    return b"_:" in text and (text.startswith(b"_:") or b" _:" in text or b"\n_:" in text)


def _ntriples(lines: list[bytes]) -> bytes:
    """N-Triples text of ``lines`` (each line ends with a newline)."""
    return b"\n".join(lines) + b"\n" if lines else b""


@dataclass(frozen=True)
class _Context:
    """What every part's alignment shares (read-only, so threads share it; pickled to worker
    processes): the ontology as N-Triples text and as lines, and the lines of it some rule can read
    (:meth:`unread`: what a part's scratch store loads); for each class (N-Triples) the lines
    `` <rdf:type> <super> .`` of its rule-named superclasses by the ontology's and the model's
    ``rdfs:subClassOf``, each without its subject and with its object ``<super> .``; what each rule
    reads, and the predicates (N-Triples) some rule reads only some objects of; what any rule reads
    (:meth:`unread`); the rules' texts."""

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
        the scratch store (provenance, columns, units, assumption texts and most derived classes).
        Decided once per distinct predicate or pair."""
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


def _aligned_part(text: bytes, context: _Context) -> tuple[bytes, list[bytes]]:
    """A part's N-Triples ``text`` aligned: what the rules derive as N-Triples text, and the
    subjects of its lines (on a worker thread, or in an alignment worker process)."""
    derived = _derived(text, context)
    return _ntriples(derived.lines), list(derived.subjects)


def _derived(model_text: bytes, context: _Context) -> _Derived:
    """The rules run to their fixpoint on the N-Triples ``model_text`` (module docstring): the lines
    derived, in order, and their subjects. Triples are lines of N-Triples throughout (they hash and
    compare at C speed); a line is split once, when it is new.

    :raises RuntimeError: no fixpoint in :data:`MAX_ROUNDS` runs per rule (a rule that keeps minting).
    """
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
