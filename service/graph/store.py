"""The graph store: every building model, ontology subset, signature and result in its own named graph.

Layout (IRIs from :func:`service.graph.namespaces.graph_iri`), so a user can drop or replace one graph
without touching the others:

==============================  ============================================================
``gtr:graph/ontology/core``     the ontology subsets in ``ontologies/`` (class hierarchy)
``gtr:graph/alignment/rules``   the alignment rules the inferred graphs were derived with
``gtr:graph/signatures/library`` the signature library as triples (``signature_triples``)
``gtr:graph/model/<name>``      a user's building model, as loaded
``gtr:graph/inferred/<name>``   what the alignment rules derive from it (``queries/alignment``)
``gtr:graph/assembly/<name>``   the assembled simulation model
``gtr:graph/run/<id>``          one calibration or diagnosis run's results
==============================  ============================================================

Two backends implement :class:`SparqlBackend`: :class:`EmbeddedBackend` (pyoxigraph on disk, or in
memory for tests) and :class:`service.graph.endpoint.SparqlEndpointBackend` (any SPARQL 1.1
endpoint with the graph store protocol). Contracts, as pyoxigraph's:

* every write is one transaction: a reader sees a graph before or after, never half of it; a model
  and what alignment infers from it are written together (:meth:`GraphStore.write_graphs`), and
  the model's old assembly is removed in the same write (a model loaded again unchanged is not
  written: :meth:`GraphStore.load_model`). The embedded store (:meth:`EmbeddedBackend.replace_graphs`)
  writes a small change to existing graphs as one update of the difference; otherwise, in memory,
  it loads the new triples into staging graphs (``gtr:staging/…``, a query over every named graph
  may see them for that moment) and moves them into place in one update, twice as fast as
  ``INSERT DATA``, and on disk it sends one ``INSERT DATA`` update. Its writes run one at a time, so
  two writes of the same graphs at once leave the last one whole, never both merged;
* a load parses everything first and raises :class:`ModelLoadError` (file, line, column) before
  anything is written: a failed load leaves the store as it was. A leading UTF-8 byte-order mark
  is skipped; an IRI that JSON-LD would drop silently (relative, invalid) is an error there as in
  the other formats;
* a model's blank nodes are skolemised on load (RDF 1.1 Concepts §3.5, :func:`skolemize`): each
  becomes an IRI ``gtr:model/<name>/genid/<n>``, numbered in order of appearance (skipping the IRIs
  of that form the file already holds, as a model exported from the store does), so it keeps its
  identity across graphs (inferred triples about it), across update requests (SPARQL ``INSERT DATA``
  renames blank nodes) and across backends, can be bound in a query, and reloading the same file
  gives the same triples;
* values reach queries through ``substitutions``: serialised by pyoxigraph (validated, escaped) into a
  ``VALUES`` block at the start of the outer WHERE group (:func:`bind_values`), the same way on
  every backend, never by splicing user text;
* query results are consumed into Python lists before they are returned (a lazy pyoxigraph
  ``QuerySolutions`` read on another thread raises in a FastAPI worker).
"""

from __future__ import annotations

import re
import threading
import uuid
from collections.abc import Collection, Iterable, Mapping, Sequence
from functools import lru_cache
from pathlib import Path
from typing import NamedTuple, Protocol, runtime_checkable
from xml.parsers import expat

import pyoxigraph as ox

from service.errors import ModelLoadError, StoreInUseError
from service.graph.alignment import alignment_rule_triples, inferred_ntriples, inferred_triples
from service.graph.blank_nodes import skolemize
from service.graph.namespaces import GTR, graph_iri
from service.graph.ntriples import GraphTriples, ntriples_chunks
from service.resources import ontologies_dir, queries_dir

__all__ = [
    "drain",
    "ModelLoad", "ModelLoadError", "StoreInUseError", "SparqlBackend", "bind_values", "insert_data_update", "EmbeddedBackend", "GraphStore",
    "rdf_format", "parse_rdf", "skolemize", "ONTOLOGY_GRAPH", "SIGNATURE_GRAPH",
]

Term = ox.NamedNode | ox.BlankNode | ox.Literal
ONTOLOGY_GRAPH = graph_iri("ontology", "core")
ALIGNMENT_RULES_GRAPH = graph_iri("alignment", "rules")
SIGNATURE_GRAPH = graph_iri("signatures", "library")
_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.\-+]{0,127}")  # 128 at most: a name is a file name too (uploads)
#: What pyoxigraph's syntax error messages start with (the position, given as ``lineno``/``offset``
#: too): ``Parser error at line 3 between columns 16 and 20: ``, ``… at line 2 column 11: ``,
#: ``… between line 2 column 11 and line 5 column 1: ``.
_POSITION_PREFIX = re.compile(r"^Parser error (at|between) line [^:]*: ")
_BOM = b"\xef\xbb\xbf"


