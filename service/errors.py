"""graphtwin's one error hierarchy: what a user gave or asked for that cannot be done.

Every message names the problem where it is (file, line, column, column name, IRI). The HTTP service
maps these classes to statuses in one handler (:mod:`service.http.errors`), the CLI to its exit code
and one-line message in one place (:mod:`service.cli.output`). Any other exception is a defect.
"""

from __future__ import annotations

from collections.abc import Sequence

__all__ = [
    "GraphtwinError", "InputError", "ModelLoadError", "SignatureError", "AssemblyError", "IncompleteModelError",
    "MeasurementError", "UnsupportedFormatError", "UnitError", "CalibrationError", "UnknownEffectError", "ResultTooLargeError",
    "NotFoundError", "ConflictError", "StoreError", "StoreInUseError", "StoreUnavailableError", "StoreUnreachableError",
    "QueryTimeoutError", "StoreRequestError",
]


def _rebuilt(cls: type, args: tuple, state: dict) -> GraphtwinError:
    """An error unpickled as it was sent: its message and attributes, without calling its
    constructor (whose arguments are not its message: ``IncompleteModelError(message)`` would list
    the message's characters as problems)."""
    error = cls.__new__(cls)
    Exception.__init__(error, *args)
    error.__dict__.update(state)
    return error


class GraphtwinError(Exception):
    """Base of every error a user can act on; the message says what is wrong and where. Pickles as
    it is (a job's error comes back from a worker process or a Dask worker)."""

    def __reduce__(self):
        own_constructor = any("__init__" in vars(c) for c in type(self).__mro__
                              if issubclass(c, GraphtwinError) and c is not GraphtwinError)
        if not own_constructor:  # built from its message alone: the usual way (OSError's subclasses need it)
            return super().__reduce__()
        return _rebuilt, (type(self), self.args, dict(self.__dict__))


class InputError(GraphtwinError, ValueError):
    """Input that cannot be used: a file's content, an option, a window, a parameter value."""


class ModelLoadError(InputError):
    """RDF that cannot be parsed: ``source``, ``line`` and ``column`` say where (1-based)."""

    def __init__(self, source: str, message: str, line: int | None = None, column: int | None = None):
        self.source, self.line, self.column = source, line, column
        where = f"{source}, line {line}, column {column}" if line is not None else source
        super().__init__(f"{where}: {message}")


class SignatureError(InputError):
    """A signature file is malformed; the message names the file and the offending key."""


class AssemblyError(InputError):
    """The building graph or the signature library cannot be assembled; the message says why."""


class IncompleteModelError(AssemblyError):
    """Nodes or inputs the assembly cannot model: ``problems`` lists one sentence each (a class no
    ontology declares, a missing connection) under ``headline``; ``notes`` what else the assembly
    found that may explain them (a misspelt property, an unknown unit)."""

    def __init__(self, problems: Sequence[str], *, headline: str = "the model is incomplete",
                 notes: Sequence[str] = ()):
        misspelt = [note for note in notes if "(did you mean " in note]  # the likeliest cause: listed first
        self.problems, self.headline = tuple(problems), headline
        self.notes = tuple(misspelt + [note for note in notes if note not in misspelt])
        cause = (f" (a misspelt term may be why: {len(misspelt)} in the notes below)"
                 if misspelt else "")
        also = "\nthe assembly also notes:\n  - " + "\n  - ".join(self.notes) if self.notes else ""
        super().__init__(f"{headline}{cause}:\n  - " + "\n  - ".join(self.problems) + also)


class MeasurementError(InputError):
    """Measured data that cannot be used; ``problems`` lists every one (column, line)."""

    def __init__(self, source: str, problems: Sequence[str]):
        self.source, self.problems = source, tuple(problems)
        shown = list(problems[:25]) + ([f"... and {len(problems) - 25} more"] if len(problems) > 25 else [])
        super().__init__(f"{source}:\n  - " + "\n  - ".join(shown))


class UnsupportedFormatError(InputError):
    """A data format graphtwin does not read or write (an RDF media type, a file suffix)."""


class UnitError(InputError):
    """An unknown unit, or two units of different dimensions."""


class CalibrationError(InputError):
    """A calibration, comparison or diagnosis that cannot run on this model and data: a window, an
    option, a simulation that gives no finite values."""


class UnknownEffectError(InputError):
    """An effect id the signature library does not hold; ``catalog`` lists the ids it does."""

    def __init__(self, effect: str, catalog: Sequence[str]):
        self.effect, self.catalog = effect, tuple(catalog)
        super().__init__(f"no effect {effect!r}; the catalog has {', '.join(self.catalog)}")


class MaintainedGraphError(InputError):
    """A write to a graph graphtwin maintains from its own files (the ontologies, the alignment
    rules, the signature library): every model's matching reads them."""


class ResultTooLargeError(InputError):
    """A query's answer has more rows or triples than the service's limit."""


class NotFoundError(GraphtwinError, LookupError):
    """No model, run, job, upload or query of that name."""


class ConflictError(GraphtwinError):
    """The request conflicts with what is stored: a name taken, a job in another state, a model
    changed while a job ran on it."""


class StoreError(GraphtwinError):
    """The graph store cannot serve the request."""


class StoreInUseError(StoreError, OSError):
    """The on-disk store is open already: in another process (another graphtwin command, a running
    ``graphtwin serve``) or, not closed yet, in this one."""


class StoreUnavailableError(StoreError, RuntimeError):
    """An external SPARQL endpoint answered with an error status other than 400, or with something
    that is not a SPARQL result; the message names the URL and the status. A ``RuntimeError`` as
    pyoxigraph raises for an update that fails as it runs (the endpoint's HTTP 500 for the same)."""


class StoreUnreachableError(StoreUnavailableError, ConnectionError):
    """No connection to the external endpoint, or no answer within the timeout; the message names the URL."""


class QueryTimeoutError(StoreError):
    """A read query ran past the service's time limit; the message says whether it was stopped."""


class StoreRequestError(StoreError, ValueError):
    """An external endpoint rejected a query or update as invalid (its HTTP 400); the message carries its text."""
