"""Where the project's declarative resources live: ``queries/``, ``ontologies/``, ``signatures/``.

They sit at the top of the repository (the layout is fixed), beside the ``service`` package. An
installation that moves the package away from them (a wheel, a container) points
``GRAPHTWIN_HOME`` at the folder that holds them.
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["project_home", "queries_dir", "ontologies_dir", "signatures_dir", "examples_dir"]


def project_home() -> Path:
    """The folder holding ``queries/``, ``ontologies/`` and ``signatures/``.

    :raises FileNotFoundError: when neither ``GRAPHTWIN_HOME`` nor the source checkout has them.
    """
    configured = os.environ.get("GRAPHTWIN_HOME")
    home = Path(configured) if configured else Path(__file__).resolve().parent.parent
    if not (home / "signatures").is_dir():
        raise FileNotFoundError(
            f"graphtwin resources not found under {home}: set GRAPHTWIN_HOME to the folder that "
            "holds queries/, ontologies/ and signatures/"
        )
    return home


def queries_dir() -> Path:
    return project_home() / "queries"


def ontologies_dir() -> Path:
    return project_home() / "ontologies"


def signatures_dir() -> Path:
    return project_home() / "signatures"


def examples_dir() -> Path:
    """Example building models, shipped inside the package."""
    return Path(__file__).resolve().parent / "examples"
