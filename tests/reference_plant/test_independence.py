"""The reference plant shares no code with graphtwin: no module of it imports ``service`` (or a
``tests`` module outside the plant), and no module of ``service`` imports the tests or the plant."""

from __future__ import annotations

import ast
from pathlib import Path

PLANT = Path(__file__).resolve().parent
SERVICE = PLANT.parents[1] / "service"


def imported_modules(path: Path) -> list[tuple[str, int]]:
    """(module, relative level) of every import in ``path``, inside functions too."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), filename=str(path))):
        if isinstance(node, ast.Import):
            found += [(alias.name, 0) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            found.append((node.module or "", node.level))
    return found


def test_no_plant_module_imports_graphtwin_or_other_tests():
    modules = sorted(PLANT.glob("*.py"))
    assert len(modules) >= 6
    for path in modules:
        for module, level in imported_modules(path):
            top = module.split(".")[0]
            assert level <= 1, f"{path.name} imports from above the plant: {'.' * level}{module}"
            if level == 0:
                assert top != "service", f"{path.name} imports {module}"
                assert top != "tests" or module.startswith("tests.reference_plant"), f"{path.name} imports {module}"


def test_no_service_module_imports_the_tests_or_the_plant():
    modules = sorted(SERVICE.rglob("*.py"))
    assert len(modules) > 50
    for path in modules:
        for module, level in imported_modules(path):
            top = module.split(".")[0] if level == 0 else ""
            assert top not in ("tests", "reference_plant"), f"{path.relative_to(SERVICE)} imports {module}"
