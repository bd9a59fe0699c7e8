"""Signature patterns: the declarative description of where a component model (or an effect) applies.

A signature is one TOML file in ``signatures/`` (every key in ``signatures/README.md``): pattern nodes
(allowed classes, a fixed IRI, a literal or any-term slot), pattern triples with a rule each
(``exact``, ``optional``, ``traverse``: the nearest match along the predicate), the nodes the model
represents, and the input / output / parameter mapping of Table 1 of Bjørnskov, Jradi & Wetter,
"Automated model generation and parameter estimation of building energy models using an
ontology-based framework". :func:`read_signature` checks a file's content; every problem raises
:class:`SignatureError` naming the file and the key. Format, rules and checks: ``docs/matching.md``.
"""

from __future__ import annotations

import tomllib
from collections.abc import Sequence
from dataclasses import KW_ONLY, dataclass, field
from enum import Enum
from pathlib import Path
from typing import Any

from service.errors import SignatureError
from service.graph.namespaces import GTR, expand_curie

__all__ = [
    "Rule", "PatternNode", "PatternTriple", "InputMapping", "OutputMapping", "ParameterMapping",
    "EffectSplice", "Signature", "SignatureError", "QUANTITIES", "QUANTITY_UNITS", "read_signature",
    "signature_from_dict", "signature_iri", "signature_error", "required_outward",
]

#: What a port may carry (``signatures/README.md``, *Quantities*) and the simulator's unit of each.
QUANTITY_UNITS = {
    "temperature": "degC", "mass_flow": "kg/s", "volume_flow": "m3/s", "power": "W", "position": "1",
    "heat_rate": "W",
}
QUANTITIES = frozenset(QUANTITY_UNITS)


class Rule(str, Enum):
    """How a pattern triple matches: one triple, possibly absent, or the nearest along the predicate."""

    EXACT = "exact"
    TRAVERSE = "traverse"
    OPTIONAL = "optional"


@dataclass(frozen=True)
class PatternNode:
    """A node of the pattern: a variable restricted to ``classes`` (subclasses match too), a fixed
    ``iri``, a ``literal`` slot (the object of a datatype triple), or ``any`` term (a unit IRI)."""

    id: str
    classes: tuple[str, ...] = ()
    iri: str | None = None
    literal: bool = False
    any: bool = False


@dataclass(frozen=True)
class PatternTriple:
    """A triple between pattern nodes (ids; the predicate an IRI) and its rule (``docs/matching.md``)."""

    subject: str
    predicate: str
    object: str
    _: KW_ONLY
    rule: Rule = Rule.EXACT
    optional: bool = False  # True for an optional traverse (rule TRAVERSE); OPTIONAL rule implies it
    #: a traverse that, where the triple as written gives the end it searches from no partner, takes
    #: the triple reversed (a coil's fan: upstream in a blow-through unit, else downstream)
    or_reverse: bool = False
    #: classes a traverse does not pass, beside the searched-for end's (a mixing box, where streams join)
    stop_at: tuple[str, ...] = ()

    @property
    def is_optional(self) -> bool:
        return self.optional or self.rule is Rule.OPTIONAL


@dataclass(frozen=True)
class InputMapping:
    """Input port ``port`` is fed by output ``quantity`` of the model that represents node ``source``."""

    port: str
    source: str
    quantity: str


@dataclass(frozen=True)
class OutputMapping:
    """Output port ``port`` carries ``quantity`` at the outlet of pattern node ``node``."""

    port: str
    node: str
    quantity: str


@dataclass(frozen=True)
class ParameterMapping:
    """Parameter ``name`` may be read from the literal bound to ``node`` (unit from ``unit_node``)."""

    name: str
    node: str
    unit_node: str | None = None


@dataclass(frozen=True)
class EffectSplice:
    """Where an effect enters the model it extends: on an ``input`` port (the effect transforms what
    the port receives) or on an ``output`` port (it transforms what the port emits) of the component
    that represents node ``node``. ``host_models`` (``module:Class`` names), when given, restricts the
    effect to hosts of those models (e.g. coil thermal mass only where the chosen coil model is static).
    ``readings_unchanged`` (an input splice): the fault changes what the port does, not what the host
    reports of it, so the host's outputs that report the input (``Port.reports``) read its feed.
    """

    node: str
    port: str
    side: str  # "input" or "output"
    host_models: tuple[str, ...] = ()
    readings_unchanged: bool = False


