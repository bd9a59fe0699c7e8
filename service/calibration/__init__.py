"""The calibration floor: calibration problems, point and Bayesian Kennedy–O'Hagan calibration,
metrics, operating regimes, successive calibration, runs and their triples (``docs/calibration.md``)."""
