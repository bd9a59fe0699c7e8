"""Configuration of the HTTP service and its jobs, from keyword arguments or ``GRAPHTWIN_*``
environment variables (each variable: ``docs/http.md``, Settings). Secrets are
:class:`~pydantic.SecretStr`: ``repr``, logs and tracebacks show ``**********``.
"""

from __future__ import annotations

from pathlib import Path
from urllib.parse import urlsplit

from pydantic import Field, SecretStr, ValidationError, field_validator, model_validator
from pydantic_settings import BaseSettings, SettingsConfigDict

from service.errors import InputError

__all__ = ["Settings", "check_executor", "load_settings"]


def check_executor(spec: str) -> str:
    """``spec`` if it names an executor: ``threads``, ``processes`` or ``dask://HOST:PORT``.

    :raises ValueError: naming the accepted forms.
    """
    if spec in ("threads", "processes"):
        return spec
    parts = urlsplit(spec)
    try:
        port = parts.port
    except ValueError:
        port = None
    if parts.scheme != "dask" or not parts.hostname or port is None or parts.path not in ("", "/"):
        raise ValueError(f"executor {spec!r}: give threads, processes or dask://HOST:PORT (the Dask scheduler)")
    return spec


class Settings(BaseSettings):
    """Everything :func:`service.http.app.create_app` needs (the variables: ``docs/http.md``)."""

    model_config = SettingsConfigDict(env_prefix="GRAPHTWIN_", extra="forbid", hide_input_in_errors=True)

    data_dir: Path = Path("graphtwin-service")
    store_dir: Path | None = None
    sparql_endpoint: str | None = None
    endpoint_token: SecretStr | None = None
    token: SecretStr | None = None
    open_reads: bool = True
    max_upload_bytes: int = Field(default=50 * 1024 * 1024, gt=0)
    max_query_bytes: int = Field(default=1024 * 1024, gt=0)
    max_request_bytes: int = Field(default=64 * 1024, gt=0)
    query_timeout_s: float = Field(default=30.0, gt=0)
    max_result_rows: int = Field(default=100_000, gt=0)
    query_workers: int = Field(default=2, ge=1, le=32)
    query_queue: int = Field(default=4, ge=0, le=1000)
    max_queries_per_client: int = Field(default=2, ge=1)
    executor: str = "processes"
    job_workers: int = Field(default=1, ge=1, le=64)
    brick_ontology: Path | None = None

    @field_validator("token", "endpoint_token")
    @classmethod
    def _no_blank_token(cls, value: SecretStr | None) -> SecretStr | None:
        if value is not None and len(value.get_secret_value().strip()) < 8:
            raise ValueError("a token needs at least 8 non-blank characters (unset it to refuse every write)")
        return value

    @field_validator("sparql_endpoint")
    @classmethod
    def _http_url(cls, value: str | None) -> str | None:
        if value is not None and not value.startswith(("http://", "https://")):
            raise ValueError(f"sparql_endpoint {value!r}: give an http(s):// URL")
        return value

    @field_validator("executor")
    @classmethod
    def _known_executor(cls, value: str) -> str:
        return check_executor(value)

    @model_validator(mode="after")
    def _workers_fit_the_executor(self) -> Settings:
        if self.job_workers > 2 and not self.executor.startswith("dask://"):
            raise ValueError(f"job_workers={self.job_workers}: at most 2 with the {self.executor} executor "
                             "(jobs share this machine); more need a Dask cluster (executor dask://HOST:PORT)")
        return self

    @property
    def store_path(self) -> Path:
        """The embedded store's folder."""
        return self.store_dir if self.store_dir is not None else self.data_dir / "store"

    @property
    def jobs_dir(self) -> Path:
        return self.data_dir / "jobs"

    @property
    def measurements_dir(self) -> Path:
        return self.data_dir / "measurements"


def load_settings(options: dict[str, str] | None = None, **values) -> Settings:
    """:class:`Settings` from the ``GRAPHTWIN_*`` variables and ``values`` (field → value);
    ``options``: field → the command-line option that gave it, for the message.

    :raises InputError: naming each variable (or option) and its problem.
    """
    try:
        return Settings(**values)
    except ValidationError as exc:
        problems = []
        for error in exc.errors():
            field = str(error["loc"][0]) if error["loc"] else ""
            variable = f"GRAPHTWIN_{field.upper()}" if field else "the settings"
            where = f"{options[field]} ({variable})" if options and field in options else variable
            problems.append(f"{where}: {error['msg'].removeprefix('Value error, ')}")
        raise InputError("; ".join(problems)) from None
