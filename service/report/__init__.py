"""The report floor: the run report page, figures and the Brick report (``docs/report.md``)."""