class ModelLoad(NamedTuple):
    """What :meth:`GraphStore.load_model` did: the triples the source holds, whether the store
    changed (False: it held that model already, triple for triple, and kept it as it was), and
    whether a model of that name was there before."""

    triples: int
    changed: bool
    replaced: bool


_SUFFIXES = {
    "ttl": ox.RdfFormat.TURTLE, "turtle": ox.RdfFormat.TURTLE, "nt": ox.RdfFormat.N_TRIPLES,
    "ntriples": ox.RdfFormat.N_TRIPLES, "n-triples": ox.RdfFormat.N_TRIPLES, "rdf": ox.RdfFormat.RDF_XML,
    "xml": ox.RdfFormat.RDF_XML, "owl": ox.RdfFormat.RDF_XML, "rdfxml": ox.RdfFormat.RDF_XML,
    "rdf/xml": ox.RdfFormat.RDF_XML, "jsonld": ox.RdfFormat.JSON_LD, "json-ld": ox.RdfFormat.JSON_LD,
    "json": ox.RdfFormat.JSON_LD,
}


def rdf_format(name_or_suffix: str) -> ox.RdfFormat:
    """``"ttl"``, ``".jsonld"``, ``"rdf/xml"``, ``"text/turtle"``… → the pyoxigraph format.

    :raises ValueError: for an unsupported format, listing the supported ones.
    """
    key = name_or_suffix.lower().lstrip(".").split(";")[0].strip()
    if key in _SUFFIXES:
        return _SUFFIXES[key]
    by_media = ox.RdfFormat.from_media_type(key)
    if by_media in (ox.RdfFormat.TURTLE, ox.RdfFormat.N_TRIPLES, ox.RdfFormat.RDF_XML, ox.RdfFormat.JSON_LD):
        return by_media
    raise ValueError(
        f"unsupported RDF format {name_or_suffix!r}: use Turtle (.ttl), N-Triples (.nt), RDF/XML (.rdf) or JSON-LD (.jsonld)"
    )


def parse_rdf(data: bytes, fmt: ox.RdfFormat, source_name: str, base_iri: str | None = None) -> list[ox.Triple]:
    """Parse completely (nothing is written anywhere) or raise :class:`ModelLoadError`.

    A leading UTF-8 byte-order mark is skipped. RDF/XML must be well-formed XML (checked by expat
    first, which names the line and column; pyoxigraph reads a document cut short up to the cut).
    JSON-LD may not hold an IRI that is relative (without ``base_iri``) or invalid, nor an invalid
    language tag: where the JSON-LD algorithms drop the triple, this names it.
    """
    data = data.removeprefix(_BOM)
    if fmt == ox.RdfFormat.RDF_XML:
        _check_well_formed_xml(data, source_name)
    quads = _parsed(data, fmt, source_name, base_iri)
    if fmt == ox.RdfFormat.JSON_LD:
        lenient = _parsed(data, fmt, source_name, base_iri, lenient=True)
        if len(lenient) != len(quads):
            raise _dropped_by_json_ld(lenient, len(lenient) - len(quads), source_name)
    return [ox.Triple(q.subject, q.predicate, q.object) for q in quads]


def _parsed(data: bytes, fmt: ox.RdfFormat, source_name: str, base_iri: str | None, lenient: bool = False) -> list[ox.Quad]:
    """Every quad of ``data``, or :class:`ModelLoadError` (with pyoxigraph's position, named once)."""
    try:
        return list(ox.parse(data, format=fmt, base_iri=base_iri, lenient=lenient))
    except SyntaxError as exc:
        message = _POSITION_PREFIX.sub("", exc.msg or str(exc))
        raise ModelLoadError(source_name, message, exc.lineno, exc.offset) from None
    except (ValueError, UnicodeDecodeError) as exc:
        raise ModelLoadError(source_name, str(exc)) from None


def _check_well_formed_xml(data: bytes, source_name: str) -> None:
    """:raises ModelLoadError: ``data`` is not well-formed XML (line, column of the first error)."""
    try:
        expat.ParserCreate().Parse(data, True)
    except expat.ExpatError as exc:
        message = expat.ErrorString(exc.code)
        if exc.code == expat.errors.codes[expat.errors.XML_ERROR_NO_ELEMENTS]:
            message += " (the document has no root element, or ends before it is closed)"
        raise ModelLoadError(source_name, f"not well-formed XML: {message}", exc.lineno, exc.offset + 1) from None


