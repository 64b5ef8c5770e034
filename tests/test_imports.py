"""The modules of the package import one another without a cycle when they run (deferred
imports included, imports for type checking only left out), and the data classes depend on
no layout."""

import ast
from pathlib import Path

import irtps

PACKAGE = Path(irtps.__file__).parent
MODULES = {path.stem for path in PACKAGE.glob("*.py") if path.stem != "__init__"}


def _run_time_nodes(node: ast.AST):
    """`node` and all below it, but for the blocks of ``if TYPE_CHECKING:`` (types only)."""
    yield node
    for child in ast.iter_child_nodes(node):
        if not (isinstance(child, ast.If) and isinstance(child.test, ast.Name) and child.test.id == "TYPE_CHECKING"):
            yield from _run_time_nodes(child)


def _imports(module: str) -> set[str]:
    """The package's modules that `module` imports when it runs, anywhere in its file."""
    found = set()
    for node in _run_time_nodes(ast.parse((PACKAGE / f"{module}.py").read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom) and node.module == "irtps":
            found |= {alias.name for alias in node.names if alias.name in MODULES}
        elif isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("irtps."):
            found.add(node.module.split(".")[1])
        elif isinstance(node, ast.Import):
            found |= {alias.name.split(".")[1] for alias in node.names if alias.name.startswith("irtps.")}
    return found & MODULES - {module}


def _cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """A cycle of `graph`, as the modules along it, or None."""
    state: dict[str, str] = {}
    path: list[str] = []

    def visit(module: str) -> list[str] | None:
        state[module] = "open"
        path.append(module)
        for other in sorted(graph[module]):
            if state.get(other) == "open":
                return path[path.index(other) :] + [other]
            if other not in state and (found := visit(other)):
                return found
        state[module] = "done"
        path.pop()
        return None

    for module in sorted(graph):
        if module not in state and (found := visit(module)):
            return found
    return None


def test_no_import_cycle():
    graph = {module: _imports(module) for module in MODULES}
    assert graph["dataset"] >= {"diligent", "data"}, "the layout dispatch reads both layouts"
    assert _cycle(graph) is None


def test_the_data_classes_depend_on_no_layout():
    assert _imports("data") <= {"errors", "scene"}
    assert "dataset" not in _imports("diligent")
