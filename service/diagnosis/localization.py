"""Where along the flow path the model fails: between the last sensor it matches and the first it doesn't.

The flow topology (``queries/flow-edges.rq``: fluid edges, and heat couplings as edges both ways;
off-path sensors placed at the node they observe, ``queries/observed-node.rq``; a closed control loop,
``queries/control-edges.rq``, as edges from what decides the controlled sensor's reading to the device
the controller moves) is a directed graph, possibly with loops. For a failing sensor, the walk
upstream stops at the nearest sensors; a failure a failing upstream sensor carries down
(``carries(u, f)``, the caller's) is not reported again; the suspects are the nodes on a walk from
a bounding upstream sensor to the failing one that passes no other sensor. The algorithm and its
rationale: ``docs/diagnosis.md``, "Localisation on the flow path".
"""

from __future__ import annotations

from collections import defaultdict, deque
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass

from service.graph.namespaces import local_name

__all__ = ["FlowTopology", "FailureLocation", "describe_locations", "localize_failures"]


@dataclass(frozen=True)
class FailureLocation:
    """The model fails at ``failing_sensor``; the missing effect sits in ``components``, which lie
    between ``matching_sensor`` (None when no sensor upstream matches) and the failing one."""

    failing_sensor: str
    matching_sensor: str | None
    components: tuple[str, ...]
    upstream_fails: bool = False  # ``matching_sensor`` fails too, by less than the error that reaches ``failing_sensor``
    #: The device a controller moves, when some suspects are upstream of its controlled sensor: a
    #: disturbance there is answered by the controller and shows on the device's side.
    through_controller_of: str | None = None
    #: ``matching_sensor`` is a boundary input: the model is fed its measurement, not judged on it
    matching_is_input: bool = False

    def describe(self, inputs_beside: Sequence[FailureLocation] = ()) -> str:
        """In words; ``inputs_beside``: other locations of the same failing sensor downstream of other
        inputs (:func:`describe_locations`), named in the one sentence with their suspects."""
        components = list(dict.fromkeys(c for location in (self, *inputs_beside) for c in location.components))
        where = " or ".join(local_name(c) for c in components) or "no modelled component"
        loop = (f" (through the controller that moves {local_name(self.through_controller_of)}: a disturbance "
                "upstream of its sensor shows on the side it moves)" if self.through_controller_of else "")
        if inputs_beside:
            names = [local_name(location.matching_sensor) for location in (self, *inputs_beside)]
            return (f"The model fails at {local_name(self.failing_sensor)}, downstream of {', '.join(names[:-1])} and "
                    f"{names[-1]}, whose measurements it takes as inputs: the missing effect sits in {where} between "
                    f"them{loop}.")
        if self.matching_sensor is None:
            return (f"The model fails at {local_name(self.failing_sensor)} with no matching sensor upstream: "
                    f"look at {where}{loop}.")
        if self.upstream_fails:
            return (
                f"The error grows from {local_name(self.matching_sensor)}, which fails too, to "
                f"{local_name(self.failing_sensor)}: a missing effect sits in {where} between them{loop}."
            )
        if self.matching_is_input:
            return (
                f"The model fails at {local_name(self.failing_sensor)}, downstream of "
                f"{local_name(self.matching_sensor)}, whose measurement it takes as an input: the missing "
                f"effect sits in {where} between them{loop}."
            )
        return (
            f"The model matches {local_name(self.matching_sensor)} but not {local_name(self.failing_sensor)}: "
            f"the missing effect sits in {where} between them{loop}."
        )

    def to_dict(self) -> dict:
        return {"between": [self.matching_sensor, self.failing_sensor], "components": list(self.components),
                "upstream_fails": self.upstream_fails, "through_controller_of": self.through_controller_of,
                "upstream_is_input": self.matching_is_input}


def describe_locations(locations: Sequence[FailureLocation]) -> list[str]:
    """One sentence per failing sensor and upstream sensor, but one for a failing sensor downstream of
    several boundary inputs (an air flow and a water temperature both feed a coil): the inputs named
    together, their suspects joined."""
    beside: dict[tuple[str, str | None], list[FailureLocation]] = defaultdict(list)
    for location in locations:
        if location.matching_is_input and not location.upstream_fails:
            beside[(location.failing_sensor, location.through_controller_of)].append(location)
    sentences = []
    for location in locations:
        group = beside.get((location.failing_sensor, location.through_controller_of), [])
        if location not in group:
            sentences.append(location.describe())
        elif location is group[0]:
            sentences.append(location.describe(group[1:]))
    return sentences