def _dropped_by_json_ld(lenient: list[ox.Quad], dropped: int, source_name: str) -> ModelLoadError:
    """The error for a JSON-LD document whose strict parse dropped ``dropped`` triples its ``lenient``
    parse kept: it names the first triple with an invalid IRI or language tag."""
    for quad in lenient:
        for term in (quad.subject, quad.predicate, quad.object, quad.graph_name):
            try:
                if isinstance(term, ox.NamedNode):
                    ox.NamedNode(term.value)
                elif isinstance(term, ox.Literal) and term.language is not None:
                    ox.Literal(term.value, language=term.language)
            except ValueError as exc:
                triple = f"{quad.subject} {quad.predicate} {quad.object}"
                if isinstance(term, ox.NamedNode):
                    return ModelLoadError(source_name, (
                        f"invalid IRI {term.value!r} ({exc}) in the triple {triple}: an @id, @type, key or IRI "
                        "value the @context does not expand to an absolute IRI (JSON-LD would drop the triple)"))
                return ModelLoadError(source_name, (
                    f"invalid language tag {term.language!r} ({exc}) in the triple {triple} (JSON-LD would drop it)"))
    return ModelLoadError(source_name, f"JSON-LD would drop {dropped} triples holding an invalid term")


@runtime_checkable
class SparqlBackend(Protocol):
    """What graphtwin needs from a quad store. Implemented by :class:`EmbeddedBackend` and
    :class:`service.graph.endpoint.SparqlEndpointBackend` (HTTP SPARQL 1.1 protocol and
    graph store protocol).

    ``query`` returns, fully consumed: for SELECT ``list[dict[str, term]]`` (unbound variables
    absent), for ASK ``bool``, for CONSTRUCT ``list[Triple]``; ``substitutions`` bind variables
    (:func:`bind_values`); ``default_graph`` lists the named graphs whose union is the default graph.
    ``update`` runs a SPARQL update request as one transaction. ``replace_graph`` and ``load_graph``
    replace one named graph atomically, ``replace_graphs`` several in one transaction (each given as
    :data:`~service.graph.ntriples.GraphTriples`: triples, or N-Triples text whole or in chunks; none: the
    graph is removed; blank nodes shared between them stay shared); ``load_graph`` parses completely first and raises :class:`ModelLoadError`, leaving the
    store untouched.
    """

    def query(self, sparql: str, *, substitutions: Mapping[str, Term] | None = None,
              default_graph: Sequence[ox.NamedNode] | None = None): ...

    def update(self, sparql: str) -> None: ...

    def replace_graph(self, graph: ox.NamedNode, triples: Iterable[ox.Triple]) -> None: ...

    def replace_graphs(self, graphs: Mapping[ox.NamedNode, GraphTriples]) -> None: ...

    def load_graph(self, graph: ox.NamedNode, data: bytes, format: ox.RdfFormat, *,
                   base_iri: str | None = None, source_name: str = "<data>") -> int: ...

    def drop_graph(self, graph: ox.NamedNode) -> None: ...

    def graphs(self) -> list[ox.NamedNode]: ...

    def dump(self, graph: ox.NamedNode, format: ox.RdfFormat) -> bytes: ...

    def triple_count(self, graph: ox.NamedNode) -> int: ...


def drain(result, convert=lambda item: item, limit: int | None = None) -> list:
    """The first ``limit`` (all when None) items of a lazy pyoxigraph result (``QuerySolutions`` or
    ``QueryTriples``), each passed through ``convert``, read and released on this thread.

    pyoxigraph's lazy results are unsendable: one dropped on another thread raises. Holding one in
    a frame's local is enough for that to happen: a sampling profiler (a Dask worker's) keeps the
    frame objects it samples, with their locals, and releases them on its own thread. So the result
    is read in a plain loop (a comprehension's frame would hold it too) and the local is deleted
    before this frame ends, whatever happens.
    """
    items = []
    try:
        for item in result:
            if limit is not None and len(items) >= limit:
                break
            items.append(convert(item))
    finally:
        del result
    return items


def _rows(result) -> list[dict[str, Term]] | bool | list[ox.Triple]:
    """A pyoxigraph query result as plain Python values (every frame that holds a lazy result
    deletes it before it ends: see :func:`drain`)."""
    try:
        if isinstance(result, ox.QueryBoolean):
            return bool(result)
        if isinstance(result, ox.QuerySolutions):
            names = [v.value for v in result.variables]

            def row(solution) -> dict[str, Term]:
                return {name: value for name in names if (value := solution[name]) is not None}

            return drain(result, row)
        return drain(result)
    finally:
        del result


