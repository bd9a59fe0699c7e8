"""The HTTP floor: the FastAPI service — the app, one router per resource, access, errors, schemas
(``docs/http.md``)."""
