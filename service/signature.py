"""Signature patterns: the declarative description of where a component model (or an effect) applies.

A signature is read from one TOML file in ``signatures/``. It names pattern nodes (local ids with
allowed classes, a fixed IRI, or a literal slot), pattern triples between them with a rule each,
the nodes the model represents, and the input / output / parameter mapping of the paper's Table 1
(Bjørnskov, Jradi & Wetter, "Automated model generation and parameter estimation of building energy
models using an ontology-based framework"). File format (every key documented in ``signatures/README.md``)::

    id = "Fan"
    label = "Fan, polynomial part-load power curve"
    kind = "component"                 # or "effect"
    model = "service.fan:Fan"          # Python class, "module:Class"; or fmu = "fan.fmu"
    complexity = 1                     # tie-break when several signatures claim the same node
    modeled_nodes = ["fan"]

    [nodes]
    fan = { classes = ["s4bldg:Fan"] }
    inlet = { classes = ["gt:TemperatureSensor", "s4bldg:Coil"] }
    nominal_flow_kind = { iri = "s4bldg:nominalAirFlowRate" }
    nominal_flow = { literal = true }
    nominal_flow_unit = { any = true }

    [[triples]]
    subject = "inlet"
    predicate = "fso:suppliesFluidTo"
    object = "fan"
    rule = "traverse"                  # "exact" (default), "traverse" or "optional"

    [inputs.inlet_air_temperature]     # the model's input port
    source = "inlet"                   # the pattern node whose model feeds it
    quantity = "temperature"           # which output of that node's model

    [outputs.outlet_air_temperature]   # the model's output port
    node = "fan"                       # located at this node's outlet (default: first modeled node)
    quantity = "temperature"

    [parameters.nominal_air_flow]      # the model's parameter
    node = "nominal_flow"              # mapped from this literal node's value
    unit_node = "nominal_flow_unit"    # optional: node bound to the value's QUDT unit IRI

Rules (the paper's Sec. 3.2): ``exact`` is one triple; ``optional`` triples may be absent from the
graph (connected optional triples form one OPTIONAL block); ``traverse`` follows the predicate from
subject to object through any number of intermediate nodes and stops at the *nearest* match: no
intermediate node is an instance of the searched-for end's allowed classes, the end the signature
does not model (see :mod:`service.sparql_compiler`; exact on recirculation loops).
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, field
from enum import Enum
from pathlib import Path
from typing import Any

from .namespaces import GTR, expand_curie

__all__ = [
    "Rule", "PatternNode", "PatternTriple", "InputMapping", "OutputMapping", "ParameterMapping",
    "EffectSplice", "Signature", "SignatureError", "load_signature", "load_signature_library",
    "signature_iri",
]


class SignatureError(ValueError):
    """A signature file is malformed; the message names the file and the offending key."""


class Rule(str, Enum):
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
    subject: str
    predicate: str
    object: str
    rule: Rule = Rule.EXACT
    optional: bool = False  # True for an optional traverse (rule TRAVERSE); OPTIONAL rule implies it

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
    """

    node: str
    port: str
    side: str  # "input" or "output"
    host_models: tuple[str, ...] = ()


@dataclass(frozen=True)
class Signature:
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

    @property
    def iri(self) -> str:
        return signature_iri(self.id)

    def node(self, node_id: str) -> PatternNode:
        return self.nodes[node_id]


def signature_iri(signature_id: str) -> str:
    return f"{GTR}signature/{signature_id}"


_TOP_KEYS = {
    "id", "label", "comment", "kind", "model", "fmu", "complexity", "modeled_nodes", "nodes",
    "triples", "inputs", "outputs", "parameters", "splice", "extra", "can_appear", "holds_values",
}


def _fail(path: Path | None, where: str, message: str) -> SignatureError:
    return SignatureError(f"{path or '<signature>'}: {where}: {message}")


def _curie(path: Path | None, where: str, text: Any) -> str:
    if not isinstance(text, str):
        raise _fail(path, where, f"expected a CURIE or IRI string, got {text!r}")
    try:
        return expand_curie(text)
    except ValueError as exc:
        raise _fail(path, where, str(exc)) from None


