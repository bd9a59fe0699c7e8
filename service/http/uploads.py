"""Measurement uploads: CSVs validated against a model's assembled model (every problem at once),
kept as ``<root>/<model>/<id>.csv`` with ``<id>.json`` describing them."""

from __future__ import annotations

import hashlib
import json
import os
import re
import tempfile
import uuid
from pathlib import Path

import numpy as np

from service.data.model_series import read_model_data
from service.errors import AssemblyError, IncompleteModelError, InputError, MeasurementError, NotFoundError
from service.graph.store import GraphStore
from service.model.assembly import assemble

__all__ = ["MeasurementUploads"]

_UPLOAD_ID = re.compile(r"^[0-9a-f]{16}$")
_TEMPORARY_PREFIX = ".upload-"  # an upload being validated, renamed to <id>.csv when kept


class MeasurementUploads:
    """Validated measurement CSVs: ``<root>/<model>/<id>.csv`` with ``<id>.json`` describing them."""

    def __init__(self, root: Path):
        """:param root: the uploads' folder (created if missing); a half-written upload a stopped
            service left there is removed."""
        self.root = Path(root)
        self.root.mkdir(parents=True, exist_ok=True)
        for leftover in self.root.glob(f"*/{_TEMPORARY_PREFIX}*"):
            leftover.unlink(missing_ok=True)

    def save(self, store: GraphStore, model_name: str, data: bytes, *, allow_gaps: bool = False) -> dict:
        """Validate ``data`` against ``model_name``'s assembled model and keep it; the same bytes
        uploaded again for the model keep their first id (``"new": false``, the description
        refreshed against the model as it is now).

        :raises MeasurementError: every problem of the file (nothing is kept then).
        :raises AssemblyError: the model does not assemble.
        """
        try:
            model = assemble(store, model_name)
        except IncompleteModelError as exc:
            raise IncompleteModelError(exc.problems, headline=f"model {model_name} does not assemble",
                                       notes=exc.notes) from None
        except AssemblyError as exc:
            raise AssemblyError(f"model {model_name} does not assemble: {exc}") from None
        folder = self.root / model_name
        folder.mkdir(parents=True, exist_ok=True)
        digest = hashlib.sha256(data).hexdigest()
        earlier = next((info["id"] for info in self.list(model_name) if self._digest(folder, info) == digest), None)
        upload_id = earlier or uuid.uuid4().hex[:16]
        handle, temporary = tempfile.mkstemp(dir=folder, prefix=_TEMPORARY_PREFIX, suffix=".csv")
        try:
            with os.fdopen(handle, "wb") as out:
                out.write(data)
            try:
                measured = read_model_data(model, temporary)
            except MeasurementError as exc:
                raise MeasurementError(f"the measurements do not fit model {model_name}", exc.problems) from None
            if not allow_gaps:
                self._refuse_gaps(measured, model_name)
            info = {
                "id": upload_id, "model": model_name, "rows": measured.n_steps,
                # as a window takes them back: ISO, with Z where the file's stamps carried offsets (read as UTC)
                **{key: np.datetime_as_string(measured.timestamps[i], unit="s") + ("Z" if measured.utc else "")
                   for key, i in (("start", 0), ("end", -1))},
                "step_s": measured.step_s, "columns": dict(measured.columns), "warnings": list(measured.warnings),
                "sha256": digest,
            }
            (folder / f"{upload_id}.json").write_text(json.dumps(info, indent=1), encoding="utf-8")
            os.replace(temporary, folder / f"{upload_id}.csv")
        except BaseException:
            Path(temporary).unlink(missing_ok=True)
            if earlier is None:
                (folder / f"{upload_id}.json").unlink(missing_ok=True)
            raise
        return info | {"new": earlier is None}

    @staticmethod
    def _digest(folder: Path, info: dict) -> str:
        """An upload's SHA-256, from its description (or its file, for uploads described before it was kept)."""
        return info.get("sha256") or hashlib.sha256((folder / f"{info['id']}.csv").read_bytes()).hexdigest()

    @staticmethod
    def _refuse_gaps(measured, model_name: str) -> None:
        problems = []
        for node, series in measured.series.items():
            missing = np.flatnonzero(np.isnan(series))
            if missing.size:
                problems.append(
                    f"column {measured.columns[node]!r}: {missing.size} step(s) without a value that no short gap "
                    f"interpolation fills (first at {measured.timestamps[missing[0]]}); fill them, or upload with "
                    "allow_gaps=true to leave those steps out of the calibration"
                )
        if problems:
            raise MeasurementError(f"the measurements do not fit model {model_name}", problems)

    def list(self, model_name: str) -> list[dict]:
        folder = self.root / model_name
        if not folder.is_dir():
            return []
        return [json.loads(p.read_text(encoding="utf-8")) for p in sorted(folder.glob("*.json"))
                if (folder / f"{p.stem}.csv").is_file()]

    def require(self, model_name: str, upload_id: str) -> Path:
        """The CSV of upload ``upload_id`` of model ``model_name``.

        :raises NotFoundError: no such upload of that model (or no name a model or an upload can have).
        """
        missing = NotFoundError(f"no measurement upload {upload_id!r} of model {model_name}")
        try:
            folder = self.root / GraphStore.check_name(model_name)
        except InputError:  # no name a model can have
            raise missing from None
        if not _UPLOAD_ID.match(upload_id or "") or not (folder / f"{upload_id}.csv").is_file():
            raise missing
        return folder / f"{upload_id}.csv"

    def delete(self, model_name: str, upload_id: str) -> None:
        """Remove upload ``upload_id`` of model ``model_name``.

        :raises NotFoundError: no such upload of that model.
        """
        csv = self.require(model_name, upload_id)
        csv.with_suffix(".json").unlink(missing_ok=True)  # the description first: list() then skips it
        csv.unlink()

    def locate(self, upload_id: str) -> Path:
        """The CSV of upload ``upload_id`` (under whichever model it was validated against).

        :raises NotFoundError: no such upload.
        """
        if _UPLOAD_ID.match(upload_id or ""):
            found = sorted(self.root.glob(f"*/{upload_id}.csv"))
            if found:
                return found[0]
        raise NotFoundError(f"no measurement upload {upload_id!r}")
