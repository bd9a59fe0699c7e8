"""The house keeps its floors (docs/architecture.md): every module of ``service/`` imports only its
own floor and the floors below it, no import cycle (imports inside functions count), no module over
500 lines, at most 8 Python files directly in ``service/``."""

import ast
from pathlib import Path

import pytest

SERVICE = Path(__file__).resolve().parents[1] / "service"

#: The floors along the data's way, bottom first (docs/architecture.md).
FLOORS = ("base", "graph", "matching", "components", "model", "data", "calibration", "diagnosis", "report",
          "workflows", "jobs", "http", "cli")
BASE_MODULES = {"service", "service.errors", "service.resources", "service.runtime", "service.settings"}
MAX_LINES, MAX_TOP_FILES = 500, 8


def _modules() -> dict[str, Path]:
    found = {}
    for path in SERVICE.rglob("*.py"):
        if "examples" in path.relative_to(SERVICE).parts:
            continue
        name = ".".join(path.relative_to(SERVICE.parent).with_suffix("").parts)
        found[name.removesuffix(".__init__")] = path
    return found


MODULES = _modules()


def _imports(name: str, path: Path, modules: dict[str, Path] = MODULES) -> set[str]:
    """The ``modules`` that ``name`` imports anywhere in its text (top level or inside a function,
    ``TYPE_CHECKING`` blocks included), each resolved to the module it names."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    targets = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")
                base = ".".join(parts[: len(parts) - node.level + 1] + ([base] if base else []))
            names = [f"{base}.{alias.name}" for alias in node.names] + [base]
        else:
            continue
        for target in names:
            while target and target not in modules:
                target = target.rpartition(".")[0]
            if target and target != name and not name.startswith(target + "."):
                targets.add(target)
    return targets


IMPORTS = {name: _imports(name, path) for name, path in MODULES.items()}


def floor_of(module: str) -> str:
    if module in BASE_MODULES:
        return "base"
    return module.split(".")[1]


def test_every_module_lives_on_a_known_floor():
    assert {floor_of(m) for m in MODULES} <= set(FLOORS), sorted({floor_of(m) for m in MODULES} - set(FLOORS))


@pytest.mark.parametrize("module", sorted(MODULES))
def test_a_module_imports_only_its_floor_and_the_floors_below(module):
    level = FLOORS.index(floor_of(module))
    above = sorted(t for t in IMPORTS[module] if FLOORS.index(floor_of(t)) > level)
    assert not above, f"{module} ({floor_of(module)}) imports floors above it: {above}"


def import_cycles(imports: dict[str, set[str]]) -> list[list[str]]:
    """Tarjan's strongly connected components of the import graph with two modules or more."""
    index, low, stack, on_stack, cycles = {}, {}, [], set(), []

    def visit(module: str) -> None:
        index[module] = low[module] = len(index)
        stack.append(module)
        on_stack.add(module)
        for target in imports[module]:
            if target not in index:
                visit(target)
                low[module] = min(low[module], low[target])
            elif target in on_stack:
                low[module] = min(low[module], index[target])
        if low[module] == index[module]:
            component = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                component.append(member)
                if member == module:
                    break
            if len(component) > 1:
                cycles.append(sorted(component))

    for module in imports:
        if module not in index:
            visit(module)
    return cycles


def test_no_import_cycle():
    assert import_cycles(IMPORTS) == []


def test_no_module_is_over_500_lines_and_the_top_of_service_holds_few_files():
    lines = {m: len(p.read_text(encoding="utf-8").splitlines()) for m, p in MODULES.items()}
    assert {m: n for m, n in lines.items() if n > MAX_LINES} == {}
    top = sorted(p.name for p in SERVICE.glob("*.py") if p.name != "__init__.py")
    assert len(top) <= MAX_TOP_FILES, top


def test_the_check_catches_a_cycle_inside_a_function_and_an_upward_import(tmp_path):
    """The rules bite: an import placed inside a function counts, a cycle through it is found, and
    the lower floor importing the higher one is named."""
    fake = {"service.graph.a": tmp_path / "a.py", "service.report.b": tmp_path / "b.py"}
    fake["service.graph.a"].write_text("def f():\n    from service.report.b import g\n")
    fake["service.report.b"].write_text("from service.graph.a import f\n")
    found = {name: _imports(name, path, fake) for name, path in fake.items()}
    assert found == {"service.graph.a": {"service.report.b"}, "service.report.b": {"service.graph.a"}}
    assert import_cycles(found) == [["service.graph.a", "service.report.b"]]
    assert FLOORS.index(floor_of("service.report.b")) > FLOORS.index(floor_of("service.graph.a"))
