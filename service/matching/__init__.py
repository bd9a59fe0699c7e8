"""The matching floor: signature patterns, their compilation to SPARQL, matching them in a model's
graphs, and the signature library as triples (``docs/matching.md``)."""