@dataclass(frozen=True)
class Signature:
    """One signature file: its pattern, the nodes its model represents, and the model's mapping."""

    id: str
    label: str
    kind: str
    nodes: dict[str, PatternNode]
    triples: tuple[PatternTriple, ...]
    modeled_nodes: tuple[str, ...]
    inputs: tuple[InputMapping, ...] = ()
    outputs: tuple[OutputMapping, ...] = ()
    parameters: tuple[ParameterMapping, ...] = ()
    model: str | None = None
    fmu: Path | None = None
    complexity: int = 1
    comment: str = ""
    splice: EffectSplice | None = None
    source_file: Path | None = None
    extra: dict[str, Any] = field(default_factory=dict)
    can_appear: bool = True  # effects: may appear from one day to the next (a fault), else a property
    holds_values: bool = False  # measuring devices whose series may hold one value for days (schedules, commands)
    steps: bool = False  # boundary series that step between samples (schedules): held, not interpolated
    #: effects: the ids of more specific effects this one is not proposed beside where they apply at
    #: the same node (its own special case or twin, with a wider prior or one parameter fewer)
    yields_to: tuple[str, ...] = ()
    #: said by the assembly about each node where this signature is chosen (what the user may add to
    #: the graph for a more specific one)
    note: str = ""

    @property
    def file_name(self) -> str:
        """The signature file's name for messages (``hot_water_loop.toml``; no server path)."""
        return self.source_file.name if self.source_file is not None else f"<signature {self.id}>"

    @property
    def iri(self) -> str:
        return signature_iri(self.id)

    def node(self, node_id: str) -> PatternNode:
        return self.nodes[node_id]

    def output_quantity(self, port: str) -> str | None:
        """The quantity the signature gives its output ``port`` (None: no such output)."""
        return next((o.quantity for o in self.outputs if o.port == port), None)

    def stating_property(self, parameter: str) -> str | None:
        """The property IRI a graph states ``parameter`` with, where the pattern names one: the fixed
        ``iri`` node beside the value node the parameter maps from (``s4bldg:nominalPowerRate`` for a
        fan's nominal power, read from a property value that is the value of that property)."""
        mapping = next((m for m in self.parameters if m.name == parameter), None)
        if mapping is None:
            return None
        holders = {t.subject for t in self.triples if t.object == mapping.node}
        return next((self.nodes[t.object].iri for t in self.triples
                     if t.subject in holders and t.object in self.nodes and self.nodes[t.object].iri), None)


def signature_iri(signature_id: str) -> str:
    return f"{GTR}signature/{signature_id}"


_TOP_KEYS = {
    "id", "label", "comment", "kind", "model", "fmu", "complexity", "modeled_nodes", "nodes",
    "triples", "inputs", "outputs", "parameters", "splice", "extra", "can_appear", "holds_values", "steps",
    "yields_to", "note",
}
_NODE_KEYS = ("classes", "iri", "literal", "any")
_TRIPLE_KEYS = {"subject", "predicate", "object", "rule", "optional", "or_reverse", "stop_at"}
_SPLICE_KEYS = {"node", "input", "output", "host_models", "readings_unchanged"}


def signature_error(path: Path | None, where: str, message: str) -> SignatureError:
    """The error for key ``where`` of signature file ``path``."""
    return SignatureError(f"{path or '<signature>'}: {where}: {message}")


def _kind_of(value: Any) -> str:
    """What a parsed TOML value is, in words for a message (``None`` stands for a missing key)."""
    if value is None:
        return "nothing (the key is missing)"
    if isinstance(value, (str, list, dict)) and not value:
        return {str: "an empty string", list: "an empty array", dict: "an empty table"}[type(value)]
    for kind, words in ((bool, "a boolean"), (int, "an integer"), (float, "a float"), (str, "a string"),
                        (list, "an array"), (dict, "a table")):
        if isinstance(value, kind):
            return words
    return f"a {type(value).__name__}"  # a TOML date or time


def _table(path: Path | None, where: str, value: Any, expected: str) -> dict[str, Any]:
    """``value`` when it is a table; else an error saying it should be ``expected`` and what it is."""
    if not isinstance(value, dict):
        raise signature_error(path, where, f"expected {expected}, got {_kind_of(value)}")
    return value


