"""The diagnosis floor: where a calibrated model fails and which physical effect is missing (``docs/diagnosis.md``)."""
