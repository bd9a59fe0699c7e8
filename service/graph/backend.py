"""The store's backend contract (:class:`SparqlBackend`) and the embedded backend (pyoxigraph).

A backend holds named graphs and answers SPARQL: every write is one transaction (a reader sees a
graph before or after, never half of it); values reach queries through ``substitutions``, serialised
by pyoxigraph into a ``VALUES`` block (:func:`bind_values`), never spliced from user text; results
are read into Python lists before they are returned (:func:`drain`). :class:`EmbeddedBackend` is
pyoxigraph on disk or in memory; :class:`service.graph.endpoint.SparqlEndpointBackend` an external
SPARQL 1.1 endpoint. Write strategies and their reasons: ``docs/graph-store.md``.
"""

from __future__ import annotations

import os
import re
import threading
import uuid
from collections.abc import Iterable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Protocol, runtime_checkable

import pyoxigraph as ox

from service.errors import InputError, StoreInUseError
from service.graph.namespaces import GTR
from service.graph.ntriples import GraphTriples, ntriples_chunks
from service.graph.rdf_io import parse_rdf

__all__ = [
    "Term", "SparqlBackend", "drain", "bind_values", "query_bound", "insert_data_update", "STAGING", "EmbeddedBackend",
]

Term = ox.NamedNode | ox.BlankNode | ox.Literal


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
    :data:`~service.graph.ntriples.GraphTriples`: triples, or N-Triples text whole or in chunks; none:
    the graph is removed; blank nodes shared between them stay shared); ``load_graph`` parses
    completely first and raises :class:`~service.errors.ModelLoadError`, leaving the store untouched.
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

    A lazy result dropped on another thread raises, so it is read in a plain loop (a comprehension's
    frame would hold it too) and the local deleted before this frame ends (``docs/graph-store.md``,
    Lazy results).
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

    :raises InputError: when the query has no WHERE/ASK group.
    """
    if not substitutions:
        return sparql
    blanked = _COMMENT.sub(lambda m: m.group(1) + " " * (len(m.group(0)) - len(m.group(1))), sparql)
    match = _GROUP_START.search(blanked)
    if match is None:
        raise InputError("cannot bind variables: the query has no WHERE group")
    names = " ".join(f"?{name}" for name in substitutions)
    values = " ".join(str(term) for term in substitutions.values())
    block = f" VALUES ({names}) {{ ({values}) }} "
    return sparql[: match.end()] + block + sparql[match.end():]


def query_bound(store: ox.Store, sparql: str, substitutions: Mapping[str, Term] | None, **kwargs):
    """``store.query`` with ``substitutions`` bound (the lazy result; read it with :func:`drain`).

    Variables the query projects are bound by Oxigraph's own substitution (SEP-0007: the constant
    replaces the variable in every pattern, so the indexes are used); others by :func:`bind_values`
    (``docs/graph-store.md``, Value binding).
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


#: Write-ahead log growth after which the embedded store on disk flushes its memtable, bytes: at most
#: ~2 s of log replay when the store is opened again (``docs/graph-store.md``, Restart).
FLUSH_AFTER_WAL_BYTES = 32 * 2**20


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
        #: writes made since the store was opened (each under ``_write_lock``): a checkpoint of an
        #: older generation misses one
        self.generation = 0
        #: write-ahead log bytes written after which a write is followed by a flush (RocksDB replays the
        #: unflushed log when the store is opened again: ~50 ms per MB, ``docs/graph-store.md``, Restart)
        self.flush_after_wal_bytes = FLUSH_AFTER_WAL_BYTES
        if self.path is not None:
            self.path.mkdir(parents=True, exist_ok=True)
            self.store = _open_store(self.path)
        else:
            self.store = ox.Store()
        for graph in [g for g in self.store.named_graphs() if g.value.startswith(STAGING)]:
            self.store.remove_graph(graph)
        self._wal_at_flush = self._wal_bytes() if self.path is not None else 0

    def query(self, sparql, *, substitutions=None, default_graph=None):
        kwargs = {}
        if default_graph is not None:
            kwargs["default_graph"] = list(default_graph)
        return _rows(query_bound(self.store, sparql, substitutions, **kwargs))

    @contextmanager
    def _writing(self) -> Iterator[None]:
        """The write lock held around one write, the generation moved after it (even a failed write
        may have changed the store: pyoxigraph's bulk loads are not transactions); on disk, the
        memtable flushed when the write-ahead log grew by :attr:`flush_after_wal_bytes`."""
        with self._write_lock:
            try:
                yield
            finally:
                self.generation += 1
                if self.path is not None:
                    self._flush_when_the_log_grew()

    def _flush_when_the_log_grew(self) -> None:
        wal = self._wal_bytes()
        if wal - self._wal_at_flush > self.flush_after_wal_bytes:
            self.store.flush()
            self._wal_at_flush = self._wal_bytes()
        else:
            self._wal_at_flush = min(self._wal_at_flush, wal)  # RocksDB removed logs it had flushed

    def _wal_bytes(self) -> int:
        """The size of RocksDB's write-ahead logs (``*.log``) in the store's folder, bytes."""
        return sum(entry.stat().st_size for entry in os.scandir(self.path) if entry.name.endswith(".log"))

    def checkpoint(self, folder: Path) -> int:
        """A RocksDB checkpoint of the on-disk store in ``folder`` (which must not exist): hard links to
        its files, cheap (``docs/graph-store.md``, Read snapshots); the generation it holds.

        :raises OSError: the store is in memory, or RocksDB cannot write the checkpoint."""
        if self.path is None:
            raise OSError("an in-memory store has no checkpoint")
        with self._write_lock:
            self.store.backup(str(folder))
            return self.generation

    def update(self, sparql):
        with self._writing():
            self.store.update(sparql)

    def replace_graph(self, graph, triples):
        self.replace_graphs({graph: triples})

    def replace_graphs(self, graphs):
        """One N-Quads load (a transaction) when none of ``graphs`` exists yet. Else one update of
        the difference (:meth:`_difference_update`) when it is small: a model edited and loaded
        again. Else, in memory, the load into staging graphs (:data:`STAGING`), then one update that
        moves them into place; on disk one ``DROP`` + ``INSERT DATA`` update (``docs/graph-store.md``,
        Writes)."""
        texts = {g: [chunk for chunk in ntriples_chunks(t) if chunk] for g, t in graphs.items()}
        with self._writing():
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
        are compared as pyoxigraph writes them (reading the graphs costs far less than rewriting them)."""
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
        with self._writing():
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