_COMMENT = re.compile(r"(^|\s)#[^\n]*")
_GROUP_START = re.compile(r"\b(WHERE|ASK)\s*\{", re.IGNORECASE)


def bind_values(sparql: str, substitutions: Mapping[str, Term] | None) -> str:
    """Bind variables by a ``VALUES`` block at the start of the outermost ``WHERE`` (or ``ASK``)
    group: ``WHERE { VALUES (?device) { (<iri>) } …``. The terms are serialised by pyoxigraph
    (validated and escaped), never spliced from user text; a variable need not be projected.

    :raises ValueError: when the query has no WHERE/ASK group.
    """
    if not substitutions:
        return sparql
    blanked = _COMMENT.sub(lambda m: m.group(1) + " " * (len(m.group(0)) - len(m.group(1))), sparql)
    match = _GROUP_START.search(blanked)
    if match is None:
        raise ValueError("cannot bind variables: the query has no WHERE group")
    names = " ".join(f"?{name}" for name in substitutions)
    values = " ".join(str(term) for term in substitutions.values())
    block = f" VALUES ({names}) {{ ({values}) }} "
    return sparql[: match.end()] + block + sparql[match.end():]


def query_bound(store: ox.Store, sparql: str, substitutions: Mapping[str, Term] | None, **kwargs):
    """``store.query`` with ``substitutions`` bound (the lazy result; read it with :func:`drain`).

    Variables the query projects are bound by Oxigraph's own substitution (SEP-0007: the constant
    replaces the variable in every pattern, so the indexes are used: 15 ms against 0.5 s for
    ``calibrated-parameters.rq`` over 1,000 buildings' results, where a ``VALUES`` join evaluates
    the patterns for every model first); others by :func:`bind_values`.
    """
    if substitutions:
        try:
            return store.query(sparql, substitutions={ox.Variable(k): v for k, v in substitutions.items()}, **kwargs)
        except RuntimeError:  # a variable the query does not project: SEP-0007 cannot bind it
            pass
    return store.query(bind_values(sparql, substitutions), **kwargs)


def insert_data_update(graphs: Mapping[ox.NamedNode, GraphTriples]) -> str:
    """``DROP SILENT GRAPH <g> ; … ; INSERT DATA { GRAPH <g> { … } … }``: the ``graphs`` replaced in
    one update request, one transaction (a graph with no triples is removed; ``INSERT DATA`` keeps a
    blank node shared between its graph blocks)."""
    blocks = []
    for graph, triples in graphs.items():
        if text := b"".join(ntriples_chunks(triples)):
            blocks.append(f"GRAPH {graph} {{\n{text.decode()}}}")
    update = " ;\n".join(f"DROP SILENT GRAPH {graph}" for graph in graphs)
    return update + (" ;\nINSERT DATA {\n" + "\n".join(blocks) + "\n}" if blocks else "")


def _nquads(graphs: Mapping[ox.NamedNode, list[bytes]]) -> bytes:
    """N-Quads of N-Triples chunks, each in its graph (blank node labels kept: shared between graphs).
    Every line of N-Triples ends with `` .`` and a newline, which a literal cannot hold unescaped."""
    return b"".join(chunk.replace(b" .\n", b" %s .\n" % str(graph).encode())
                    for graph, chunks in graphs.items() for chunk in chunks)


#: Named graphs a write stages its data in before moving it into place (left only by a crash between
#: the two, and removed when the store is opened again).
STAGING = f"{GTR}staging/"


