"""Models the Brick alignment tests share: the project's ontology subsets and a small generated
campus, both with blank nodes as IRIs (as :meth:`service.graph.store.GraphStore.load_model` has them)."""

import pyoxigraph as ox

from service.graph.blank_nodes import skolemize
from service.graph.rdf_io import parse_rdf
from service.resources import ontologies_dir
from tests.bench.brick_campus import campus_turtle


def ontology_triples() -> list[ox.Triple]:
    """Every ontology file the project ships, parsed."""
    return skolemize([t for p in sorted(ontologies_dir().glob("*.ttl"))
                      for t in parse_rdf(p.read_bytes(), ox.RdfFormat.TURTLE, str(p))], "urn:ontology/genid/")


def campus_triples(n_units: int, extra: str = "") -> list[ox.Triple]:
    """A small Brick campus (tests/bench/brick_campus.py: every third unit described by its points
    only), with ``extra`` Turtle appended."""
    text = campus_turtle(n_units, n_zones=2, points_only_every=3) + extra
    return skolemize(parse_rdf(text.encode(), ox.RdfFormat.TURTLE, "campus"), "urn:campus/genid/")
