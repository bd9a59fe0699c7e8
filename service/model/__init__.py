"""The model floor: assembling a simulation model from a building graph (instances, wiring, effects),
the assembled model, its triples and summary, and the simulator (``docs/assembly.md``)."""