def signature_from_dict(data: dict[str, Any], path: Path | None = None) -> Signature:
    """Build and validate a :class:`Signature` from parsed TOML.

    :raises SignatureError: naming the file and key of the first problem found.
    """
    unknown = set(data) - _TOP_KEYS
    if unknown:
        raise _fail(path, "top level", f"unknown key(s) {sorted(unknown)}; allowed: {sorted(_TOP_KEYS)}")
    for key in ("id", "nodes", "modeled_nodes"):
        if key not in data:
            raise _fail(path, "top level", f"missing required key {key!r}")
    sig_id = data["id"]
    if not isinstance(sig_id, str) or not sig_id.isidentifier():
        raise _fail(path, "id", f"{sig_id!r} must be an identifier (letters, digits, underscores)")
    kind = data.get("kind", "component")
    if kind not in ("component", "effect"):
        raise _fail(path, "kind", f"{kind!r} must be 'component' or 'effect'")

    nodes: dict[str, PatternNode] = {}
    for node_id, spec in data["nodes"].items():
        where = f"nodes.{node_id}"
        if not node_id.isidentifier():
            raise _fail(path, where, "node ids must be identifiers")
        if not isinstance(spec, dict):
            raise _fail(path, where, "expected a table with 'classes', 'iri' or 'literal'")
        chosen = [k for k in ("classes", "iri", "literal", "any") if k in spec]
        if len(chosen) != 1 or set(spec) - {"classes", "iri", "literal", "any"}:
            raise _fail(path, where, "give exactly one of 'classes', 'iri', 'literal = true', 'any = true'")
        if "classes" in spec:
            classes = spec["classes"]
            if not isinstance(classes, list) or not classes:
                raise _fail(path, where + ".classes", "expected a non-empty list of classes")
            nodes[node_id] = PatternNode(node_id, classes=tuple(_curie(path, where, c) for c in classes))
        elif "iri" in spec:
            nodes[node_id] = PatternNode(node_id, iri=_curie(path, where + ".iri", spec["iri"]))
        else:
            flag = chosen[0]
            if spec[flag] is not True:
                raise _fail(path, f"{where}.{flag}", "must be true")
            nodes[node_id] = PatternNode(node_id, literal=flag == "literal", any=flag == "any")

    def known(node_id: Any, where: str) -> str:
        if node_id not in nodes:
            raise _fail(path, where, f"names node {node_id!r}, which is not in [nodes]")
        return node_id

    triples = []
    for i, spec in enumerate(data.get("triples", [])):
        where = f"triples[{i}]"
        rule_text = spec.get("rule", "exact")
        try:
            rule = Rule(str(rule_text).lower())
        except ValueError:
            raise _fail(path, where + ".rule", f"{rule_text!r} must be exact, traverse or optional") from None
        subject = known(spec.get("subject"), where + ".subject")
        obj = known(spec.get("object"), where + ".object")
        if nodes[subject].literal:
            raise _fail(path, where + ".subject", "a literal node cannot be a subject")
        if rule is Rule.TRAVERSE and (nodes[obj].literal or nodes[subject].iri or nodes[obj].iri):
            raise _fail(path, where, "traverse needs class-restricted nodes at both ends")
        predicate = _curie(path, where + ".predicate", spec.get("predicate"))
        optional = spec.get("optional", False)
        if not isinstance(optional, bool):
            raise _fail(path, where + ".optional", "must be true or false")
        unknown_keys = set(spec) - {"subject", "predicate", "object", "rule", "optional"}
        if unknown_keys:
            raise _fail(path, where, f"unknown key(s) {sorted(unknown_keys)}")
        triples.append(PatternTriple(subject, predicate, obj, rule, optional or rule is Rule.OPTIONAL))

    modeled = tuple(known(n, "modeled_nodes") for n in data["modeled_nodes"])
    if not modeled:
        raise _fail(path, "modeled_nodes", "a signature models at least one node")

    inputs = tuple(
        InputMapping(port, known(spec.get("source"), f"inputs.{port}.source"), _text(path, f"inputs.{port}.quantity", spec.get("quantity")))
        for port, spec in data.get("inputs", {}).items()
    )
    outputs = tuple(
        OutputMapping(port, known(spec.get("node", modeled[0]), f"outputs.{port}.node"), _text(path, f"outputs.{port}.quantity", spec.get("quantity")))
        for port, spec in data.get("outputs", {}).items()
    )
    parameters = []
    for name, spec in data.get("parameters", {}).items():
        node_id = known(spec.get("node"), f"parameters.{name}.node")
        unit_node = spec.get("unit_node")
        if unit_node is not None:
            known(unit_node, f"parameters.{name}.unit_node")
        parameters.append(ParameterMapping(name, node_id, unit_node))

    splice = None
    if "splice" in data:
        spec = data["splice"]
        side = "input" if "input" in spec else "output" if "output" in spec else None
        if side is None or kind != "effect":
            raise _fail(path, "splice", "an effect's splice names node and one of 'input' or 'output'")
        host_models = spec.get("host_models", [])
        if not isinstance(host_models, list) or not all(isinstance(m, str) and ":" in m for m in host_models):
            raise _fail(path, "splice.host_models", "expected a list of 'module:Class' names")
        splice = EffectSplice(known(spec.get("node"), "splice.node"), spec[side], side, tuple(host_models))
    elif kind == "effect":
        raise _fail(path, "splice", "an effect must say where it enters the model ([splice])")

    model = data.get("model")
    fmu = data.get("fmu")
    if (model is None) == (fmu is None):
        raise _fail(path, "model", "give exactly one of 'model' (module:Class) or 'fmu' (file)")
    if model is not None and ":" not in model:
        raise _fail(path, "model", f"{model!r} must read 'module:Class'")
    fmu_path = None
    if fmu is not None:
        fmu_path = Path(fmu) if Path(fmu).is_absolute() or path is None else path.parent / fmu

    complexity = data.get("complexity", 1)
    if not isinstance(complexity, int):
        raise _fail(path, "complexity", "must be an integer")
    can_appear = data.get("can_appear", True)
    if not isinstance(can_appear, bool) or ("can_appear" in data and kind != "effect"):
        raise _fail(path, "can_appear", "effects only, true or false")
    holds_values = data.get("holds_values", False)
    if not isinstance(holds_values, bool) or ("holds_values" in data and kind != "component"):
        raise _fail(path, "holds_values", "components only, true or false")
    return Signature(
        id=sig_id, label=str(data.get("label", sig_id)), kind=kind, nodes=nodes,
        triples=tuple(triples), modeled_nodes=modeled, inputs=inputs, outputs=outputs,
        parameters=tuple(parameters), model=model, fmu=fmu_path, complexity=complexity,
        comment=str(data.get("comment", "")), splice=splice, source_file=path,
        extra=dict(data.get("extra", {})), can_appear=can_appear, holds_values=holds_values,
    )


def _text(path: Path | None, where: str, value: Any) -> str:
    if not isinstance(value, str) or not value:
        raise _fail(path, where, "expected a non-empty string")
    return value


def load_signature(path: Path) -> Signature:
    """Read one signature file.

    :raises SignatureError: on TOML syntax errors (with line and column) or invalid content.
    """
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise SignatureError(f"{path}: {exc}") from None
    return signature_from_dict(data, path)


def load_signature_library(folder: Path) -> dict[str, Signature]:
    """Every ``*.toml`` signature under ``folder`` (recursively), keyed by id.

    :raises SignatureError: for an invalid file or two files with the same id.
    """
    library: dict[str, Signature] = {}
    for path in sorted(folder.rglob("*.toml")):
        sig = load_signature(path)
        if sig.id in library:
            raise SignatureError(f"{path}: id {sig.id!r} is already used by {library[sig.id].source_file}")
        library[sig.id] = sig
    return library