class EmbeddedBackend:
    """pyoxigraph :class:`~pyoxigraph.Store` on disk under ``path`` (created if missing), or in memory.

    Its writes run one at a time: a replacement checks which graphs exist and writes accordingly,
    and two at once could both find a new graph missing and both add to it.

    :raises StoreInUseError: another process (or an open :class:`EmbeddedBackend` of this one) holds
        the store at ``path``.
    """

    def __init__(self, path: Path | None = None):
        self.path = Path(path) if path is not None else None
        self._write_lock = threading.RLock()
        if self.path is not None:
            self.path.mkdir(parents=True, exist_ok=True)
            self.store = _open_store(self.path)
        else:
            self.store = ox.Store()
        for graph in [g for g in self.store.named_graphs() if g.value.startswith(STAGING)]:
            self.store.remove_graph(graph)

    def query(self, sparql, *, substitutions=None, default_graph=None):
        kwargs = {}
        if default_graph is not None:
            kwargs["default_graph"] = list(default_graph)
        return _rows(query_bound(self.store, sparql, substitutions, **kwargs))

    def update(self, sparql):
        with self._write_lock:
            self.store.update(sparql)

    def replace_graph(self, graph, triples):
        self.replace_graphs({graph: triples})

    def replace_graphs(self, graphs):
        """One N-Quads load (a transaction) when none of ``graphs`` exists yet. Else one update of
        the difference (:meth:`_difference_update`) when it is small: a model edited and loaded
        again. Else, in memory, the load into staging graphs, then one update that moves them into
        place (2× faster than parsing the triples as ``INSERT DATA``); on disk, where moving a graph
        copies and deletes it in one RocksDB transaction, one ``DROP`` + ``INSERT DATA`` update (a
        300k-triple model replaced in 28–31 s, not 48–54 s)."""
        texts = {g: [chunk for chunk in ntriples_chunks(t) if chunk] for g, t in graphs.items()}
        with self._write_lock:
            if not any(self.store.contains_named_graph(g) for g in texts):
                self.store.load(_nquads(texts), ox.RdfFormat.N_QUADS, lenient=True)  # Oxigraph wrote the lines
                return
            if (update := self._difference_update(texts)) is not None:
                if update:
                    self.update(update)
                return
            if self.path is not None:
                self.update(insert_data_update(texts))
                return
            run = uuid.uuid4().hex
            staging = {g: ox.NamedNode(f"{STAGING}{run}/{i}") for i, g in enumerate(texts) if texts[g]}
            self.store.load(_nquads({staging[g]: texts[g] for g in staging}), ox.RdfFormat.N_QUADS, lenient=True)
            self.update(" ;\n".join(
                f"DROP SILENT GRAPH {g}" + (f" ;\nMOVE {staging[g]} TO {g}" if g in staging else "") for g in texts))

    def _difference_update(self, texts: Mapping[ox.NamedNode, list[bytes]]) -> str | None:
        """One update turning each graph into its N-Triples ``texts`` by deleting the lines it no longer
        has and inserting the new ones (a graph given none is dropped; "" when nothing changes), or
        None when that is no smaller than rewriting the graphs, or a line to delete or insert holds a
        blank node (``DELETE DATA`` cannot name one; the store's labels are not the text's). Lines
        are compared as pyoxigraph writes them; reading the graphs costs 1.6 s at 300k triples on disk,
        a rewrite 28–31 s."""
        removed, added, rewritten = {}, {}, 0
        for graph, chunks in texts.items():
            new = set(b"".join(chunks).splitlines())
            if not new:  # dropped below: not read
                continue
            held = set(self.dump(graph, ox.RdfFormat.N_TRIPLES).splitlines())
            removed[graph], added[graph] = held - new, new - held
            rewritten += len(new)
        changed = [line for lines in (*removed.values(), *added.values()) for line in lines]
        if 2 * len(changed) > rewritten or any(b"_:" in line for line in changed):
            return None

        def block(lines_of: Mapping[ox.NamedNode, set[bytes]]) -> str:
            return "\n".join(f"GRAPH {g} {{\n" + b"\n".join(lines).decode() + "\n}"
                             for g, lines in lines_of.items() if lines)

        steps = [f"DROP SILENT GRAPH {g}" for g in texts if not texts[g] and self.store.contains_named_graph(g)]
        if any(removed.values()):
            steps.append(f"DELETE DATA {{\n{block(removed)}\n}}")
        if any(added.values()):
            steps.append(f"INSERT DATA {{\n{block(added)}\n}}")
        return " ;\n".join(steps)

    def load_graph(self, graph, data, format, *, base_iri=None, source_name="<data>"):
        triples = parse_rdf(data, format, source_name, base_iri)
        self.replace_graph(graph, triples)
        return len(triples)

    def drop_graph(self, graph):
        with self._write_lock:
            if self.store.contains_named_graph(graph):
                self.store.remove_graph(graph)

    def graphs(self):
        return sorted(self.store.named_graphs(), key=lambda g: g.value)

    def dump(self, graph, format):
        return self.store.dump(format=format, from_graph=graph) or b""

    def triple_count(self, graph):
        return sum(1 for _ in self.store.quads_for_pattern(None, None, None, graph))


