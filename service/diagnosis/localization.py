"""Where along the flow path the model fails: between the last sensor it matches and the first it doesn't.

The building graph's flow topology (``fso:suppliesFluidTo`` for air and water, ``fso:transfersHeatTo``
between a coil's water side and its air side; ``queries/flow-edges.rq``) is a directed graph,
possibly with loops (return air mixed back into the supply). A heat transfer couples both ways — the
air a coil heats decides the water leaving it as much as the water decides the air — so it is an
edge in both directions: a coil's water outlet sensor has the air side's upstream among its suspects
(a fan's motor heat upstream of the coil shows at the water outlet). For a failing sensor ``f``:

1. its place ``p`` is ``f`` itself when ``f`` sits in the flow path, else the node that has the
   property it observes (a valve position sensor sits at its valve, a power meter at its fan;
   ``queries/observed-node.rq``);
2. walking upstream from ``p``, the walk stops at the first sensor on every branch; those are the
   nearest upstream sensors. If one of them fails too and ``f``'s failure is what it carries down,
   ``f`` only inherits it and is not reported (an off-path sensor is still reported at its
   component). Whether it is: ``carries(u, f)``, given by the caller (the diagnosis: ``f``'s residual
   minus ``u``'s is within the noise, for sensors of one unit); where no failing upstream sensor
   carries it, the error grows between them, and they bound the suspects as a matching sensor does
   (on real data a mixed-air sensor 0.7 K off must not hide a supply-air sensor 14 K off);
3. the suspects are the nodes ``n`` with a walk ``u → n → p`` from a matching upstream sensor ``u``
   that passes no other sensor: forward-reachable from ``u`` and backward-reachable from ``p``, each
   search stopping at sensors. On a loop this is still exact, because searches stop at sensors
   rather than at "already seen upstream" nodes.
"""

from __future__ import annotations

from collections import defaultdict, deque
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass

from service.graph.namespaces import local_name

__all__ = ["FlowTopology", "FailureLocation", "localize_failures"]


@dataclass(frozen=True)
class FailureLocation:
    """The model fails at ``failing_sensor``; the missing effect sits in ``components``, which lie
    between ``matching_sensor`` (None when no sensor upstream matches) and the failing one."""

    failing_sensor: str
    matching_sensor: str | None
    components: tuple[str, ...]
    upstream_fails: bool = False  # ``matching_sensor`` fails too, by less than the error that reaches ``failing_sensor``

    def describe(self) -> str:
        where = " or ".join(local_name(c) for c in self.components) or "no modelled component"
        if self.matching_sensor is None:
            return f"The model fails at {local_name(self.failing_sensor)} with no matching sensor upstream: look at {where}."
        if self.upstream_fails:
            return (
                f"The error grows from {local_name(self.matching_sensor)}, which fails too, to "
                f"{local_name(self.failing_sensor)}: a missing effect sits in {where} between them."
            )
        return (
            f"The model matches {local_name(self.matching_sensor)} but not {local_name(self.failing_sensor)}: "
            f"the missing effect sits in {where} between them."
        )

    def to_dict(self) -> dict:
        return {"between": [self.matching_sensor, self.failing_sensor], "components": list(self.components),
                "upstream_fails": self.upstream_fails}


