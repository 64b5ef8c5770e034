"""The modules of the package import one another without a cycle when they run (deferred
imports included, imports for type checking only left out), each subpackage imports only
from its own layer and those below it, and the data classes depend on no layout."""

import ast
import subprocess
import sys
from pathlib import Path

import irtps

PACKAGE = Path(irtps.__file__).parent
#: Every module of the package by its dotted path below ``irtps`` ("io.dataset", "errors"),
#: the package's own ``__init__`` (the public API, which imports from all) left out.
MODULES = {
    ".".join(path.relative_to(PACKAGE).with_suffix("").parts).removesuffix(".__init__")
    for path in PACKAGE.rglob("*.py")
    if path != PACKAGE / "__init__.py"
}
#: The subpackages (and top-level modules) from the bottom up, as in the module map (docs/architecture.md): a
#: module imports only from its own subpackage and those of lower layers. A layer of more than
#: one is of peers that import none of each other.
LAYERS = [
    ["errors"],
    ["_shared"],
    ["model"],
    ["ps"],
    ["geometry"],
    ["io"],
    ["render"],
    ["irt"],
    ["evaluate"],
    ["report", "batch"],
    ["calibrate"],
    ["cli"],
]


def _file(module: str) -> Path:
    path = PACKAGE.joinpath(*module.split("."))
    return path / "__init__.py" if path.is_dir() else path.with_suffix(".py")


def _run_time_nodes(node: ast.AST):
    """`node` and all below it, but for the blocks of ``if TYPE_CHECKING:`` (types only)."""
    yield node
    for child in ast.iter_child_nodes(node):
        if not (isinstance(child, ast.If) and isinstance(child.test, ast.Name) and child.test.id == "TYPE_CHECKING"):
            yield from _run_time_nodes(child)


def _imports(module: str) -> set[str]:
    """The package's modules that `module` imports when it runs, anywhere in its file."""
    found = set()
    for node in _run_time_nodes(ast.parse(_file(module).read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            if node.module == "irtps" or node.module.startswith("irtps."):
                base = node.module.removeprefix("irtps").removeprefix(".")
                found.add(base)
                found |= {f"{base}.{alias.name}".lstrip(".") for alias in node.names}
        elif isinstance(node, ast.Import):
            found |= {alias.name.removeprefix("irtps.") for alias in node.names if alias.name.startswith("irtps.")}
    return found & MODULES - {module}


def _layer(module: str) -> int:
    top = module.split(".")[0]
    return next(number for number, layer in enumerate(LAYERS) if top in layer)


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


def test_the_modules_are_found():
    assert {"errors", "io.dataset", "ps.fit", "cli.main", "_shared.checks"} <= MODULES
    assert _imports("io.dataset") >= {"io.diligent", "model.data"}, "the layout dispatch reads both layouts"


def test_no_import_cycle():
    graph = {module: _imports(module) for module in MODULES}
    assert _cycle(graph) is None


def test_the_cycle_check_sees_a_cycle():
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]


def test_every_module_is_in_a_layer():
    assert {module.split(".")[0] for module in MODULES} == {top for layer in LAYERS for top in layer}


def test_no_import_from_a_higher_layer():
    upward = {
        (module, other)
        for module in MODULES
        for other in _imports(module)
        if module.split(".")[0] != other.split(".")[0] and _layer(other) >= _layer(module)
    }
    assert not upward, sorted(upward)


def test_the_subpackages_import_nothing():
    """A subpackage's ``__init__`` re-exports nothing: importing one imports no other."""
    for path in PACKAGE.glob("*/__init__.py"):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        assert not [node for node in ast.walk(tree) if isinstance(node, (ast.Import, ast.ImportFrom))], path


def test_the_data_classes_depend_on_no_layout():
    assert _imports("model.data") <= {"errors", "model", "model.scene"}
    assert not {"io.dataset", "io.dataset_files", "io.dataset_writer"} & _imports("io.diligent")


#: Libraries that only some commands use, each tens of MiB at every start: `import irtps` and
#: the command's own modules import them when a function needs them (drawing, circle
#: detection, a cluster, camera RAW), not before.
DEFERRED_LIBRARIES = ("matplotlib", "skimage", "distributed", "dask", "rawpy")


def test_heavy_libraries_wait_until_a_command_needs_them():
    listing = "import sys, irtps, irtps.cli.main; print(' '.join(sorted({m.split('.')[0] for m in sys.modules})))"
    loaded = subprocess.run([sys.executable, "-c", listing], capture_output=True, text=True, check=True).stdout.split()
    assert "irtps" in loaded and "numpy" in loaded
    assert [library for library in DEFERRED_LIBRARIES if library in loaded] == []
