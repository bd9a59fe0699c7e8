"""The data floor: measurement CSVs read against a model (units, gaps, warnings), time windows, the
operating filter, and synthetic data from a known truth (``docs/data.md``)."""
