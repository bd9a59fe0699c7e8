"""One router per resource: models (and their measurements), SPARQL (and named queries), jobs, reports."""