def _array(path: Path | None, where: str, value: Any, expected: str, *, empty_ok: bool = True) -> list[Any]:
    """``value`` when it is an array (a non-empty one unless ``empty_ok``); else an error as :func:`_table`."""
    if not isinstance(value, list) or not (value or empty_ok):
        raise signature_error(path, where, f"expected {expected}, got {_kind_of(value)}")
    return value


def _text(path: Path | None, where: str, value: Any) -> str:
    if not isinstance(value, str) or not value:
        raise signature_error(path, where, f"expected a non-empty string, got {_kind_of(value)}")
    return value


def _only_keys(path: Path | None, where: str, spec: dict[str, Any], allowed: set[str]) -> None:
    unknown = set(spec) - allowed
    if unknown:
        raise signature_error(path, where, f"unknown key(s) {sorted(unknown)}; allowed: {sorted(allowed)}")


def _quantity(path: Path | None, where: str, value: Any) -> str:
    quantity = _text(path, where, value)
    if quantity not in QUANTITIES:
        raise signature_error(path, where, f"{quantity!r} is not a quantity; known: {', '.join(sorted(QUANTITIES))}")
    return quantity


def _model_name(path: Path | None, where: str, value: Any) -> str:
    """``value`` when it reads ``module:Class``: a dotted module path, a colon, a class name."""
    module, sep, name = value.partition(":") if isinstance(value, str) else ("", "", "")
    if not (sep and name.isidentifier() and all(part.isidentifier() for part in module.split("."))):
        raise signature_error(path, where, f"{value!r} must read 'module:Class'")
    return value


def _curie(path: Path | None, where: str, text: Any) -> str:
    if not isinstance(text, str):
        raise signature_error(path, where, f"expected a CURIE or IRI string, got {_kind_of(text)}")
    try:
        return expand_curie(text)
    except ValueError as exc:
        raise signature_error(path, where, str(exc)) from None


