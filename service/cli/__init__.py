"""The ``graphtwin`` command line: the same work as the HTTP service, run locally (``graphtwin --help``)."""

from service.cli import model_commands, fit_commands, store_commands, demo  # noqa: F401, I001 (each registers its commands, in this order)
from service.cli.common import app

__all__ = ["app"]
