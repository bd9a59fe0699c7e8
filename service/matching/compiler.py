"""Signature → SPARQL: one SELECT query per signature pattern, and the parts the matcher runs.

Classes become ``rdf:type/rdfs:subClassOf*`` restrictions (subclasses match), ``exact`` triples triple
patterns, connected ``optional`` triples one OPTIONAL block, a ``traverse`` the path ``?s P+ ?o``
(``?s (P+|^P+) ?o`` with ``or_reverse``). :attr:`CompiledQuery.text` is that whole query: a superset
of the matches, as the *nearest* condition is not expressible on property paths. The matcher runs
the pattern cut at its traverse triples (:class:`QueryPart`, :class:`Traversal`) and joins the parts
on nearest pairs. Terms are serialised through pyoxigraph: an invalid IRI raises ``ValueError``
naming it. Source: Bjørnskov, Jradi & Wetter, Sec. 3.2. Details and measured costs: ``docs/matching.md``.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import KW_ONLY, dataclass

import pyoxigraph as ox

from service.graph.namespaces import PREFIXES, RDF, RDFS, S4BLDG, compact_iri
from service.matching.signature import PatternTriple, Rule, Signature

__all__ = ["CompiledQuery", "QueryPart", "Reads", "Traversal", "compile_signature"]

#: What a query reads: each predicate IRI with the objects its triples can take (None: any).
Reads = tuple[tuple[str, tuple[str, ...] | None], ...]


@dataclass(frozen=True)
class Traversal:
    """A traverse triple the matcher joins on nearest pairs: ``subject`` reaches ``object`` along
    ``predicate`` without passing an instance of ``blocking_classes``; ``block``: the optional block
    (index in :attr:`CompiledQuery.blocks`) that is unbound when it fails, None when it is required.

    With ``or_reverse`` the pairs are searched from :attr:`start` (the object when ``from_object``):
    its nearest instances of ``far_classes`` as the triple is written, and where it has none, with
    the triple reversed."""

    subject: str
    predicate: str
    object: str
    blocking_classes: tuple[str, ...]
    _: KW_ONLY
    block: int | None = None
    or_reverse: bool = False
    far_classes: tuple[str, ...] = ()
    from_object: bool = False

    @property
    def start(self) -> str:
        """The end the pairs are searched from."""
        return self.object if self.from_object else self.subject

    @property
    def far(self) -> str:
        """The end searched for."""
        return self.subject if self.from_object else self.object


@dataclass(frozen=True)
class QueryPart:
    """A piece of the pattern joined by exact triples: ``text`` is its SELECT query binding
    ``nodes`` (None when the part is one node reached only by traverses: the instances of
    ``classes``); ``block`` is the optional block it belongs to (None: required). The query is not
    DISTINCT: the matcher drops repeated rows (cheaper in Python than in the store).

    ``reads``: each predicate its triples use, with the objects they can take (``rdf:type``: the
    classes listed; a fixed IRI; None: any), so the matcher can leave out of its dataset a graph that
    holds none of them (see :meth:`~service.matching.matcher.MatchSession.dataset_for`)."""

    nodes: tuple[str, ...]
    text: str | None
    _: KW_ONLY
    classes: tuple[str, ...] = ()
    block: int | None = None
    reads: Reads = ()


@dataclass(frozen=True)
class CompiledQuery:
    """``text``: the whole SELECT query; ``variables``: pattern node id → SPARQL variable name
    (without ``?``; empty for a fixed IRI); ``traversals``: the nearest joins; ``parts`` and
    ``blocks`` (the own nodes of each optional block the matcher left-joins: one holding a traverse,
    or hanging on several parts): what the matcher runs."""

    signature_id: str
    text: str
    variables: dict[str, str]
    traversals: tuple[Traversal, ...]
    _: KW_ONLY
    parts: tuple[QueryPart, ...] = ()
    blocks: tuple[tuple[str, ...], ...] = ()


def _iri(value: str, where: str) -> str:
    try:
        return str(ox.NamedNode(value))
    except ValueError as exc:
        raise ValueError(f"{where}: {value!r} is not a valid IRI ({exc})") from None


def _short(iri_text: str) -> str:
    """``<iri>`` (N-Triples) as the query writes it: :func:`compact_iri`."""
    return compact_iri(iri_text.strip("<>"))


class _Writer:
    """Renders pattern pieces as SPARQL group lines; with ``subclasses`` (class → itself and every
    subclass) a class restriction lists the subclasses instead of following ``rdfs:subClassOf*``."""

    def __init__(self, signature: Signature, subclasses: Mapping[str, Sequence[str]] | None = None):
        self.signature = signature
        self.subclasses = subclasses
        self.where = f"signature {signature.id} ({signature.source_file})"

    def term(self, node_id: str) -> str:
        node = self.signature.nodes[node_id]
        return _short(_iri(node.iri, self.where)) if node.iri else f"?{node_id}"

    def class_restriction(self, node_id: str) -> list[str]:
        node = self.signature.nodes[node_id]
        if not node.classes:
            return []
        classes = [_short(_iri(c, self.where)) for c in node.classes]
        if self.subclasses is not None:
            listed = dict.fromkeys(_short(_iri(sub, self.where)) for c in node.classes for sub in (c, *self.subclasses[c]))
            return [
                f"# {node_id}: an instance of {' or '.join(classes)} or of one of their subclasses listed",
                f"VALUES ?{node_id}__class {{ {' '.join(listed)} }}",
                f"?{node_id} rdf:type ?{node_id}__class .",
            ]
        return [
            f"# {node_id}: an instance of {' or '.join(classes)} (or a subclass)",
            f"VALUES ?{node_id}__class {{ {' '.join(classes)} }}",
            f"?{node_id} rdf:type/rdfs:subClassOf* ?{node_id}__class .",
        ]

    def triple(self, triple: PatternTriple) -> list[str]:
        predicate = _short(_iri(triple.predicate, self.where))
        subject, obj = self.term(triple.subject), self.term(triple.object)
        if triple.rule is Rule.TRAVERSE:
            path, fallback = f"{predicate}+", ""
            if triple.or_reverse:
                path = f"({predicate}+|^{predicate}+)"
                fallback = f", or where that gives none {triple.object} {predicate}+ {triple.subject}"
            return [
                f"# traverse: {triple.subject} {predicate}+ {triple.object}{fallback} (nearest: joined by the matcher)",
                f"{subject} {path} {obj} .",
            ]
        return [f"{subject} {predicate} {obj} ."]

    def group(self, triples: list[PatternTriple], nodes: list[str], restricted: set[str], *,
              blocks: list[list[PatternTriple]], block_nodes: list[set[str]]) -> list[str]:
        """``triples`` ordered outward from ``nodes[0]`` so each step joins on a bound variable,
        then the other ``nodes``' restrictions (only those in ``restricted``), then the OPTIONAL
        ``blocks`` (each restricting its ``block_nodes``). With ``subclasses`` (a matcher's part) a
        block first repeats the restrictions of the restricted nodes it hangs on: that changes no
        row, but Oxigraph then evaluates the block from those nodes' instances (``docs/matching.md``)."""
        lines: list[str] = []
        placed: set[str] = set()

        def place(node_id: str) -> None:
            if node_id not in placed:
                placed.add(node_id)
                if node_id in restricted:
                    lines.extend(self.class_restriction(node_id))

        if nodes:
            place(nodes[0])
        pending = list(triples)
        while pending:
            index = next((i for i, t in enumerate(pending) if t.subject in placed or t.object in placed), 0)
            triple = pending.pop(index)
            lines.extend(self.triple(triple))
            place(triple.subject)
            place(triple.object)
        for node_id in sorted(set(nodes) - placed):
            place(node_id)
        for block, own in zip(blocks, block_nodes):
            inner: list[str] = []
            done: set[str] = set()
            if self.subclasses is not None:  # the block starts from the nodes it hangs on: see group's docstring
                hooks = dict.fromkeys(n for t in block for n in (t.subject, t.object) if n not in own and n in restricted)
                for node_id in hooks:
                    inner += self.class_restriction(node_id)
            for triple in block:
                inner += self.triple(triple)
                for node_id in (triple.subject, triple.object):
                    if node_id in own and node_id not in done:
                        inner += self.class_restriction(node_id)
                        done.add(node_id)
            lines.append("OPTIONAL {")
            lines += [f"  {line}" for line in inner]
            lines.append("}")
        return lines

    def reads(self, triples: list[PatternTriple], nodes: Iterable[str]) -> Reads:
        """What a group over ``triples`` restricting the classes of ``nodes`` reads (see
        :attr:`QueryPart.reads`): each exact triple's predicate with its fixed object or any object,
        ``rdf:type`` with the classes listed (with the ``rdfs:subClassOf*`` path: any class, and the
        subclass triples)."""
        objects: dict[str, set[str] | None] = {}

        def read(predicate: str, values) -> None:
            if values is None or objects.get(predicate, set()) is None:
                objects[predicate] = None
            else:
                objects.setdefault(predicate, set()).update(values)

        for triple in triples:
            if triple.rule is not Rule.TRAVERSE:
                fixed = self.signature.nodes[triple.object].iri
                read(triple.predicate, None if fixed is None else [fixed])
        for node_id in nodes:
            classes = self.signature.nodes[node_id].classes
            if classes and self.subclasses is not None:
                read(RDF.iri("type"), [sub for c in classes for sub in (c, *self.subclasses[c])])
            elif classes:
                read(RDF.iri("type"), None)
                read(RDFS.iri("subClassOf"), None)
        return tuple((p, None if o is None else tuple(sorted(o))) for p, o in sorted(objects.items()))

    def select(self, nodes: Sequence[str], lines: list[str], title: str, *, distinct: bool = True) -> str:
        projected = " ".join(f"?{n}" for n in nodes if not self.signature.nodes[n].iri)
        prefix_lines = "\n".join(f"PREFIX {p}: <{ns}>" for p, ns in PREFIXES.items())
        body = "\n".join(f"  {line}" for line in lines)
        return f"{prefix_lines}\n# {title}\nSELECT {'DISTINCT ' if distinct else ''}{projected} WHERE {{\n{body}\n}}\n"


def _components(nodes: list[str], triples: list[PatternTriple]) -> list[list[str]]:
    """Connected components of ``nodes`` over ``triples`` (in ``nodes`` order)."""
    parent = {n: n for n in nodes}

    def root(n: str) -> str:
        while parent[n] != n:
            n = parent[n]
        return n

    for t in triples:
        parent[root(t.subject)] = root(t.object)
    groups: dict[str, list[str]] = {}
    for n in nodes:
        groups.setdefault(root(n), []).append(n)
    return list(groups.values())


def compile_signature(signature: Signature, *, subclasses: Mapping[str, Sequence[str]] | None = None,
                      instance_counts: Mapping[str, int] | None = None) -> CompiledQuery:
    """Compile ``signature``'s pattern (see the module docstring).

    :param subclasses: the subclasses of each class the signature names, as read from the store
        (:meth:`service.matching.matcher.MatchSession.subclasses`): the parts then restrict classes
        by ``rdf:type`` over that list, which Oxigraph answers from its index; the whole query
        (:attr:`CompiledQuery.text`) keeps the ``rdf:type/rdfs:subClassOf*`` path.
    :param instance_counts: node id → how many instances its classes have (an estimate will do):
        each part's query then starts from its restricted node with the fewest, as Oxigraph
        evaluates a group's triples in the written order.
    :raises ValueError: a class, predicate or fixed IRI is not a valid IRI (named in the message).
    """
    writer = _Writer(signature)
    part_writer = _Writer(signature, subclasses)
    order = list(signature.nodes)
    anchor = signature.modeled_nodes[0]
    required = [t for t in signature.triples if not t.is_optional]
    optional = [t for t in signature.triples if t.is_optional]
    required_nodes = {anchor}
    for t in required:
        required_nodes.update((t.subject, t.object))
    for node_id in signature.nodes:
        if not any(node_id in (t.subject, t.object) for t in signature.triples):
            required_nodes.add(node_id)

    # optional blocks: connected through nodes that occur only in optional triples
    blocks: list[list[PatternTriple]] = []
    for triple in optional:
        joined = [b for b in blocks if any(
            n in (t.subject, t.object) for t in b for n in (triple.subject, triple.object) if n not in required_nodes
        )]
        merged = [triple] + [t for b in joined for t in b]
        blocks = [b for b in blocks if b not in joined] + [merged]
    blocks = [sorted(b, key=signature.triples.index) for b in sorted(blocks, key=lambda b: signature.triples.index(b[-1]))]
    owns = [{n for t in b for n in (t.subject, t.object) if n not in required_nodes} for b in blocks]

    ordered_required = [anchor] + [n for n in order if n in required_nodes and n != anchor]
    title = f"signature {signature.id}: {signature.label}"
    if any(t.rule is Rule.TRAVERSE for t in signature.triples):
        title += ("\n# Its traverses' property paths reach every node along their predicate; graphtwin keeps the\n"
                  "# nearest only (no instance of the far end's classes between, never through a building space,\n"
                  "# boiler, chiller or cooling tower, nor past a stop_at class): run alone, this query returns\n"
                  "# those matches and more (service/matching/matcher.py).")
    whole = writer.group(required, ordered_required, required_nodes, blocks=blocks, block_nodes=owns)
    text = writer.select(order, whole, title)

    # the parts: required components over the exact triples; a block without traverse goes into the
    # query of the one component it hangs on, any other block is joined by the matcher
    exact = [t for t in required if t.rule is not Rule.TRAVERSE]
    components = _components(ordered_required, exact)
    component_of = {n: i for i, c in enumerate(components) for n in c}
    attached: dict[int, list[int]] = {}
    matcher_blocks: list[int] = []
    for index, (block, own) in enumerate(zip(blocks, owns)):
        hooks = {component_of[n] for t in block for n in (t.subject, t.object) if n not in own}
        if all(t.rule is not Rule.TRAVERSE for t in block) and len(hooks) == 1:
            attached.setdefault(hooks.pop(), []).append(index)
        else:
            matcher_blocks.append(index)

    parts: list[QueryPart] = []
    for i, component in enumerate(components):
        triples = [t for t in exact if t.subject in component]
        mine = attached.get(i, [])
        node = signature.nodes[component[0]]
        if not triples and not mine and len(component) == 1 and node.classes:
            parts.append(QueryPart((component[0],), None, classes=node.classes))
            continue
        bound = component + [n for b in mine for n in order if n in owns[b]]
        lines = part_writer.group(triples, _fewest_first(component, set(component), instance_counts), set(component),
                                  blocks=[blocks[b] for b in mine], block_nodes=[owns[b] for b in mine])
        parts.append(QueryPart(tuple(n for n in bound if not signature.nodes[n].iri),
                               writer.select(bound, lines, f"signature {signature.id}: part {len(parts) + 1}", distinct=False),
                               reads=part_writer.reads(triples + [t for b in mine for t in blocks[b]], bound)))
    for number, index in enumerate(matcher_blocks):
        own = [n for n in order if n in owns[index]]
        block_exact = [t for t in blocks[index] if t.rule is not Rule.TRAVERSE]
        hooked = [n for n in order if n not in own and any(n in (t.subject, t.object) for t in block_exact)]
        for component in _components(own + hooked, block_exact):
            triples = [t for t in block_exact if t.subject in component]
            node = signature.nodes[component[0]]
            if not triples and len(component) == 1 and node.classes:
                parts.append(QueryPart((component[0],), None, classes=node.classes, block=number))
                continue
            restricted = set(component) & owns[index]
            lines = part_writer.group(triples, _fewest_first(component, restricted, instance_counts), restricted,
                                      blocks=[], block_nodes=[])
            parts.append(QueryPart(tuple(n for n in component if not signature.nodes[n].iri),
                                   writer.select(component, lines, f"signature {signature.id}: part {len(parts) + 1}", distinct=False),
                                   block=number, reads=part_writer.reads(triples, restricted)))

    traversals = [
        _traversal(signature, t, number)
        for number, index in enumerate(matcher_blocks) for t in blocks[index] if t.rule is Rule.TRAVERSE
    ] + [_traversal(signature, t, None) for t in required if t.rule is Rule.TRAVERSE]
    variables = {n: ("" if signature.nodes[n].iri else n) for n in order}
    return CompiledQuery(
        signature.id, text, variables, tuple(traversals), parts=tuple(parts),
        blocks=tuple(tuple(n for n in order if n in owns[index]) for index in matcher_blocks),
    )


def _fewest_first(nodes: list[str], restricted: set[str], instance_counts: Mapping[str, int] | None) -> list[str]:
    """``nodes`` with the restricted one of fewest instances first (the earliest on a tie; ``nodes``
    unchanged without counts): the node a part's query starts from."""
    counted = [n for n in nodes if n in restricted and instance_counts and n in instance_counts]
    if not counted:
        return nodes
    start = min(counted, key=instance_counts.__getitem__)
    return [start] + [n for n in nodes if n != start]


#: Nodes no traverse passes: the air that leaves a room is not the air that entered it (a fan coil's
#: inlet across the room it serves would read its own supply air as its inlet), nor is the water that
#: leaves a boiler, a chiller or a cooling tower (a closed heating loop's supply water sensor would
#: read the coil's return water as its source).
OPAQUE_CLASSES = tuple(f"{S4BLDG}{name}" for name in ("BuildingSpace", "Boiler", "Chiller", "CoolingTower"))


def _traversal(signature: Signature, triple: PatternTriple, block: int | None) -> Traversal:
    """The searched-for end is the one the signature does not model (a fan looks for its nearest
    upstream sensor, a coil for its nearest fan, even past another coil); when both or
    neither end is modelled, both ends' classes block (``or_reverse``: it is searched from the
    subject, and the object's classes block); so do the triple's ``stop_at`` classes and
    :data:`OPAQUE_CLASSES`."""
    ends = [triple.subject, triple.object]
    searched = [n for n in ends if n not in signature.modeled_nodes] or ends
    if triple.or_reverse:
        searched = searched[-1:]
    elif len(searched) == 2:
        searched = ends
    classes = tuple(c for n in searched for c in signature.nodes[n].classes) + triple.stop_at + OPAQUE_CLASSES
    return Traversal(triple.subject, triple.predicate, triple.object, tuple(dict.fromkeys(classes)), block=block,
                     or_reverse=triple.or_reverse,
                     far_classes=signature.nodes[searched[-1]].classes if triple.or_reverse else (),
                     from_object=triple.or_reverse and searched[-1] == triple.subject)
