"""The graph store: every building model, ontology subset, signature and result in its own named graph.

Layout (IRIs from :func:`service.namespaces.graph_iri`), so a user can drop or replace one graph
without touching the others:

==============================  ============================================================
``gtr:graph/ontology/core``     the ontology subsets in ``ontologies/`` (class hierarchy)
``gtr:graph/signatures/library`` the signature library as triples (``signature_triples``)
``gtr:graph/model/<name>``      a user's building model, as loaded
``gtr:graph/inferred/<name>``   what the alignment rules derive from it (``queries/alignment``)
``gtr:graph/assembly/<name>``   the assembled simulation model
``gtr:graph/run/<id>``          one calibration or diagnosis run's results
==============================  ============================================================

Two backends implement :class:`SparqlBackend`: :class:`EmbeddedBackend` (pyoxigraph on disk, or in
memory for tests) and :class:`service.sparql_endpoint_backend.SparqlEndpointBackend` (any SPARQL 1.1
endpoint with the graph store protocol). Contracts, as pyoxigraph's:

* every write is one transaction: a reader sees a graph before or after, never half of it;
* a load parses everything first and raises :class:`ModelLoadError` (file, line, column) before
  anything is written: a failed load leaves the store as it was;
* values reach queries through ``substitutions``: serialised by pyoxigraph (validated, escaped) into a
  ``VALUES`` block at the start of the outer WHERE group (:func:`bind_values`), the same way on
  every backend, never by splicing user text;
* query results are consumed into Python lists before they are returned (a lazy pyoxigraph
  ``QuerySolutions`` read on another thread raises in a FastAPI worker).
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Mapping, Sequence
from functools import lru_cache
from pathlib import Path
from typing import Protocol, runtime_checkable

import pyoxigraph as ox

from .namespaces import PREFIXES, graph_iri
from .resources import ontologies_dir, queries_dir

__all__ = [
    "ModelLoadError", "SparqlBackend", "bind_values", "insert_data_update", "EmbeddedBackend", "GraphStore", "rdf_format", "parse_rdf",
    "ONTOLOGY_GRAPH", "SIGNATURE_GRAPH",
]

Term = ox.NamedNode | ox.BlankNode | ox.Literal
ONTOLOGY_GRAPH = graph_iri("ontology", "core")
SIGNATURE_GRAPH = graph_iri("signatures", "library")
_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.\-+]*$")
_POSITION = re.compile(r"line (\d+) between columns (\d+)")


class ModelLoadError(ValueError):
    """RDF that cannot be parsed: ``source``, ``line`` and ``column`` say where (1-based)."""

    def __init__(self, source: str, message: str, line: int | None = None, column: int | None = None):
        self.source, self.line, self.column = source, line, column
        where = f"{source}, line {line}, column {column}" if line is not None else source
        super().__init__(f"{where}: {message}")


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
    """Parse completely (nothing is written anywhere) or raise :class:`ModelLoadError`."""
    try:
        quads = list(ox.parse(data, format=fmt, base_iri=base_iri))
    except SyntaxError as exc:
        message = str(exc)
        line = column = None
        match = _POSITION.search(message)
        if match:
            line, column = int(match.group(1)), int(match.group(2))
        elif getattr(exc, "lineno", None):
            line, column = exc.lineno, exc.offset
        message = re.sub(r"^Parser error at line \d+ between columns \d+( and \d+)?: ", "", message)
        raise ModelLoadError(source_name, message, line, column) from None
    except (ValueError, UnicodeDecodeError) as exc:
        raise ModelLoadError(source_name, str(exc)) from None
    return [ox.Triple(q.subject, q.predicate, q.object) for q in quads]


@runtime_checkable
class SparqlBackend(Protocol):
    """What graphtwin needs from a quad store. Implemented by :class:`EmbeddedBackend` and
    :class:`service.sparql_endpoint_backend.SparqlEndpointBackend`."""

    def query(self, sparql: str, *, substitutions: Mapping[str, Term] | None = None,
              default_graph: Sequence[ox.NamedNode] | None = None): ...

    def update(self, sparql: str) -> None: ...

    def replace_graph(self, graph: ox.NamedNode, triples: Iterable[ox.Triple]) -> None: ...

    def load_graph(self, graph: ox.NamedNode, data: bytes, format: ox.RdfFormat, *,
                   base_iri: str | None = None, source_name: str = "<data>") -> int: ...

    def drop_graph(self, graph: ox.NamedNode) -> None: ...

    def graphs(self) -> list[ox.NamedNode]: ...

    def dump(self, graph: ox.NamedNode, format: ox.RdfFormat) -> bytes: ...

    def triple_count(self, graph: ox.NamedNode) -> int: ...


def _rows(result) -> list[dict[str, Term]] | bool | list[ox.Triple]:
    if isinstance(result, ox.QueryBoolean):
        return bool(result)
    if isinstance(result, ox.QuerySolutions):
        names = [v.value for v in result.variables]
        rows = []
        for solution in result:
            row = {}
            for name in names:
                value = solution[name]
                if value is not None:
                    row[name] = value
            rows.append(row)
        return rows
    return list(result)


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


def insert_data_update(graph: ox.NamedNode, triples: Iterable[ox.Triple]) -> str:
    """``DROP SILENT GRAPH <g>; INSERT DATA { GRAPH <g> { … } }``: one update request, one transaction."""
    body = "\n".join(f"{t.subject} {t.predicate} {t.object} ." for t in triples)
    return f"DROP SILENT GRAPH {graph} ;\nINSERT DATA {{ GRAPH {graph} {{\n{body}\n}} }}"


class EmbeddedBackend:
    """pyoxigraph :class:`~pyoxigraph.Store` on disk under ``path`` (created if missing), or in memory."""

    def __init__(self, path: Path | None = None):
        self.path = Path(path) if path is not None else None
        if self.path is not None:
            self.path.mkdir(parents=True, exist_ok=True)
            self.store = ox.Store(str(self.path))
        else:
            self.store = ox.Store()

    def query(self, sparql, *, substitutions=None, default_graph=None):
        kwargs = {}
        if default_graph is not None:
            kwargs["default_graph"] = list(default_graph)
        return _rows(self.store.query(bind_values(sparql, substitutions), **kwargs))

    def update(self, sparql):
        self.store.update(sparql)

    def replace_graph(self, graph, triples):
        triples = list(triples)
        if not triples:
            self.drop_graph(graph)
            return
        self.store.update(insert_data_update(graph, triples))

    def load_graph(self, graph, data, format, *, base_iri=None, source_name="<data>"):
        triples = parse_rdf(data, format, source_name, base_iri)
        self.replace_graph(graph, triples)
        return len(triples)

    def drop_graph(self, graph):
        if self.store.contains_named_graph(graph):
            self.store.remove_graph(graph)

    def graphs(self):
        return sorted(self.store.named_graphs(), key=lambda g: g.value)

    def dump(self, graph, format):
        return self.store.dump(format=format, from_graph=graph) or b""

    def triple_count(self, graph):
        return sum(1 for _ in self.store.quads_for_pattern(None, None, None, graph))


@lru_cache(maxsize=None)
def _named_query_text(path: Path) -> str:
    return path.read_text(encoding="utf-8")


def _term(value) -> Term:
    if isinstance(value, (ox.NamedNode, ox.BlankNode, ox.Literal)):
        return value
    if isinstance(value, str) and value.startswith(("http://", "https://", "urn:")):
        return ox.NamedNode(value)
    if isinstance(value, bool):
        return ox.Literal("true" if value else "false", datatype=ox.NamedNode("http://www.w3.org/2001/XMLSchema#boolean"))
    if isinstance(value, (int, float, str)):
        return ox.Literal(value)
    raise TypeError(f"cannot bind {value!r} in a query: give a str, number or pyoxigraph term")


class GraphStore:
    """graphtwin's graph layout on top of a :class:`SparqlBackend`."""

    def __init__(self, backend: SparqlBackend):
        self.backend = backend
        self._ontologies_loaded = False

    @classmethod
    def embedded(cls, path: Path | None = None) -> GraphStore:
        """On disk under ``path`` (the default deployment), in memory when None."""
        return cls(EmbeddedBackend(path))

    @classmethod
    def remote(cls, url: str, token: str | None = None) -> GraphStore:
        """An external SPARQL 1.1 endpoint (Oxigraph server layout: ``/query``, ``/update``, ``/store``)."""
        from .sparql_endpoint_backend import SparqlEndpointBackend

        return cls(SparqlEndpointBackend.for_oxigraph_server(url, token=token))

    # ------------------------------------------------------------------ graph names
    @staticmethod
    def check_name(name: str) -> str:
        if not _NAME.match(name or ""):
            raise ValueError(
                f"model name {name!r}: use letters, digits, '_', '-', '.', '+' (starting with a letter or digit)"
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

    def matching_dataset(self, name: str) -> list[ox.NamedNode]:
        """Default graph for signature queries: the model, what alignment inferred, the ontologies."""
        return [self.model_graph(name), self.inferred_graph(name), ONTOLOGY_GRAPH]

    def models(self) -> list[str]:
        prefix = graph_iri("model", "x").value[:-1]
        return sorted(g.value[len(prefix):] for g in self.backend.graphs() if g.value.startswith(prefix))

    def has_model(self, name: str) -> bool:
        return self.model_graph(name) in self.backend.graphs()

    # ------------------------------------------------------------------ loading
    def ensure_ontologies(self) -> None:
        """Load ``ontologies/*.ttl`` into the ontology graph once (idempotent)."""
        if self._ontologies_loaded:
            return
        triples: list[ox.Triple] = []
        for path in sorted(ontologies_dir().glob("*.ttl")):
            triples += parse_rdf(path.read_bytes(), ox.RdfFormat.TURTLE, str(path))
        current = self.backend.triple_count(ONTOLOGY_GRAPH)
        if current != len(set(triples)):
            self.backend.replace_graph(ONTOLOGY_GRAPH, triples)
        self._ontologies_loaded = True

    def ensure_signature_library(self, library=None) -> None:
        """Write the signature library as triples (``gtr:graph/signatures/library``)."""
        from .signature_triples import library_triples

        self.backend.replace_graph(SIGNATURE_GRAPH, library_triples(library))

    def load_model(self, name: str, source: Path | bytes | str, format: str | None = None, *,
                   source_name: str | None = None) -> int:
        """Load (or replace) building model ``name`` and refresh what alignment infers from it.

        :param source: a file path, or the RDF as bytes.
        :param format: ``ttl``, ``nt``, ``rdf``, ``jsonld`` or a media type; from the suffix when None.
        :returns: the number of triples loaded.
        :raises ModelLoadError: the source does not parse; the store is unchanged.
        """
        self.check_name(name)
        if isinstance(source, (str, Path)) and not isinstance(source, bytes):
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
        self.ensure_ontologies()
        self.backend.replace_graph(self.model_graph(name), triples)
        from .alignment import align_model

        align_model(self, name)
        return len(triples)

    def drop_model(self, name: str) -> None:
        for graph in (self.model_graph(name), self.inferred_graph(name), self.assembly_graph(name)):
            self.backend.drop_graph(graph)

    # ------------------------------------------------------------------ queries
    def query(self, sparql: str, *, substitutions: Mapping[str, object] | None = None,
              model: str | None = None, default_graph: Sequence[ox.NamedNode] | None = None):
        """Run a SPARQL query; ``model=`` sets the default graph to :meth:`matching_dataset`."""
        if model is not None:
            default_graph = self.matching_dataset(model)
        bound = {k: _term(v) for k, v in (substitutions or {}).items()}
        try:
            return self.backend.query(sparql, substitutions=bound or None, default_graph=default_graph)
        except SyntaxError as exc:
            raise ValueError(f"SPARQL syntax error: {exc}") from None

    def named_query_text(self, name: str) -> str:
        path = queries_dir() / f"{name}.rq"
        if not path.is_file():
            known = ", ".join(sorted(p.stem for p in queries_dir().glob("*.rq")))
            raise KeyError(f"no query {name!r} in {queries_dir()} (known: {known})")
        return _named_query_text(path)

    def run_named_query(self, query_name: str, /, *, dataset: str | None = None, **params):
        """Run ``queries/<query_name>.rq``; each keyword binds the variable of that name (str starting
        with http(s):// or urn: → IRI, other str and numbers → literal, pyoxigraph terms as they are).
        ``dataset=NAME`` matches over model NAME's :meth:`matching_dataset` (queries about a building
        graph); without it the query sees every named graph through ``GRAPH`` (queries about results)."""
        return self.query(self.named_query_text(query_name), substitutions=params, model=dataset)

    def write_graph(self, graph: ox.NamedNode, triples: Iterable[ox.Triple]) -> None:
        """Replace ``graph`` with ``triples`` in one transaction."""
        self.backend.replace_graph(graph, triples)

    def prefixes_header(self) -> str:
        return "".join(f"PREFIX {p}: <{iri}>\n" for p, iri in PREFIXES.items())