def signature_from_dict(data: dict[str, Any], path: Path | None = None) -> Signature:
    """Build and validate a :class:`Signature` from parsed TOML: every key is checked for its type
    (table, array, string, …) where it is read. Model classes are not imported here
    (:class:`~service.components.library.SignatureLibrary` checks them).

    :raises SignatureError: naming the file and key of the first problem found.
    """
    _only_keys(path, "top level", data, _TOP_KEYS)
    for key in ("id", "nodes", "modeled_nodes"):
        if key not in data:
            raise signature_error(path, "top level", f"missing required key {key!r}")
    sig_id = data["id"]
    if not isinstance(sig_id, str) or not sig_id.isidentifier():
        raise signature_error(path, "id", f"{sig_id!r} must be an identifier (letters, digits, underscores)")
    kind = data.get("kind", "component")
    if kind not in ("component", "effect"):
        raise signature_error(path, "kind", f"{kind!r} must be 'component' or 'effect'")
    label, comment, note = data.get("label", sig_id), data.get("comment", ""), data.get("note", "")
    for key, value in (("label", label), ("comment", comment), ("note", note)):
        if not isinstance(value, str):
            raise signature_error(path, key, f"expected a string, got {_kind_of(value)}")

    nodes: dict[str, PatternNode] = {}
    for node_id, spec in _table(path, "nodes", data["nodes"], "a table of pattern nodes ([nodes])").items():
        where = f"nodes.{node_id}"
        if not node_id.isidentifier():
            raise signature_error(path, where, "node ids must be identifiers")
        spec = _table(path, where, spec, "a table with one of 'classes', 'iri', 'literal = true', 'any = true'")
        chosen = [k for k in _NODE_KEYS if k in spec]
        if len(chosen) != 1 or set(spec) - set(_NODE_KEYS):
            raise signature_error(path, where, "give exactly one of 'classes', 'iri', 'literal = true', 'any = true'")
        if "classes" in spec:
            classes = _array(path, where + ".classes", spec["classes"], "a non-empty array of classes", empty_ok=False)
            nodes[node_id] = PatternNode(node_id, classes=tuple(
                _curie(path, f"{where}.classes[{i}]", c) for i, c in enumerate(classes)))
        elif "iri" in spec:
            nodes[node_id] = PatternNode(node_id, iri=_curie(path, where + ".iri", spec["iri"]))
        else:
            flag = chosen[0]
            if spec[flag] is not True:
                raise signature_error(path, f"{where}.{flag}", "must be true")
            nodes[node_id] = PatternNode(node_id, literal=flag == "literal", any=flag == "any")

    def known(node_id: Any, where: str) -> str:
        if not isinstance(node_id, str):
            raise signature_error(path, where, f"expected a node id (a string), got {_kind_of(node_id)}")
        if node_id not in nodes:
            raise signature_error(path, where, f"names node {node_id!r}, which is not in [nodes]")
        return node_id

    triples = []
    for i, spec in enumerate(_array(path, "triples", data.get("triples", []), "an array of tables ([[triples]])")):
        where = f"triples[{i}]"
        spec = _table(path, where, spec, "a table with 'subject', 'predicate', 'object', optional 'rule', 'optional', 'or_reverse' and 'stop_at'")
        _only_keys(path, where, spec, _TRIPLE_KEYS)
        rule_text = spec.get("rule", "exact")
        try:
            rule = Rule(str(rule_text).lower())
        except ValueError:
            raise signature_error(path, where + ".rule", f"{rule_text!r} must be exact, traverse or optional") from None
        subject = known(spec.get("subject"), where + ".subject")
        obj = known(spec.get("object"), where + ".object")
        if nodes[subject].literal:
            raise signature_error(path, where + ".subject", "a literal node cannot be a subject")
        if rule is Rule.TRAVERSE and not (nodes[subject].classes and nodes[obj].classes):
            raise signature_error(path, where, "traverse needs class-restricted nodes at both ends")
        predicate = _curie(path, where + ".predicate", spec.get("predicate"))
        optional = spec.get("optional", False)
        or_reverse = spec.get("or_reverse", False)
        for key, flag in (("optional", optional), ("or_reverse", or_reverse)):
            if not isinstance(flag, bool):
                raise signature_error(path, f"{where}.{key}", "must be true or false")
        if or_reverse and rule is not Rule.TRAVERSE:
            raise signature_error(path, where + ".or_reverse", "only a traverse can fall back to the reverse direction")
        stop_at = tuple(_curie(path, f"{where}.stop_at[{j}]", c) for j, c in enumerate(
            _array(path, f"{where}.stop_at", spec.get("stop_at", []), "an array of class CURIEs")))
        if stop_at and rule is not Rule.TRAVERSE:
            raise signature_error(path, where + ".stop_at", "only a traverse has places to stop at")
        triples.append(PatternTriple(subject, predicate, obj, rule=rule, optional=optional or rule is Rule.OPTIONAL,
                                     or_reverse=or_reverse, stop_at=stop_at))

    modeled = tuple(known(n, f"modeled_nodes[{i}]") for i, n in enumerate(_array(
        path, "modeled_nodes", data["modeled_nodes"], "a non-empty array of node ids", empty_ok=False)))

    def entries(key: str, expected: str, allowed: set[str]) -> list[tuple[str, str, dict[str, Any]]]:
        """(name, key path, table) of each ``[key.NAME]`` table, checked to hold only ``allowed`` keys."""
        found = []
        for name, spec in _table(path, key, data.get(key, {}), f"a table of [{key}.NAME] tables").items():
            where = f"{key}.{name}"
            spec = _table(path, where, spec, expected)
            _only_keys(path, where, spec, allowed)
            found.append((name, where, spec))
        return found

    inputs = []
    for port, where, spec in entries("inputs", "a table with keys 'source' and 'quantity'", {"source", "quantity"}):
        source = known(spec.get("source"), where + ".source")
        inputs.append(InputMapping(port, source, _quantity(path, where + ".quantity", spec.get("quantity"))))
    outputs = []
    for port, where, spec in entries("outputs", "a table with key 'quantity' and optional 'node'", {"node", "quantity"}):
        node_id = known(spec.get("node", modeled[0]), where + ".node")
        outputs.append(OutputMapping(port, node_id, _quantity(path, where + ".quantity", spec.get("quantity"))))
    parameters = []
    expected = "a table with key 'node' and optional 'unit_node'"
    for name, where, spec in entries("parameters", expected, {"node", "unit_node"}):
        node_id = known(spec.get("node"), where + ".node")
        unit_node = spec.get("unit_node")
        if unit_node is not None:
            known(unit_node, where + ".unit_node")
        parameters.append(ParameterMapping(name, node_id, unit_node))

    splice = None
    if "splice" in data:
        expected = "a table with 'node', 'input' or 'output', and optional 'host_models'"
        spec = _table(path, "splice", data["splice"], expected)
        _only_keys(path, "splice", spec, _SPLICE_KEYS)
        sides = [side for side in ("input", "output") if side in spec]
        if len(sides) != 1 or kind != "effect":
            raise signature_error(path, "splice", "an effect's splice names node and one of 'input' or 'output'")
        side = sides[0]
        host_models = _array(path, "splice.host_models", spec.get("host_models", []), "an array of 'module:Class' names")
        readings_unchanged = spec.get("readings_unchanged", False)
        if not isinstance(readings_unchanged, bool) or (readings_unchanged and side != "input"):
            raise signature_error(path, "splice.readings_unchanged", "true or false, and true only on an input splice")
        splice = EffectSplice(
            node=known(spec.get("node"), "splice.node"), port=_text(path, f"splice.{side}", spec[side]), side=side,
            host_models=tuple(_model_name(path, f"splice.host_models[{i}]", m) for i, m in enumerate(host_models)),
            readings_unchanged=readings_unchanged,
        )
    elif kind == "effect":
        raise signature_error(path, "splice", "an effect must say where it enters the model ([splice])")

    model = data.get("model")
    fmu = data.get("fmu")
    if (model is None) == (fmu is None):
        raise signature_error(path, "model", "give exactly one of 'model' (module:Class) or 'fmu' (file)")
    if model is not None:
        _model_name(path, "model", model)
    fmu_path = None
    if fmu is not None:
        fmu = _text(path, "fmu", fmu)
        fmu_path = Path(fmu) if Path(fmu).is_absolute() or path is None else path.parent / fmu

    complexity = data.get("complexity", 1)
    if not isinstance(complexity, int) or isinstance(complexity, bool):
        raise signature_error(path, "complexity", "must be an integer")
    can_appear = data.get("can_appear", True)
    if not isinstance(can_appear, bool) or ("can_appear" in data and kind != "effect"):
        raise signature_error(path, "can_appear", "effects only, true or false")
    holds_values = data.get("holds_values", False)
    if not isinstance(holds_values, bool) or ("holds_values" in data and kind != "component"):
        raise signature_error(path, "holds_values", "components only, true or false")
    steps = data.get("steps", False)
    if not isinstance(steps, bool) or ("steps" in data and kind != "component"):
        raise signature_error(path, "steps", "components only, true or false")
    yields_to = _array(path, "yields_to", data.get("yields_to", []), "an array of effect ids")
    if yields_to and kind != "effect":
        raise signature_error(path, "yields_to", "effects only")
    for i, other in enumerate(yields_to):
        if not isinstance(other, str) or not other.isidentifier() or other == sig_id:
            raise signature_error(path, f"yields_to[{i}]", f"{other!r} must be another effect's id")
    extra = _table(path, "extra", data.get("extra", {}), "a table")
    if kind == "component" and (loose := _loose_triples(modeled[0], triples)):
        raise signature_error(path, "triples", f"{', '.join(loose)} not joined to the modelled node {modeled[0]!r} by "
                              "required triples (a pattern in pieces matches every combination of its pieces)")
    return Signature(
        id=sig_id, label=label, kind=kind, nodes=nodes,
        triples=tuple(triples), modeled_nodes=modeled, inputs=tuple(inputs), outputs=tuple(outputs),
        parameters=tuple(parameters), model=model, fmu=fmu_path, complexity=complexity,
        comment=comment, splice=splice, source_file=path,
        extra=dict(extra), can_appear=can_appear, holds_values=holds_values, steps=steps,
        yields_to=tuple(yields_to), note=note,
    )


def required_outward(anchor: str, triples: Sequence[PatternTriple]) -> list[PatternTriple]:
    """The required triples that required triples join to node ``anchor``, in the order a walk
    outward from it takes them (each touches a node one before it reached)."""
    required = [t for t in triples if not t.is_optional]
    reached, ordered = {anchor}, []
    while step := next((t for t in required if t not in ordered and {t.subject, t.object} & reached), None):
        ordered.append(step)
        reached |= {step.subject, step.object}
    return ordered


def _loose_triples(anchor: str, triples: list[PatternTriple]) -> list[str]:
    """The keys (``triples[i]``) of the required triples that required triples do not join to node
    ``anchor``."""
    joined = required_outward(anchor, triples)
    return [f"triples[{i}]" for i, t in enumerate(triples) if not t.is_optional and t not in joined]


def read_signature(path: Path) -> Signature:
    """Read and validate one signature file (its content; not the classes it names).

    :raises SignatureError: on TOML syntax errors (with line and column) or invalid content.
    """
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise SignatureError(f"{path}: {exc}") from None
    return signature_from_dict(data, path)