def _open_store(path: Path) -> ox.Store:
    """The pyoxigraph store under ``path``.

    :raises StoreInUseError: when RocksDB cannot take the store's lock (its messages: ``While lock
        file: …`` held by another process, ``lock hold by current process`` by this one).
    """
    try:
        return ox.Store(str(path))
    except OSError as exc:
        if "While lock file" in str(exc):
            raise StoreInUseError(f"store {path} is in use by another process (another graphtwin command, or a running "
                                  "graphtwin serve; a store has one user at a time)") from exc
        if "lock hold by current process" in str(exc):
            raise StoreInUseError(f"store {path} is open already in this process") from exc
        raise


@lru_cache(maxsize=None)
def _named_query_text(path: Path) -> str:
    return path.read_text(encoding="utf-8")


def _term(name: str, value) -> Term:
    """A query parameter as a term: str starting with http(s):// or urn: → IRI, other str, bool,
    int and float → literal (xsd:string, boolean, integer, double), pyoxigraph terms as they are."""
    if isinstance(value, (ox.NamedNode, ox.BlankNode, ox.Literal)):
        return value
    if isinstance(value, str) and value.startswith(("http://", "https://", "urn:")):
        try:
            return ox.NamedNode(value)
        except ValueError as exc:
            raise ValueError(f"query parameter {name}: {value!r} is not a valid IRI ({exc})") from None
    if isinstance(value, (bool, int, float, str)):
        return ox.Literal(value)
    raise TypeError(f"query parameter {name}: cannot bind {value!r}; give a str, number or pyoxigraph term")


_GRAPH_TRIPLES = "CONSTRUCT { ?s ?p ?o } WHERE { GRAPH ?graph { ?s ?p ?o } }"


