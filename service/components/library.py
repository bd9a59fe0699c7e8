"""The signature library: every signature of ``signatures/`` bound to the component class it names.

:meth:`SignatureLibrary.load` reads each file (:func:`~service.matching.signature.read_signature`) and
checks it against its class: every input, output and parameter the file maps is one the class
declares, every input port of the class is mapped, and a splice's port is one every ``host_models``
class has. A folder is read again only when one of its files changed.
"""

from __future__ import annotations

import importlib
from functools import lru_cache
from pathlib import Path

from service.components.component import ComponentModel
from service.errors import SignatureError, UnknownEffectError
from service.matching.signature import Signature, read_signature, signature_error
from service.resources import signatures_dir

__all__ = ["SignatureLibrary", "load_signature", "check_model_names", "import_model_class", "load_model_class",
           "host_ports"]

#: Input ports the simulator feeds without a mapping: a measuring device's ``measured_value`` (its
#: measurement, replayed when it is a boundary input) and an effect's ``value_in`` (what the spliced port carries).
_FED_WITHOUT_MAPPING = {"component": ("measured_value",), "effect": ("value_in",)}


class SignatureLibrary(dict[str, Signature]):
    """Signatures by id: the components' and the effects' (the catalog the diagnosis ranks)."""

    @classmethod
    def load(cls, folder: Path | None = None) -> SignatureLibrary:
        """Every ``*.toml`` signature under ``folder`` (default ``signatures/``), recursively, each
        checked by :func:`load_signature`.

        :raises SignatureError: for an invalid file or two files with the same id.
        """
        folder = (folder or signatures_dir()).resolve()
        files = tuple((path, path.stat().st_mtime_ns, path.stat().st_size) for path in sorted(folder.rglob("*.toml")))
        return cls(_loaded(files))

    @property
    def effects(self) -> dict[str, Signature]:
        """The effect catalog: effect signatures by id."""
        return {key: signature for key, signature in self.items() if signature.kind == "effect"}

    def effect(self, effect_id: str) -> Signature:
        """The effect ``effect_id``.

        :raises UnknownEffectError: naming the catalog's effects.
        """
        signature = self.get(effect_id)
        if signature is None or signature.kind != "effect":
            raise UnknownEffectError(effect_id, sorted(self.effects))
        return signature


@lru_cache(maxsize=8)
def _loaded(files: tuple[tuple[Path, int, int], ...]) -> dict[str, Signature]:
    """The signatures of ``files`` (path, modification time, size: a changed file is read again)."""
    library: dict[str, Signature] = {}
    for path, _, _ in files:
        signature = load_signature(path)
        if signature.id in library:
            raise SignatureError(f"{path}: id {signature.id!r} is already used by {library[signature.id].source_file}")
        library[signature.id] = signature
    for signature in library.values():
        for i, other in enumerate(signature.yields_to):
            if other not in library or library[other].kind != "effect":
                known = ", ".join(sorted(k for k, s in library.items() if s.kind == "effect"))
                raise signature_error(signature.source_file, f"yields_to[{i}]",
                                      f"{other!r} is not an effect of the library; its effects: {known}")
    return library


def load_signature(path: Path) -> Signature:
    """Read one signature file and check it against the classes it names (:func:`check_model_names`;
    a signature with an ``fmu`` is checked where the FMU's class is built, :func:`load_model_class`).

    :raises SignatureError: invalid content, a model that cannot be imported, or a port or parameter
        name its class does not declare.
    """
    signature = read_signature(path)
    if signature.model is not None:
        check_model_names(signature, import_model_class(path, "model", signature.model))
    if signature.splice is not None:
        splice = signature.splice
        for i, host in enumerate(splice.host_models):
            host_class = import_model_class(path, f"splice.host_models[{i}]", host)
            _undeclared(path, f"splice.{splice.side}", model=host, what=f"{splice.side} port", name=splice.port,
                        declared=host_ports(signature, host_class))
    return signature


