"""Which named graphs a SPARQL update can change, so that the service derives again the inferences of
the building models an update edits (``POST /sparql/update``; why: ``docs/graph-store.md``).

Read from rdflib's parse of the update (parsing only; Oxigraph runs it): the graphs of ``INSERT DATA``,
``DELETE DATA`` and ``DELETE WHERE`` quads, of the ``GRAPH`` blocks of a ``DELETE``/``INSERT``
template and its ``WITH`` graph, the graph ``CLEAR``/``DROP``/``LOAD … INTO`` names, the target of
``ADD``/``COPY``/``MOVE`` and the source ``MOVE`` empties. A ``GRAPH ?g`` template, ``CLEAR ALL`` or
``DROP NAMED`` can change any named graph. The default graph is no named graph and is not listed.
"""

from __future__ import annotations

from pyparsing import ParseBaseException
from rdflib import URIRef
from rdflib.plugins.sparql.algebra import translateUpdate
from rdflib.plugins.sparql.parser import parseUpdate
from rdflib.plugins.sparql.parserutils import CompValue
from rdflib.plugins.sparql.sparql import Update

from service.graph.sparql_reads import RDFLIB_PARSER_LOCK

__all__ = ["written_graphs"]


def written_graphs(text: str) -> frozenset[str] | None:
    """The IRIs of the named graphs the update ``text`` can add triples to or remove triples from;
    None when it can change any named graph (module docstring), or rdflib cannot parse it (Oxigraph's
    grammar is the one that counts: it runs the update, or refuses it with its own message)."""
    try:
        with RDFLIB_PARSER_LOCK:
            update = translateUpdate(parseUpdate(text))
    except ParseBaseException:
        return None
    # an update of no operation (a prologue or a comment alone) translates to [], not an Update,
    # which rdflib's prepareUpdate then fails on
    operations = update.algebra if isinstance(update, Update) else []
    graphs: set[str] = set()
    for operation in operations:
        named = list(_named_graphs(operation))
        if any(graph is None for graph in named):
            return None
        graphs.update(named)
    return frozenset(graphs)


def _named_graphs(operation: CompValue):
    """The graphs one operation changes: an IRI, or None for "any named graph"."""
    name = operation.name
    if name in ("InsertData", "DeleteData", "DeleteWhere"):
        yield from map(_graph, operation["quads"])
    elif name == "Modify":
        for clause in (operation[key] for key in ("delete", "insert") if key in operation):
            yield from map(_graph, clause["quads"])
            if clause["triples"] and "withClause" in operation:
                yield _graph(operation["withClause"])
    elif name in ("Clear", "Drop", "Load"):
        target = operation["graphiri"] if "graphiri" in operation else "DEFAULT"  # LOAD without INTO
        if target != "DEFAULT":
            yield _graph(target)  # None for ALL and NAMED
    elif name in ("Add", "Copy", "Move"):
        source, target = operation["graph"]
        if name == "Move" and isinstance(source, URIRef):
            yield str(source)
        if isinstance(target, URIRef):
            yield str(target)


def _graph(term) -> str | None:
    return str(term) if isinstance(term, URIRef) else None