class FlowTopology:
    """Directed flow graph of a building model plus where off-path sensors sit.

    :param edges: (upstream IRI, downstream IRI) pairs.
    :param observed_owner: sensor IRI → IRI of the node whose property it observes.
    :param heat_couplings: (IRI, IRI) pairs that exchange heat (``fso:transfersHeatTo``), edges both ways.
    """

    def __init__(self, edges: Iterable[tuple[str, str]], observed_owner: Mapping[str, str] | None = None,
                 heat_couplings: Iterable[tuple[str, str]] = ()):
        self.downstream: dict[str, set[str]] = defaultdict(set)
        self.upstream: dict[str, set[str]] = defaultdict(set)
        for source, target in [*edges, *((b, a) for a, b in heat_couplings), *heat_couplings]:
            self.downstream[source].add(target)
            self.upstream[target].add(source)
        self.observed_owner = dict(observed_owner or {})

    @classmethod
    def from_store(cls, store, model_name: str) -> FlowTopology:
        """Read the topology of ``model_name`` with ``queries/flow-edges.rq`` and ``observed-node.rq``."""
        rows = store.run_named_query("flow-edges", dataset=model_name)
        edges = [(r["from"].value, r["to"].value) for r in rows if r["kind"].value == "fluid"]
        couplings = [(r["from"].value, r["to"].value) for r in rows if r["kind"].value == "heat"]
        owners: dict[str, str] = {}
        for row in store.run_named_query("observed-node", dataset=model_name):
            if row.get("owner") is not None:
                owners.setdefault(row["device"].value, row["owner"].value)
        return cls(edges, owners, couplings)

    def in_flow_path(self, node: str) -> bool:
        return node in self.downstream or node in self.upstream

    def place(self, sensor: str) -> str:
        """The flow-path node where ``sensor``'s reading is decided."""
        if self.in_flow_path(sensor):
            return sensor
        return self.observed_owner.get(sensor, sensor)

    def _reach(self, start: str, neighbours: Mapping[str, set[str]], stop: set[str]) -> set[str]:
        seen = {start}
        queue = deque([start])
        while queue:
            node = queue.popleft()
            for nxt in neighbours.get(node, ()):
                if nxt in seen:
                    continue
                seen.add(nxt)
                if nxt not in stop:
                    queue.append(nxt)
        return seen

    def nearest_upstream_sensors(self, node: str, sensors: set[str]) -> set[str]:
        """Sensors reached first on every upstream branch of ``node`` (the walk stops at sensors)."""
        reached = self._reach(node, self.upstream, sensors)
        return {s for s in reached if s in sensors and s != node}

    def nodes_between(self, upstream_sensor: str, node: str, sensors: set[str]) -> set[str]:
        """Nodes on a walk ``upstream_sensor → n → node`` passing no other sensor (ends excluded
        unless ``node`` is not a sensor)."""
        forward = self._reach(upstream_sensor, self.downstream, sensors | {node})
        backward = self._reach(node, self.upstream, sensors | {upstream_sensor})
        between = (forward & backward) - sensors - {upstream_sensor}
        if node not in sensors:
            between.add(node)
        else:
            between.discard(node)
        return between


def localize_failures(
    topology: FlowTopology, matches: Mapping[str, bool], sensors: Iterable[str],
    carries: Callable[[str, str], bool] | None = None,
) -> list[FailureLocation]:
    """Locate every first failure.

    :param matches: sensor IRI → True when the model matches it (boundary inputs count as matching:
        they are the measurements themselves); only sensors in this mapping are judged.
    :param sensors: every measuring device of the model (targets and boundary inputs); the upstream
        walks stop at all of them.
    :param carries: ``carries(u, f)``: whether the failure at sensor ``f`` is what the failing sensor
        ``u`` upstream of it carries down (None: always).
    :returns: one :class:`FailureLocation` per failing sensor that does not merely inherit a failure
        from a failing sensor upstream (per nearest upstream sensor bounding its suspects), sorted by
        sensor IRI.
    """
    sensor_set = set(sensors)
    locations = []
    for sensor in sorted(s for s, ok in matches.items() if not ok):
        place = topology.place(sensor)
        upstream = topology.nearest_upstream_sensors(place, sensor_set - {sensor})
        good = sorted(u for u in upstream if matches.get(u, True))
        failing = sorted(u for u in upstream if not matches.get(u, True))
        grows_from = []
        if failing and place == sensor:
            if carries is None or any(carries(u, sensor) for u in failing):
                continue
            grows_from = failing
        if not good and not grows_from:
            locations.append(FailureLocation(sensor, None, (place,) if place != sensor else ()))
            continue
        for reference in good + grows_from:
            between = topology.nodes_between(reference, place, sensor_set)
            locations.append(FailureLocation(sensor, reference, tuple(sorted(between)), upstream_fails=reference in grows_from))
    return locations
