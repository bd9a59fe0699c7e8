"""The graph floor: the Oxigraph store and its layout of named graphs, RDF in and out, the embedded and
external-endpoint backends, namespaces and units, and the alignment of a model's spellings to the
canonical SAREF/FSO view (``docs/graph-store.md``, ``docs/alignment.md``)."""