class GraphStore:
    """graphtwin's graph layout on top of a :class:`SparqlBackend`."""

    def __init__(self, backend: SparqlBackend):
        self.backend = backend
        self._ontology_triples: list[ox.Triple] | None = None
        # a model's graph and what is derived from it (inferences, assembly) are read, derived and
        # written under this lock, so a load and an update of the same model cannot interleave
        self._model_lock = threading.RLock()

    @classmethod
    def embedded(cls, path: Path | None = None) -> GraphStore:
        """On disk under ``path`` (the default deployment), in memory when None.

        :raises StoreInUseError: another process holds the store at ``path`` (:class:`EmbeddedBackend`).
        """
        return cls(EmbeddedBackend(path))

    @classmethod
    def remote(cls, url: str, token: str | None = None) -> GraphStore:
        """An external SPARQL 1.1 endpoint (Oxigraph server layout: ``/query``, ``/update``, ``/store``)."""
        from service.graph.endpoint import SparqlEndpointBackend

        return cls(SparqlEndpointBackend.for_oxigraph_server(url, token=token))

    # ------------------------------------------------------------------ graph names
    @staticmethod
    def check_name(name: str) -> str:
        """``name`` if it can name a model or run (it becomes part of graph IRIs).

        :raises ValueError: naming the rule.
        """
        if not _NAME.fullmatch(name or ""):
            raise ValueError(
                f"model name {name!r}: use letters, digits, '_', '-', '.', '+' (starting with a letter or digit), "
                "128 characters at most"
            )
        return name

    def model_graph(self, name: str) -> ox.NamedNode:
        return graph_iri("model", self.check_name(name))

    def inferred_graph(self, name: str) -> ox.NamedNode:
        return graph_iri("inferred", self.check_name(name))

    def assembly_graph(self, name: str) -> ox.NamedNode:
        return graph_iri("assembly", self.check_name(name))

    def run_graph(self, run_id: str) -> ox.NamedNode:
        return graph_iri("run", self.check_name(run_id))

    def graph_variables(self, name: str) -> dict[str, ox.NamedNode]:
        """Model ``name``'s graphs by the variables the queries in ``queries/`` bind them to
        (``?model_graph``, ``?inferred_graph``, ``?ontology_graph``)."""
        return {"model_graph": self.model_graph(name), "inferred_graph": self.inferred_graph(name),
                "ontology_graph": ONTOLOGY_GRAPH}

    def matching_dataset(self, name: str) -> list[ox.NamedNode]:
        """Default graph for signature queries: the model, what alignment inferred, the ontologies."""
        return list(self.graph_variables(name).values())

    def models(self) -> list[str]:
        """The names of the models in the store (a graph a SPARQL update made under the models' prefix
        with a name no model can have is not one)."""
        prefix = graph_iri("model", "x").value[:-1]
        return sorted(name for g in self.backend.graphs() if g.value.startswith(prefix)
                      and _NAME.fullmatch(name := g.value[len(prefix):]))

    def has_model(self, name: str) -> bool:
        return self.model_graph(name) in self.backend.graphs()

    def graph_triples(self, graph: ox.NamedNode) -> list[ox.Triple]:
        """Every triple of ``graph`` (empty when it does not exist)."""
        return self.backend.query(_GRAPH_TRIPLES, substitutions={"graph": graph})

    # ------------------------------------------------------------------ loading
    def ensure_ontologies(self) -> bool:
        """Make the ontology graph hold ``ontologies/*.ttl`` and the alignment-rules graph the rules of
        ``queries/alignment`` (:func:`~service.graph.alignment.alignment_rule_triples`); checked once per
        :class:`GraphStore`. Every model's inferred graph is what those rules derive from it with
        those ontologies: when either differs from what the store holds (a new graphtwin version
        opening an old store), both graphs are replaced and every model's inferences derived again.

        :returns: whether the graphs were (re)written.
        """
        if self._ontology_triples is not None:
            return False
        triples: list[ox.Triple] = []
        for path in sorted(ontologies_dir().glob("*.ttl")):
            triples += parse_rdf(path.read_bytes(), ox.RdfFormat.TURTLE, str(path))
        triples = skolemize(triples, f"{GTR}ontology/genid/")
        self._ontology_triples = triples
        held = {ONTOLOGY_GRAPH: triples, ALIGNMENT_RULES_GRAPH: alignment_rule_triples()}
        if all(set(content) == set(self.graph_triples(graph)) for graph, content in held.items()):
            return False
        self.write_graphs(held)
        for name in self.models():
            self.realign(name)
        return True

    def load_model(self, name: str, source: Path | bytes | str, format: str | None = None, *,
                   source_name: str | None = None) -> ModelLoad:
        """Load (or replace) building model ``name`` with what alignment infers from it, in one
        transaction that also removes the model's assembly graph (it described the model replaced);
        blank nodes are skolemised (module docstring). A model the store holds already, triple for
        triple, is left as it is, inferences and assembly included (every CLI command loads its model
        file: on disk, finding a 300k-triple model unchanged takes 3.2 s; one with a triple added, 6.8 s).

        :param source: a file path, or the RDF as bytes.
        :param format: ``ttl``, ``nt``, ``rdf``, ``jsonld`` or a media type; from the suffix when None
            (Turtle for bytes).
        :returns: the number of triples the source holds, whether the store changed, and whether
            a model of that name was there.
        :raises ModelLoadError: the source does not parse or is empty; the store is unchanged.
        :raises FileNotFoundError: no file at ``source``.
        """
        self.check_name(name)
        if isinstance(source, (str, Path)):
            path = Path(source)
            if not path.is_file():
                raise FileNotFoundError(f"{path}: no such file")
            data = path.read_bytes()
            source_name = source_name or str(path)
            fmt = rdf_format(format or path.suffix)
        else:
            data = source
            source_name = source_name or "<upload>"
            fmt = rdf_format(format or "ttl")
        triples = parse_rdf(data, fmt, source_name)
        if not triples:
            raise ModelLoadError(source_name, "the model is empty: no triples")
        triples = skolemize(triples, f"{GTR}model/{name}/genid/")
        self.ensure_ontologies()
        with self._model_lock:
            if self._holds_model(name, triples):
                return ModelLoad(len(triples), changed=False, replaced=True)
            replaced = self.has_model(name)
            self.write_graphs({
                self.model_graph(name): triples,
                self.inferred_graph(name): inferred_ntriples(triples, self._ontology_triples),
                self.assembly_graph(name): [],
            })
        return ModelLoad(len(triples), changed=True, replaced=replaced)

    def _holds_model(self, name: str, triples: list[ox.Triple]) -> bool:
        """Whether model ``name``'s graph holds exactly ``triples`` (compared as N-Triples lines, which
        pyoxigraph writes one way) and its inferred graph is there. That graph then holds what the
        current rules derive from them: :meth:`ensure_ontologies` derives them again when the rules or
        ontologies change, :meth:`update_models` when an update changes the model; an inferred graph
        an update emptied is derived again here (a model with nothing to infer is then rewritten on
        every load: a small one)."""
        graph = self.model_graph(name)
        if graph not in self.backend.graphs() or not self.query(f"ASK {{ GRAPH {self.inferred_graph(name)} {{ ?s ?p ?o }} }}"):
            return False
        held = self.backend.dump(graph, ox.RdfFormat.N_TRIPLES)
        return set(held.splitlines()) == set(b"".join(ntriples_chunks(triples)).splitlines())

    def realign(self, name: str) -> int:
        """Derive model ``name``'s inferences again (after the ontologies or the rules changed);
        returns the number of inferred triples."""
        self.ensure_ontologies()
        with self._model_lock:
            inferred = self._inferences(name)
            self.write_graph(self.inferred_graph(name), inferred)
        return len(inferred)

    def _inferences(self, name: str) -> list[ox.Triple]:
        """What the alignment rules derive from model ``name``'s graph as the store holds it."""
        return inferred_triples(self.graph_triples(self.model_graph(name)), self._ontology_triples)

    def drop_model(self, name: str) -> None:
        """Remove model ``name``, its inferences and its assembly (one transaction); runs stay."""
        graphs = (self.model_graph(name), self.inferred_graph(name), self.assembly_graph(name))
        with self._model_lock:
            self.backend.update(" ;\n".join(f"DROP SILENT GRAPH {g}" for g in graphs))

    def update_models(self, sparql: str, written: Collection[str] | None) -> list[str]:
        """Run a SPARQL update, then bring what is derived from each model it changed in step with it:
        a model whose graph it can have written (``written``: graph IRIs, None for any;
        :func:`service.graph.sparql_writes.written_graphs`) gets its inferences derived again and loses its
        assembly (which described the model before), as a load does; a model whose graph it removed
        leaves neither behind. The update and those writes hold the model lock: a load of the same
        model waits. Returns the names of the models brought in step.

        :raises SyntaxError, ValueError, RuntimeError, OSError: the backend's refusal of the update
            (nothing was changed).
        """
        self.ensure_ontologies()
        with self._model_lock:
            before = self.models()
            self.backend.update(sparql)
            after = self.models()
            changed = [name for name in after if written is None or self.model_graph(name).value in written]
            dropped = sorted(set(before) - set(after))
            for name in changed:
                self.write_graphs({self.inferred_graph(name): self._inferences(name), self.assembly_graph(name): []})
            for name in dropped:
                self.write_graphs({self.inferred_graph(name): [], self.assembly_graph(name): []})
        return changed + dropped

    # ------------------------------------------------------------------ queries
    def query(self, sparql: str, *, substitutions: Mapping[str, object] | None = None,
              model: str | None = None, default_graph: Sequence[ox.NamedNode] | None = None):
        """Run a SPARQL query (results as :class:`SparqlBackend` ``query``).

        :param substitutions: variable name → value, converted as :meth:`run_named_query` says.
        :param model: match over this model: the default graph is :meth:`matching_dataset`.
        :param default_graph: the named graphs whose union is the default graph (not with ``model``).
        :raises ValueError: a SPARQL syntax error, or both ``model`` and ``default_graph``.
        """
        if model is not None:
            if default_graph is not None:
                raise ValueError("give model= or default_graph=, not both")
            default_graph = self.matching_dataset(model)
        bound = {k: _term(k, v) for k, v in (substitutions or {}).items()}
        try:
            return self.backend.query(sparql, substitutions=bound or None, default_graph=default_graph)
        except SyntaxError as exc:
            raise ValueError(f"SPARQL syntax error: {exc}") from None

    def named_query_text(self, name: str) -> str:
        """The text of ``queries/<name>.rq`` (read once).

        :raises KeyError: no such query, listing the known ones.
        """
        path = queries_dir() / f"{name}.rq"
        if not path.is_file():
            known = ", ".join(sorted(p.stem for p in queries_dir().glob("*.rq")))
            raise KeyError(f"no query {name!r} in {queries_dir()} (known: {known})")
        return _named_query_text(path)

    def run_named_query(self, query_name: str, /, *, dataset: str | None = None, **params):
        """Run ``queries/<query_name>.rq``; each keyword binds the variable of that name (str starting
        with http(s):// or urn: → IRI, other str, bool, int, float → literal, pyoxigraph terms as they
        are). ``dataset=NAME`` matches over model NAME's :meth:`matching_dataset` (queries about a
        building graph); without it the query sees the named graphs through ``GRAPH`` (queries about
        results, the signature library). ``model`` is an ordinary parameter (``?model``, a model
        name, in the result queries)."""
        return self.query(self.named_query_text(query_name), substitutions=params, model=dataset)

    def write_graph(self, graph: ox.NamedNode, triples: Iterable[ox.Triple]) -> None:
        """Replace ``graph`` with ``triples`` in one transaction."""
        self.backend.replace_graph(graph, triples)

    def write_graphs(self, graphs: Mapping[ox.NamedNode, GraphTriples]) -> None:
        """Replace several graphs (:data:`GraphTriples`) in one transaction (the backend's
        ``replace_graphs``; a remote store receives one update request, whose body an Oxigraph
        server bounds: module :mod:`service.graph.endpoint`)."""
        self.backend.replace_graphs(graphs)
