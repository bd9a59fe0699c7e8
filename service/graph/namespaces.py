"""IRIs of the vocabularies graphtwin reads and writes (official namespaces, see ``ontologies/``)."""

from __future__ import annotations

import hashlib
from collections import Counter
from collections.abc import Iterable

import pyoxigraph as ox

__all__ = [
    "SAREF", "S4BLDG", "S4SYST", "FSO", "BRICK", "REF", "GT", "GTR", "QUDT", "UNIT", "QK",
    "RDF", "RDFS", "OWL", "XSD", "PROV", "DCTERMS", "PREFIXES", "Namespace", "expand_curie",
    "compact_iri", "graph_iri", "local_name", "namespace_of", "distinct_local_names",
]


class Namespace(str):
    """A namespace IRI; ``NS.term`` and ``NS["term"]`` give the term as a :class:`pyoxigraph.NamedNode`."""

    def __getattr__(self, local: str) -> ox.NamedNode:
        if local.startswith("__"):
            raise AttributeError(local)
        return ox.NamedNode(str(self) + local)

    def __getitem__(self, local: str) -> ox.NamedNode:  # type: ignore[override]
        return ox.NamedNode(str(self) + local)

    def iri(self, local: str) -> str:
        return str(self) + local


SAREF = Namespace("https://saref.etsi.org/core/")
S4BLDG = Namespace("https://saref.etsi.org/saref4bldg/")
S4SYST = Namespace("https://saref.etsi.org/saref4syst/")
FSO = Namespace("https://w3id.org/fso#")
BRICK = Namespace("https://brickschema.org/schema/Brick#")
REF = Namespace("https://brickschema.org/schema/Brick/ref#")
#: graphtwin's own vocabulary (``ontologies/graphtwin.ttl``).
GT = Namespace("https://w3id.org/graphtwin/ontology#")
#: graphtwin's result resources (runs, component instances, estimates): minted IRIs live here.
GTR = Namespace("https://w3id.org/graphtwin/resource/")
QUDT = Namespace("http://qudt.org/schema/qudt/")
UNIT = Namespace("http://qudt.org/vocab/unit/")
QK = Namespace("http://qudt.org/vocab/quantitykind/")
RDF = Namespace("http://www.w3.org/1999/02/22-rdf-syntax-ns#")
RDFS = Namespace("http://www.w3.org/2000/01/rdf-schema#")
OWL = Namespace("http://www.w3.org/2002/07/owl#")
XSD = Namespace("http://www.w3.org/2001/XMLSchema#")
PROV = Namespace("http://www.w3.org/ns/prov#")
DCTERMS = Namespace("http://purl.org/dc/terms/")

#: Prefix → namespace, used for CURIEs in signature files and as query prefixes.
PREFIXES: dict[str, str] = {
    "saref": str(SAREF), "s4bldg": str(S4BLDG), "s4syst": str(S4SYST), "fso": str(FSO),
    "brick": str(BRICK), "ref": str(REF), "gt": str(GT), "gtr": str(GTR), "qudt": str(QUDT),
    "unit": str(UNIT), "quantitykind": str(QK), "rdf": str(RDF), "rdfs": str(RDFS),
    "owl": str(OWL), "xsd": str(XSD), "prov": str(PROV), "dcterms": str(DCTERMS),
}


def expand_curie(curie: str) -> str:
    """``"s4bldg:Fan"`` → full IRI; a full IRI in angle brackets or with a scheme passes through.

    :raises ValueError: for an unknown prefix, naming it.
    """
    text = curie.strip()
    if text.startswith("<") and text.endswith(">"):
        return text[1:-1]
    if "://" in text or text.startswith("urn:"):
        return text
    prefix, sep, local = text.partition(":")
    if not sep:
        raise ValueError(f"{curie!r} is neither a CURIE (prefix:name) nor an IRI")
    if prefix not in PREFIXES:
        raise ValueError(f"unknown prefix {prefix!r} in {curie!r}; known: {', '.join(sorted(PREFIXES))}")
    return PREFIXES[prefix] + local


def compact_iri(iri: str) -> str:
    """The inverse of :func:`expand_curie`: ``prefix:name`` where a known prefix covers ``iri`` and the
    rest is a plain name (letters, digits, ``_``, ``-``), else ``<iri>``."""
    for prefix, namespace in PREFIXES.items():
        if iri.startswith(namespace) and iri[len(namespace):].replace("_", "a").replace("-", "a").isalnum():
            return f"{prefix}:{iri[len(namespace):]}"
    return f"<{iri}>"


def graph_iri(kind: str, name: str = "") -> ox.NamedNode:
    """IRI of one of graphtwin's named graphs, e.g. ``graph_iri("model", "ahu1")``."""
    return ox.NamedNode(f"{GTR}graph/{kind}" + (f"/{name}" if name else ""))


def local_name(iri: str, *, hashed: bool = False) -> str:
    """The last segment of ``iri`` (after its last ``/`` or ``#``); with ``hashed``, followed by ``-``
    and the first 8 hex digits of the SHA-256 of the whole IRI (``…/unit1#fan`` and ``…/unit2#fan``
    then name two things)."""
    local = iri.replace("#", "/").rstrip("/").rsplit("/", 1)[-1]
    return f"{local}-{hashlib.sha256(iri.encode()).hexdigest()[:8]}" if hashed else local


def namespace_of(iri: str) -> str:
    """The IRI up to and including its last ``#`` or ``/``."""
    return iri[: max(iri.rfind("#"), iri.rfind("/")) + 1]


def distinct_local_names(iris: Iterable[str]) -> dict[str, str]:
    """IRI → its :func:`local_name`, hashed where two of ``iris`` share one: names for result IRIs
    that stay readable and never merge two nodes."""
    iris = set(iris)
    shared = Counter(local_name(i) for i in iris)
    return {i: local_name(i, hashed=shared[local_name(i)] > 1) for i in iris}

