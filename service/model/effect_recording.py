"""Recording an effect in the semantic model: the triples ``add-effect`` writes and re-assembly reads.

An applied effect is data in the building graph (a user can also write it by hand or POST it)::

    <node> gt:hasEffect <applied> .
    <applied> a gt:AppliedEffect ; gt:effectSignature <signature IRI> ; rdfs:label "…" ; prov:generatedAtTime "…" .

``queries/applied-effects.rq`` finds them; :mod:`service.model.effect_splicing` splices each one. The
new model is written in the format of the output file's suffix, appended to the user's text where
both are Turtle or both N-Triples (``docs/assembly.md``).
"""

from __future__ import annotations

from datetime import datetime, timezone
from pathlib import Path

import pyoxigraph as ox

from service.errors import InputError, UnsupportedFormatError
from service.graph.namespaces import GT, GTR, PROV, RDF, RDFS, XSD, local_name
from service.graph.rdf_io import rdf_format
from service.matching.signature import Signature

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
    """Write ``source`` plus ``triples`` to ``output``, in the format its suffix names.

    :raises InputError: when ``output`` is ``source`` (the user's file is never overwritten);
    :raises UnsupportedFormatError: its suffix names no RDF format graphtwin writes.
    """
    if output.resolve() == source.resolve():
        raise InputError(f"{output}: write the new model to another file; graphtwin keeps the original")
    try:
        source_format, output_format = rdf_format(source.suffix), rdf_format(output.suffix)
    except UnsupportedFormatError as exc:
        raise UnsupportedFormatError(f"{output}: {exc}") from None
    block = "\n".join(f"{t.subject} {t.predicate} {t.object} ." for t in triples)
    header = f"\n# Added by graphtwin add-effect ({datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC)\n"
    if source_format == output_format and source_format in (ox.RdfFormat.TURTLE, ox.RdfFormat.N_TRIPLES):
        text = source.read_text(encoding="utf-8")
        output.write_text(text.rstrip("\n") + "\n" + header + block + "\n", encoding="utf-8")
        return
    held = [ox.Triple(q.subject, q.predicate, q.object) for q in ox.parse(path=str(source), format=source_format)]
    body = ox.serialize(held + triples, format=output_format)
    if output_format in (ox.RdfFormat.TURTLE, ox.RdfFormat.N_TRIPLES):  # the formats with comments
        body += header.encode("utf-8")
    output.write_bytes(body)
