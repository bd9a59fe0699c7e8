"""Request and response bodies of the HTTP API (pydantic models; they make the OpenAPI document).

Job requests are the workflows' own (:mod:`service.workflows.requests`).
"""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, Field

__all__ = [
    "ErrorBody", "Health", "ModelSummary", "ModelList", "ModelInfo", "ModelUploaded", "MeasurementsInfo",
    "MeasurementsList", "NamedQueryInfo", "NamedQueryList", "ProgressEntry", "JobPublic", "JobList",
]


class ErrorBody(BaseModel):
    """Every error: ``detail`` says what is wrong; the other fields when they apply."""

    detail: str
    problems: list[str] | None = Field(default=None, description="every problem found (measurements, assembly)")
    notes: list[str] | None = Field(default=None, description=(
        "what else the assembly found that may explain its problems (a misspelt property, an unknown unit)"))
    line: int | None = Field(default=None, description="1-based line of a syntax error in uploaded RDF")
    column: int | None = Field(default=None, description="1-based column of a syntax error in uploaded RDF")


class Health(BaseModel):
    status: Literal["ok"]
    backend: Literal["embedded", "remote"]
    executor: str = Field(description="where job work runs: threads, processes or dask://HOST:PORT")
    jobs_active: int


class ModelSummary(BaseModel):
    name: str
    graph: str = Field(description="IRI of the model's named graph")


class ModelList(BaseModel):
    data: list[ModelSummary]
    count: int


class ModelInfo(ModelSummary):
    triples: int
    inferred_triples: int = Field(description="what the alignment rules derived (the model's inferred graph)")
    assembled: bool = Field(description="an assembly graph exists (an assemble or calibrate job ran)")
    measurements: list[str] = Field(description="ids of the measurement uploads validated against this model")


class UnalignedClassPublic(BaseModel):
    class_iri: str
    count: int = Field(description="nodes of the model typed with the class")
    unaligned: int = Field(description="of them, those no alignment rule used")
    needed: str = Field(description="what would be needed for graphtwin to use them")


class UnreadRelationPublic(BaseModel):
    predicate: str
    count: int = Field(description="triples of the model with the predicate")
    needed: str


class AssumptionPublic(BaseModel):
    about: str = Field(description="the node the assumption is about")
    assumption: str = Field(description="what the alignment assumed")
    resolved_by: str = Field(description="the triple(s) that would remove the ambiguity")
    rule: str = Field(description="the alignment rule that assumed it")


class BrickReportPublic(BaseModel):
    model_name: str
    official_ontology: bool = Field(description=(
        "the service knows the official Brick classes (GRAPHTWIN_BRICK_ONTOLOGY): an unaligned class outside "
        "graphtwin's subset is then told apart as official Brick or not Brick at all"))
    unaligned_classes: list[UnalignedClassPublic]
    unread_relations: list[UnreadRelationPublic]
    assumptions: list[AssumptionPublic]
    points_without_column: list[str]
    points_without_unit: list[str]
    temperature_points_off_path: list[str]
    water_points_unread: list[str] = Field(description=(
        "water temperature points no model reads (a coil's leaving water; a unit's or plant's supply water)"))


class AssemblyCheck(BaseModel):
    """What assembling the uploaded model says, without writing anything (``POST /jobs/assemble``
    writes the assembly)."""

    complete: bool = Field(description="it assembles: every node of a component's class is in a component")
    problems: list[str] = Field(description="why it does not (one sentence a node or input), empty when it does")
    notes: list[str] = Field(description="the assembly's notes: choices it made, terms it did not know, units")


class ModelUploaded(ModelSummary):
    triples: int
    replaced: bool = Field(description="a model of this name existed and was replaced")
    changed: bool = Field(description=(
        "the store changed: false when it held this model already, triple for triple (its inferences, "
        "assembly and runs are kept as they were)"))
    assembly: AssemblyCheck


class MeasurementsInfo(BaseModel):
    """A validated measurement upload (``service.data.measurements``: the data contract)."""

    id: str
    model: str
    rows: int = Field(description="time steps after resampling to the regular step")
    start: str
    end: str
    step_s: float = Field(description="the regular time step, s")
    columns: dict[str, str] = Field(description="device IRI → CSV column")
    warnings: list[str]
    sha256: str | None = Field(default=None, description="the file's SHA-256 (absent for uploads kept before it was)")
    new: bool | None = Field(default=None, description="on upload: false when the same file was uploaded before for this "
                             "model, whose id is given back (200 instead of 201)")


class MeasurementsList(BaseModel):
    data: list[MeasurementsInfo]
    count: int


class NamedQueryInfo(BaseModel):
    name: str
    description: str
    variables: list[str] = Field(description="variables a query parameter of the same name binds")


class NamedQueryList(BaseModel):
    data: list[NamedQueryInfo]
    count: int


class ProgressEntry(BaseModel):
    time: str
    message: str


class JobPublic(BaseModel):
    """A job: ``status`` is queued, running, succeeded, failed, cancelled or interrupted."""

    id: str
    kind: str
    params: dict
    status: Literal["queued", "running", "succeeded", "failed", "cancelled", "interrupted"]
    created: str
    started: str | None
    finished: str | None
    progress: list[ProgressEntry]
    result: dict | None
    links: dict[str, str] = Field(description="this job, and what it wrote (graph IRIs, query URLs)")
    error: str | None
    cancel_requested: bool
    resubmitted_from: str | None


class JobList(BaseModel):
    data: list[JobPublic]
    count: int
