"""graphtwin: semantic HVAC model in, calibrated simulation model and missing-physics diagnosis out."""

__version__ = "0.1.0"
__all__ = ["__version__"]
