"""The typed requests of graphtwin's work, one per kind, from the HTTP body or the CLI's options to
the code that runs it: checked when made (model names, windows ``START/END``, operating conditions)."""

from __future__ import annotations

from typing import Literal, TypeVar

import pyoxigraph as ox
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from service.calibration.model_data import DEFAULT_GP_INPUTS
from service.data.operating_filter import parse_condition
from service.data.windows import parse_window
from service.errors import InputError
from service.graph.store import GraphStore

__all__ = [
    "JobRequest", "ModelRequest", "FitRequest", "AssembleRequest", "CalibrateRequest", "DiagnoseRequest",
    "AddEffectRequest", "checked_request",
]


class JobRequest(BaseModel):
    """Any request: unknown fields are refused (a misspelt ``start-from`` is an error, not ignored)."""

    model_config = ConfigDict(extra="forbid")

    def graphs_read(self, store: GraphStore) -> list[ox.NamedNode]:
        """The graphs of ``store`` the work reads: what is shipped where it runs away from the store."""
        return []

    def uploads(self) -> tuple[str, ...]:
        """The measurement uploads the work reads, by id."""
        return ()


class ModelRequest(JobRequest):
    """Work on one model of the store."""

    model: str = Field(description="model name in the store")

    @field_validator("model")
    @classmethod
    def _model_name(cls, value: str) -> str:
        return GraphStore.check_name(value)

    def graphs_read(self, store: GraphStore) -> list[ox.NamedNode]:
        return store.matching_dataset(self.model)


def _check_window(value: str | None) -> str | None:
    if value is not None:
        parse_window(value)
    return value


_ONLY_WHEN = ("operating conditions COLUMN OP NUMBER in the column's unit, e.g. 'SF Spd Cmd (%) > 5': the "
              "targets are compared only where all hold (docs/data.md: operating filter)")


def _check_conditions(value: list[str]) -> list[str]:
    for condition in value:
        parse_condition(condition)
    return value


class AssembleRequest(ModelRequest):
    pass


class FitRequest(ModelRequest):
    """What calibrate and diagnose share: the data, the seed, the operating filter, the start."""

    measurements: str = Field(description="the measurements: a measurement upload's id (the CLI: the CSV's path)")
    seed: int = Field(default=0, ge=0, le=2**32 - 1, description="random seed (numpy: 0 … 2³² − 1)")
    only_when: list[str] = Field(default=[], description=_ONLY_WHEN)
    start_from: str | None = Field(default=None, description=(
        "a model in the store whose latest calibrated parameters start the fit (the version before an added "
        "effect, say); the others start at their defaults"))

    _conditions = field_validator("only_when")(_check_conditions)

    @field_validator("start_from")
    @classmethod
    def _start_model_name(cls, value: str | None) -> str | None:
        return GraphStore.check_name(value) if value is not None else None

    def graphs_read(self, store: GraphStore) -> list[ox.NamedNode]:
        """The model's, and the model the fit starts from with its assembly and calibration runs (the
        values it starts from)."""
        graphs = super().graphs_read(store)
        if self.start_from and store.has_model(self.start_from):
            graphs += [*store.matching_dataset(self.start_from), store.assembly_graph(self.start_from)]
            graphs += [row["g"] for row in store.run_named_query("calibration-run-graphs", model=self.start_from)]
        return graphs

    def uploads(self) -> tuple[str, ...]:
        return (self.measurements,)


class CalibrateRequest(FitRequest):
    train: str = Field(default="/", description="training window START/END (ISO; either side may be empty)")
    test: str | None = Field(default=None, description="test window START/END")
    method: Literal["point", "bayes"] = "point"
    gp_inputs: list[str] | None = Field(default=None, min_length=1, description=(
        f"inputs of the discrepancy GP, method bayes only (default {list(DEFAULT_GP_INPUTS)}): 'time' and boundary "
        "inputs by node IRI, local name or CSV column"))
    max_steps: int | None = Field(default=None, ge=200, le=200_000, description=(
        "the sampler's step limit, method bayes only (default 4000): a run that has not converged by then "
        "stops and says so"))

    _windows = field_validator("train", "test")(_check_window)

    @model_validator(mode="after")
    def _sampling_only(self) -> CalibrateRequest:
        if self.method == "point" and self.max_steps is not None:
            raise ValueError("max_steps limits the sampler of a Bayesian calibration (method bayes); a point "
                             "calibration has none")
        return self


class DiagnoseRequest(FitRequest):
    train: str = Field(description="training window START/END")
    test: str = Field(description="test window START/END")

    _windows = field_validator("train", "test")(_check_window)


class AddEffectRequest(ModelRequest):
    effect: str = Field(description="effect signature id, e.g. FanMotorHeat")
    target: str = Field(description="IRI of the building node the effect applies to")
    version: str | None = Field(default=None, description="name of the new model version (default "
                                "<model>+<effect>); an existing version with other effects is not overwritten (409)")

    @field_validator("version")
    @classmethod
    def _version_name(cls, value: str | None) -> str | None:
        return value if value is None else GraphStore.check_name(value)

    @property
    def version_name(self) -> str:
        """The version this request writes: ``version``, by default ``<model>+<effect>``."""
        return self.version or f"{self.model}+{self.effect}"

    def graphs_read(self, store: GraphStore) -> list[ox.NamedNode]:
        """The model's, and the version's where it exists (which effects it records decides whether
        the work may write it)."""
        graphs = super().graphs_read(store)
        if store.has_model(self.version_name):
            graphs += store.matching_dataset(self.version_name)
        return graphs


R = TypeVar("R", bound=JobRequest)


def checked_request(request_type: type[R], **fields) -> R:
    """A request made from the CLI's options.

    :raises InputError: the first invalid field, in the words of its check (a window's, a condition's).
    """
    try:
        return request_type(**fields)
    except ValidationError as exc:
        error = exc.errors()[0]
        cause = error.get("ctx", {}).get("error")
        raise InputError(str(cause) if isinstance(cause, Exception) else
                         f"{'.'.join(map(str, error['loc']))}: {error['msg']}") from None