class FlowTopology:
    """Directed flow graph of a building model plus where off-path sensors sit.

    :param edges: (upstream IRI, downstream IRI) pairs.
    :param observed_owner: sensor IRI → IRI of the node whose property it observes.
    :param heat_couplings: (IRI, IRI) pairs that exchange heat (``fso:transfersHeatTo``), edges both ways.
    :param control_loops: (controlled sensor IRI, actuated node IRI) pairs of closed control loops
        (``queries/control-edges.rq``): edges from the nodes that decide the sensor's reading (its
        upstream neighbours in the flow path, or the node it observes) to the actuated node.
    """

    def __init__(self, edges: Iterable[tuple[str, str]], observed_owner: Mapping[str, str] | None = None,
                 heat_couplings: Iterable[tuple[str, str]] = (), control_loops: Iterable[tuple[str, str]] = ()):
        self.downstream: dict[str, set[str]] = defaultdict(set)
        self.upstream: dict[str, set[str]] = defaultdict(set)
        for source, target in [*edges, *((b, a) for a, b in heat_couplings), *heat_couplings]:
            self._add(source, target)
        self.observed_owner = dict(observed_owner or {})
        #: the (node, actuated node) edges control loops add to the walks (not a physical path)
        self.control_edges: set[tuple[str, str]] = set()
        for sensor, actuated in control_loops:
            deciding = set(self.upstream.get(sensor, ())) if self.in_flow_path(sensor) else {self.place(sensor)}
            for source in deciding - {actuated, sensor}:
                self.control_edges.add((source, actuated))
        for source, target in self.control_edges:
            self._add(source, target)

    def _add(self, source: str, target: str) -> None:
        self.downstream[source].add(target)
        self.upstream[target].add(source)

    @classmethod
    def from_store(cls, store, model_name: str) -> FlowTopology:
        """Read the topology of ``model_name`` with ``queries/flow-edges.rq``, ``observed-node.rq`` and
        ``control-edges.rq``."""
        rows = store.run_named_query("flow-edges", dataset=model_name)
        edges = [(r["from"].value, r["to"].value) for r in rows if r["kind"].value == "fluid"]
        couplings = [(r["from"].value, r["to"].value) for r in rows if r["kind"].value == "heat"]
        owners: dict[str, str] = {}
        for row in store.run_named_query("observed-node", dataset=model_name):
            if row.get("owner") is not None:
                owners.setdefault(row["device"].value, row["owner"].value)
        loops = [(r["sensor"].value, r["actuated"].value)
                 for r in store.run_named_query("control-edges", dataset=model_name)]
        return cls(edges, owners, couplings, loops)

    def physical_paths(self) -> tuple[dict[str, set[str]], dict[str, set[str]]]:
        """(downstream, upstream) adjacency without the control loops' edges: the flow and heat
        paths as the building graph states them (what a picture of the system draws)."""
        control = self.control_edges
        return ({n: {m for m in ms if (n, m) not in control} for n, ms in self.downstream.items()},
                {n: {m for m in ms if (m, n) not in control} for n, ms in self.upstream.items()})

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

    def loop_actuated(self, upstream: str, between: set[str], node: str) -> str | None:
        """The node a control loop moves, when a walk ``upstream → between → node`` takes one of its
        edges (the suspects then include what lies upstream of the loop's sensor); else None."""
        inside = between | {upstream, node}
        return next((target for source, target in sorted(self.control_edges)
                     if source in inside and target in inside), None)

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
    carries: Callable[[str, str], bool] | None = None, inputs: Iterable[str] = (),
) -> list[FailureLocation]:
    """Locate every first failure.

    :param matches: sensor IRI → True when the model matches it (boundary inputs count as matching:
        they are the measurements themselves); only sensors in this mapping are judged.
    :param sensors: every measuring device of the model (targets and boundary inputs); the upstream
        walks stop at all of them.
    :param inputs: the boundary inputs among ``sensors`` (a location bounded by one says so).
    :param carries: ``carries(u, f)``: whether the failure at sensor ``f`` is what the failing sensor
        ``u`` upstream of it carries down (None: always).
    :returns: one :class:`FailureLocation` per failing sensor that does not merely inherit a failure
        from a failing sensor upstream (per nearest upstream sensor bounding its suspects), sorted by
        sensor IRI.
    """
    sensor_set, input_set = set(sensors), set(inputs)
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
            locations.append(FailureLocation(sensor, reference, tuple(sorted(between)),
                                             upstream_fails=reference in grows_from,
                                             through_controller_of=topology.loop_actuated(reference, between, place),
                                             matching_is_input=reference in input_set))
    return locations
