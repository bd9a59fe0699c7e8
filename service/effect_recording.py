"""Recording an effect in the semantic model: the triples ``add-effect`` writes and re-assembly reads.

An applied effect is data in the building graph, so a user can also write it by hand or POST it::

    <node> gt:hasEffect <applied> .
    <applied> a gt:AppliedEffect ; gt:effectSignature <signature IRI> ;
        rdfs:label "FanMotorHeat at supply_fan" ; prov:generatedAtTime "…"^^xsd:dateTime .

``queries/applied-effects.rq`` finds them; :func:`service.assembly.assemble` splices each one.
For a Turtle source the new triples are appended to the user's text (prefixes, comments and layout
kept); any other format is re-serialised as Turtle.
"""

from __future__ import annotations

from datetime import datetime, timezone
from pathlib import Path

import pyoxigraph as ox

from .namespaces import GT, GTR, PROV, RDF, RDFS, XSD, local_name
from .signature import Signature

__all__ = ["applied_effect_iri", "applied_effect_triples", "record_effect_in_file"]


def applied_effect_iri(signature: Signature, node: str) -> ox.NamedNode:
    """``gtr:applied-effect/<effect>/<node's local name>-<8 hex digits of its IRI's SHA-256>``: one per
    effect and building node, whatever other node shares the local name."""
    return ox.NamedNode(f"{GTR}applied-effect/{signature.id}/{local_name(node, hashed=True)}")


def applied_effect_triples(signature: Signature, node: str, when: datetime | None = None) -> list[ox.Triple]:
    """The triples recording ``signature`` applied at building node ``node``."""
    when = when or datetime.now(timezone.utc)
    applied = applied_effect_iri(signature, node)
    return [
        ox.Triple(ox.NamedNode(node), GT.hasEffect, applied),
        ox.Triple(applied, RDF.type, GT.AppliedEffect),
        ox.Triple(applied, GT.effectSignature, ox.NamedNode(signature.iri)),
        ox.Triple(applied, RDFS.label, ox.Literal(f"{signature.id} at {local_name(node)}")),
        ox.Triple(applied, PROV.generatedAtTime, ox.Literal(when.isoformat(), datatype=XSD.dateTime)),
    ]


def record_effect_in_file(source: Path, output: Path, triples: list[ox.Triple]) -> None:
    """Write ``source`` plus ``triples`` to ``output`` (Turtle).

    :raises ValueError: when ``output`` is ``source`` (the user's file is never overwritten).
    """
    if output.resolve() == source.resolve():
        raise ValueError(f"{output}: write the new model to another file; graphtwin keeps the original")
    block = "\n".join(f"{t.subject} {t.predicate} {t.object} ." for t in triples)
    header = f"\n# Added by graphtwin add-effect ({datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC)\n"
    if source.suffix.lower() in (".ttl", ".nt"):
        text = source.read_text(encoding="utf-8")
        output.write_text(text.rstrip("\n") + "\n" + header + block + "\n", encoding="utf-8")
        return
    fmt = ox.RdfFormat.from_extension(source.suffix.lstrip(".").lower())
    quads = list(ox.parse(path=str(source), format=fmt))
    body = ox.serialize([ox.Triple(q.subject, q.predicate, q.object) for q in quads], format=ox.RdfFormat.TURTLE)
    output.write_bytes(body + (header + block + "\n").encode("utf-8"))
