"""The graph store: every building model, ontology subset, signature and result in its own named graph.

:class:`GraphStore` lays graphtwin's graphs out (IRIs from :func:`service.graph.namespaces.graph_iri`:
``gtr:graph/ontology/core``, ``alignment/rules``, ``signatures/library``, ``model/<name>``,
``inferred/<name>``, ``assembly/<name>``, ``run/<id>``) on a :class:`~service.graph.backend.SparqlBackend`,
so a user can drop or replace one graph without touching the others. A model and what alignment
infers from it are written in one transaction; a load parses everything first (a failed load leaves
the store as it was) and skolemises the model's blank nodes. The layout table and the write,
skolemisation and binding contracts: ``docs/graph-store.md``.
"""

from __future__ import annotations

import re
import threading
from collections.abc import Collection, Iterable, Mapping, Sequence
from functools import lru_cache
from pathlib import Path
from typing import NamedTuple

import pyoxigraph as ox

from service.errors import InputError, MaintainedGraphError, ModelLoadError, NotFoundError
from service.graph.alignment import alignment_rule_triples, inferred_ntriples, inferred_triples
from service.graph.backend import EmbeddedBackend, SparqlBackend, Term
from service.graph.blank_nodes import skolemize
from service.graph.endpoint import SparqlEndpointBackend
from service.graph.namespaces import GT, GTR, graph_iri
from service.graph.ntriples import GraphTriples, ntriples_chunks
from service.graph.rdf_io import parse_rdf, rdf_format, sparql_syntax_message
from service.resources import ontologies_dir, queries_dir

__all__ = ["ModelLoad", "GraphStore", "ONTOLOGY_GRAPH", "ALIGNMENT_RULES_GRAPH", "SIGNATURE_GRAPH", "MAINTAINED_GRAPHS"]

ONTOLOGY_GRAPH = graph_iri("ontology", "core")
ALIGNMENT_RULES_GRAPH = graph_iri("alignment", "rules")
SIGNATURE_GRAPH = graph_iri("signatures", "library")
#: The graphs graphtwin writes from its own files; an update may not write them (:meth:`GraphStore.update_models`).
MAINTAINED_GRAPHS = frozenset(g.value for g in (ONTOLOGY_GRAPH, ALIGNMENT_RULES_GRAPH, SIGNATURE_GRAPH))
_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.\-+]{0,127}")  # 128 at most: a name is a file name too (uploads)


