"""The documentation site builds with warnings as errors, and holds every command, option and
public function of the package, generated from the code: the site's inventory
(``objects.inv``) is read back and compared with what the parser and the modules hold."""

import argparse
import importlib
import inspect
import pkgutil
from pathlib import Path

import irtps
import pytest
from irtps.cli.parser import build_parser
from sphinx.cmd import build as sphinx_build
from sphinx.util.inventory import InventoryFile

ROOT = Path(__file__).resolve().parents[1]
#: MyST's own calls of Sphinx's deprecated API, hundreds per build; they are not ours to fix.
pytestmark = pytest.mark.filterwarnings("ignore:.*Check CHANGES for Sphinx API modifications")


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("site")
    status = sphinx_build.build_main(["-q", "-W", "--keep-going", "-b", "html", str(ROOT / "docs"), str(out)])
    assert status == 0, "the site did not build without warnings (run: python -m sphinx -W -b html docs OUT)"
    return out


def _inventory(site: Path) -> dict[str, set[str]]:
    with open(site / "objects.inv", "rb") as stream:
        inventory = InventoryFile.load(stream, "", lambda base, uri: base + uri)
    data = inventory.data if hasattr(inventory, "data") else inventory
    return {kind: set(entries) for kind, entries in data.items()}


def command_options() -> set[str]:
    """``irtps-COMMAND.OPTION`` for every option string and positional argument of every command."""
    expected = set()
    for action in build_parser()._actions:
        if isinstance(action, argparse._SubParsersAction):
            for command, parser in action.choices.items():
                for argument in parser._actions:
                    names = argument.option_strings or [argument.dest]
                    expected |= {f"irtps-{command}.{name}" for name in names}
    return expected


def public_objects() -> set[str]:
    """The dotted names of every public function and class: those of ``irtps.__all__``, and of
    every module whose path has no part starting with an underscore (its ``__all__``, or the
    names it defines that do not start with one)."""
    expected = {f"irtps.{name}" for name in irtps.__all__ if not name.startswith("__")}
    for info in pkgutil.walk_packages(irtps.__path__, "irtps."):
        if any(part.startswith("_") for part in info.name.split(".")[1:]):
            continue
        module = importlib.import_module(info.name)
        names = getattr(module, "__all__", [name for name in vars(module) if not name.startswith("_")])
        for name in names:
            value = getattr(module, name)
            if (inspect.isfunction(value) or inspect.isclass(value)) and value.__module__ == module.__name__:
                expected.add(f"{module.__name__}.{name}")
    return expected


def test_every_command_and_option_is_in_the_site(site):
    expected = command_options()
    assert len({name.split(".")[0] for name in expected}) == len(irtps.cli.parser.COMMANDS)
    assert "irtps-reconstruct.--method" in expected and "irtps-calibrate.--matte-albedo" in expected
    assert expected - _inventory(site)["std:cmdoption"] == set()


def test_every_public_function_and_class_is_in_the_site(site):
    expected = public_objects()
    assert {"irtps.reconstruct", "irtps.report.build.write_report", "irtps.batch.run.reconstruct_many"} <= expected
    inventory = _inventory(site)
    documented = set().union(*(inventory.get(f"py:{kind}", set()) for kind in ("function", "class", "exception")))
    assert expected - documented == set()


def test_the_gallery_shows_what_irtps_report_draws(site):
    page = (site / "gallery.html").read_text(encoding="utf-8")
    shown = 0
    for run in ("cap_cornell_irtps", "relief_pinhole", "cavity_rig"):
        figures = sorted(path.name for path in (site / "gallery" / run).glob("*.png"))
        assert {"normal.png", "albedo.png", "angular_error.png", "shading.png"} <= set(figures)
        assert all(f"({name})" in page for name in figures)
        assert f'href="gallery/{run}/index.html"' in page
        assert "irtps-shape-data" in (site / "gallery" / run / "index.html").read_text(encoding="utf-8")
        shown += len(figures)
    assert page.count("<img ") == shown
    assert "(indirect.png)" in page and "(rig.png)" in page and "(discontinuities.png)" in page


def test_the_checks_catch_what_is_missing():
    """A command option or a public function that the site lacks is found (so the tests above can fail)."""
    documented = command_options() - {"irtps-reconstruct.--method"}
    assert command_options() - documented == {"irtps-reconstruct.--method"}
    assert "irtps.calibrate.circles.refine_circle" in public_objects()