def host_ports(signature: Signature, model_class: type[ComponentModel]) -> tuple[str, ...]:
    """The ports of ``model_class`` on the side an effect ``signature`` splices (one must be its port)."""
    assert signature.splice is not None
    return model_class.input_names() if signature.splice.side == "input" else model_class.output_names()


def import_model_class(path: Path | None, where: str, name: str) -> type[ComponentModel]:
    """The :class:`~service.components.component.ComponentModel` subclass ``name`` (``module:Class``) names.

    :raises SignatureError: naming file ``path`` and key ``where`` when it cannot be imported or is
        no component model.
    """
    module_name, _, class_name = name.partition(":")
    try:
        model_class = getattr(importlib.import_module(module_name), class_name)
    except (ImportError, AttributeError) as exc:
        raise signature_error(path, where, f"model {name!r} cannot be imported: {exc}") from None
    if not (isinstance(model_class, type) and issubclass(model_class, ComponentModel)):
        raise signature_error(path, where, f"{name!r} is not a ComponentModel")
    return model_class


def _undeclared(path: Path | None, where: str, *, model: str, what: str, name: str, declared: tuple[str, ...]) -> None:
    """Refuses ``name`` unless it is one of the ``declared`` names of ``model``'s ``what`` (port, parameter)."""
    if name not in declared:
        raise signature_error(path, where, f"{model} has no {what} {name!r}; its {what}s: {', '.join(declared) or 'none'}")


def check_model_names(signature: Signature, model_class: type[ComponentModel]) -> None:
    """Every input, output and parameter ``signature`` maps is one ``model_class`` declares, and
    every input port of the class is mapped (but those the simulator feeds itself): an unmapped
    input would run on NaN.

    :raises SignatureError: naming the file, the key and the names the class declares.
    """
    path, model = signature.source_file, signature.model or str(signature.fmu)
    parameter_names = tuple(p.name for p in model_class.parameters)
    for mapping in signature.inputs:
        _undeclared(path, f"inputs.{mapping.port}", model=model, what="input port", name=mapping.port,
                    declared=model_class.input_names())
    for mapping in signature.outputs:
        _undeclared(path, f"outputs.{mapping.port}", model=model, what="output port", name=mapping.port,
                    declared=model_class.output_names())
    for parameter in signature.parameters:
        _undeclared(path, f"parameters.{parameter.name}", model=model, what="parameter", name=parameter.name,
                    declared=parameter_names)
    mapped = {mapping.port for mapping in signature.inputs} | set(_FED_WITHOUT_MAPPING.get(signature.kind, ()))
    unmapped = [name for name in model_class.input_names() if name not in mapped]
    if unmapped:
        raise signature_error(path, f"inputs.{unmapped[0]}", (
            f"{model} has input port(s) {', '.join(map(repr, unmapped))} the signature does not map: add "
            "[inputs.NAME] with its source node and quantity (an input left unfed would run on NaN)"))


_MODEL_CACHE: dict[str, type[ComponentModel]] = {}


def load_model_class(signature: Signature) -> type[ComponentModel]:
    """The model class a signature names (``"module:Class"``, imported once); an FMU signature gets
    the FMU wrapper class built for its file, checked against the ports and parameters it maps and
    their units.

    :raises SignatureError: the model cannot be imported, or the FMU lacks a mapped port or
        parameter, or declares a mapped port in another unit than the simulator passes.
    """
    if signature.fmu is not None:
        from service.components.fmu import check_port_units, fmu_model_class  # fmpy loads only for FMU signatures

        model_class = fmu_model_class(signature.fmu)
        check_model_names(signature, model_class)
        check_port_units(signature, model_class)
        return model_class
    assert signature.model is not None
    cached = _MODEL_CACHE.get(signature.model)
    if cached is None:
        cached = _MODEL_CACHE[signature.model] = import_model_class(signature.source_file, "model", signature.model)
    return cached