class ModelLoad(NamedTuple):
    """What :meth:`GraphStore.load_model` did: the triples the source holds, whether the store
    changed (False: it held that model already, triple for triple, and kept it as it was), and
    whether a model of that name was there before; ``previous``: the graphs a changing load replaced
    (graph → N-Triples), kept when asked for (:meth:`GraphStore.undo_load`)."""

    triples: int
    changed: bool
    replaced: bool
    previous: dict[ox.NamedNode, bytes] | None = None



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
            raise InputError(f"query parameter {name}: {value!r} is not a valid IRI ({exc})") from None
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
    def remote(cls, url: str, token: str | None = None, query_timeout_s: float | None = None) -> GraphStore:
        """An external SPARQL 1.1 endpoint (Oxigraph server layout: ``/query``, ``/update``, ``/store``);
        ``query_timeout_s`` its queries' HTTP timeout (30 s when None)."""
        return cls(SparqlEndpointBackend.for_oxigraph_server(url, token=token, query_timeout_s=query_timeout_s))

    # ------------------------------------------------------------------ graph names
    @staticmethod
    def check_name(name: str) -> str:
        """``name`` if it can name a model or run (it becomes part of graph IRIs).

        :raises InputError: naming the rule.
        """
        if not _NAME.fullmatch(name or ""):
            spaced = " " in name and _NAME.fullmatch(name.replace(" ", "+"))
            raise InputError(
                f"model name {name!r}: use letters, digits, '_', '-', '.', '+' (starting with a letter or digit), "
                "128 characters at most" + (f"; in a URL's query a '+' reads as a space: write "
                                            f"{name.replace(' ', '%2B')!r}" if spaced else "")
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

    def result_bindings(self, name: str, sparql: str) -> dict[str, object]:
        """What a query about model ``name``'s results binds: ``?model`` to the name, and each of
        :meth:`graph_variables` the text uses."""
        return {"model": name} | {var: iri for var, iri in self.graph_variables(name).items() if f"?{var}" in sparql}

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

    def has_results(self, name: str) -> bool:
        """Whether a run (calibration or diagnosis) of model ``name`` is stored: a dropped model's
        results stay queryable."""
        return bool(self.query(f"ASK {{ GRAPH ?g {{ ?run <{GT}forModel> ?model }} }}", substitutions={"model": name}))

    def graph_triples(self, graph: ox.NamedNode) -> list[ox.Triple]:
        """Every triple of ``graph`` (empty when it does not exist)."""
        return self.backend.query(_GRAPH_TRIPLES, substitutions={"graph": graph})

    # ------------------------------------------------------------------ loading
    def ensure_ontologies(self, *, recheck: bool = False) -> bool:
        """Make the ontology graph hold ``ontologies/*.ttl`` and the alignment-rules graph the rules of
        ``queries/alignment`` (:func:`~service.graph.alignment.alignment_rule_triples`); checked once per
        :class:`GraphStore` (``recheck``: again, after an update that may have changed them; the files
        are read once). Every model's inferred graph is what those rules derive from it with
        those ontologies: when either differs from what the store holds (a new graphtwin version
        opening an old store), both graphs are replaced and every model's inferences derived again.

        :returns: whether the graphs were (re)written.
        """
        if self._ontology_triples is not None and not recheck:
            return False
        if self._ontology_triples is None:
            triples: list[ox.Triple] = []
            for path in sorted(ontologies_dir().glob("*.ttl")):
                triples += parse_rdf(path.read_bytes(), ox.RdfFormat.TURTLE, str(path))
            self._ontology_triples = skolemize(triples, f"{GTR}ontology/genid/")
        held = {ONTOLOGY_GRAPH: self._ontology_triples, ALIGNMENT_RULES_GRAPH: alignment_rule_triples()}
        if all(set(content) == set(self.graph_triples(graph)) for graph, content in held.items()):
            return False
        self.write_graphs(held)
        for name in self.models():
            self.realign(name)
        return True

    def load_model(self, name: str, source: Path | bytes | str, format: str | None = None, *,
                   source_name: str | None = None, keep_previous: bool = False) -> ModelLoad:
        """Load (or replace) building model ``name`` with what alignment infers from it, in one
        transaction that also removes the model's assembly graph (it described the model replaced);
        blank nodes are skolemised (``docs/graph-store.md``). A model the store holds already, triple
        for triple, is left as it is, inferences and assembly included (every CLI command loads its
        model file).

        :param source: a file path, or the RDF as bytes.
        :param format: ``ttl``, ``nt``, ``rdf``, ``jsonld`` or a media type; from the suffix when None
            (Turtle for bytes).
        :param keep_previous: keep the graphs a changing load replaces (``ModelLoad.previous``), so
            that :meth:`undo_load` can put them back.
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
            graphs = (self.model_graph(name), self.inferred_graph(name), self.assembly_graph(name))
            previous = ({graph: self.backend.dump(graph, ox.RdfFormat.N_TRIPLES) for graph in graphs}
                        if keep_previous and replaced else None)
            self.write_graphs(dict(zip(graphs, (triples, inferred_ntriples(triples, self._ontology_triples), []))))
        return ModelLoad(len(triples), changed=True, replaced=replaced, previous=previous)

    def undo_load(self, name: str, load: ModelLoad) -> None:
        """Put model ``name`` back as it was before ``load`` (a :meth:`load_model` with
        ``keep_previous``): its graphs as they were, or no model where there was none; nothing where
        the load changed nothing.

        :raises ValueError: ``load`` replaced a model without keeping its graphs.
        """
        if not load.changed:
            return
        if not load.replaced:
            self.drop_model(name)
            return
        if load.previous is None:
            raise ValueError(f"model {name}: the load replaced it without keeping its graphs (keep_previous)")
        with self._model_lock:
            self.write_graphs(load.previous)

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
        leaves neither behind. An update that names a graph graphtwin maintains (:data:`MAINTAINED_GRAPHS`)
        is refused; one that can write any named graph (``CLEAR ALL``, ``GRAPH ?g``) runs, and the
        ontologies and alignment rules are written again where it changed them. The update and those
        writes hold the model lock: a load of the same model waits. Returns the names of the models
        brought in step.

        :raises MaintainedGraphError: the update names a maintained graph (nothing was changed).
        :raises SyntaxError, ValueError, RuntimeError, OSError: the backend's refusal of the update
            (nothing was changed).
        """
        if written is not None and (maintained := sorted(MAINTAINED_GRAPHS.intersection(written))):
            raise MaintainedGraphError(
                f"the update writes {', '.join(f'<{g}>' for g in maintained)}, which graphtwin maintains from its own "
                "files (the ontologies, the alignment rules, the signature library: every model's matching reads "
                "them); write a model's graph, or a graph of your own")
        self.ensure_ontologies()
        with self._model_lock:
            before = self.models()
            self.backend.update(sparql)
            if written is None:  # it may have changed the maintained graphs
                self.ensure_ontologies(recheck=True)
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
            raise InputError(sparql_syntax_message(sparql, exc)) from None

    def named_query_text(self, name: str) -> str:
        """The text of ``queries/<name>.rq`` (read once).

        :raises NotFoundError: no such query, listing the known ones.
        """
        path = queries_dir() / f"{name}.rq"
        if not path.is_file():
            known = ", ".join(sorted(p.stem for p in queries_dir().glob("*.rq")))
            raise NotFoundError(f"no query {name!r} in {queries_dir()} (known: {known})")
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
        """Replace several graphs (:data:`~service.graph.ntriples.GraphTriples`) in one transaction (the
        backend's ``replace_graphs``; a remote store receives one update request, whose body an
        Oxigraph server bounds: ``docs/graph-store.md``, External endpoint)."""
        self.backend.replace_graphs(graphs)
