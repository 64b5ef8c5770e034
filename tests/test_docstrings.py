"""The examples in the docstrings of every module of the package run and print what they say,
and docs that name the choices of an argument name those the code accepts."""

import ast
import doctest
import importlib
import pkgutil
from pathlib import Path

import pytest

import irtps
from irtps.geometry.integrate import METHODS, ROBUST_WEIGHTS, integrate_normals
from irtps.ps.fit import ROBUST_CHOICES, photometric_stereo

PACKAGE = Path(irtps.__file__).parent
MODULES = sorted(module.name for module in pkgutil.walk_packages(irtps.__path__, "irtps."))


def _has_examples(path: Path) -> bool:
    """Whether a docstring of the module at `path` holds a ``>>>`` example."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    nodes = [
        tree,
        *(node for node in ast.walk(tree) if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef))),
    ]
    return any(">>>" in (ast.get_docstring(node) or "") for node in nodes)


WITH_EXAMPLES = sorted(
    ".".join(("irtps", *path.relative_to(PACKAGE).with_suffix("").parts))
    for path in PACKAGE.rglob("*.py")
    if _has_examples(path)
)


def test_every_module_with_examples_is_collected():
    assert WITH_EXAMPLES, "no module with examples found: the package was not found"
    assert set(WITH_EXAMPLES) <= set(MODULES)


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples(name):
    result = doctest.testmod(importlib.import_module(name), optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    assert result.failed == 0
    assert (result.attempted > 0) == (name in WITH_EXAMPLES)


@pytest.mark.parametrize(
    ("function", "argument", "choices"),
    [
        (integrate_normals, "method", METHODS),
        (integrate_normals, "robust_weight", ROBUST_WEIGHTS),
        (photometric_stereo, "robust", ROBUST_CHOICES),
    ],
)
def test_documented_choices_are_the_code_s(function, argument, choices):
    documented = {"{" + ", ".join(f'"{choice}"' for choice in choices) + "}"}
    lines = [line.strip() for line in function.__doc__.splitlines() if line.strip().startswith(f"{argument} : ")]
    assert {line.removeprefix(f"{argument} : ") for line in lines} == documented
