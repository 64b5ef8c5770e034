"""The API reference, generated from the installed package when the site is built.

Before Sphinx reads its sources, this writes ``docs/reference/generated/``: a page for the
``irtps`` package (an autosummary table of ``irtps.__all__``, one page per name) and a page
per subpackage (every public module in it, with its public members: its ``__all__``, or
every name it defines that does not start with an underscore). Nothing in it is written by
hand, so a new function or module appears in the site by itself.
"""

from __future__ import annotations

import importlib
import pkgutil
from pathlib import Path

import irtps

#: Where the generated pages go, relative to the documentation's source folder.
FOLDER = Path("reference") / "generated"


def public_modules() -> list[str]:
    """The package's modules whose dotted path has no part starting with an underscore."""
    names = []
    for module in pkgutil.walk_packages(irtps.__path__, "irtps."):
        if not any(part.startswith("_") for part in module.name.split(".")[1:]):
            names.append(module.name)
    return sorted(names)


def _heading(text: str, underline: str) -> str:
    return f"{text}\n{underline * len(text)}\n"


def package_page() -> str:
    """The reST page of ``irtps`` itself: its docstring and a table of ``irtps.__all__``."""
    names = [name for name in irtps.__all__ if not name.startswith("__")]
    rows = "\n".join(f"   {name}" for name in names)
    return (
        _heading("irtps", "=")
        + "\n.. automodule:: irtps\n   :no-members:\n\n"
        + "Everything below is importable from ``irtps`` itself.\n\n"
        + ".. currentmodule:: irtps\n\n"
        + f".. autosummary::\n   :toctree: stubs\n   :nosignatures:\n\n{rows}\n"
    )


def subpackage_page(subpackage: str, modules: list[str]) -> str:
    """The reST page of one subpackage: its docstring, then each of its public modules.

    A subpackage named as a function of ``irtps`` (``irtps.render``, ``irtps.evaluate``) is
    not indexed as a module: the name in the index is the function's.
    """
    shadowed = "   :no-index:\n" if subpackage.rpartition(".")[2] in irtps.__all__ else ""
    text = _heading(subpackage, "=") + f"\n.. automodule:: {subpackage}\n   :no-members:\n{shadowed}\n"
    for module in modules:
        text += "\n" + _heading(module, "-") + f"\n.. automodule:: {module}\n   :members:\n"
        if not hasattr(importlib.import_module(module), "__all__"):
            text += "   :exclude-members: annotations\n"
    return text


def write_pages(source_folder: Path) -> None:
    """Write the API reference's pages under `source_folder`/``reference/generated``."""
    folder = source_folder / FOLDER
    folder.mkdir(parents=True, exist_ok=True)
    pages = {"irtps.rst": package_page()}
    modules = public_modules()
    subpackages = [
        name for name in modules if name.count(".") == 1 and hasattr(importlib.import_module(name), "__path__")
    ]
    for subpackage in subpackages:
        inside = [name for name in modules if name.startswith(subpackage + ".")]
        pages[f"{subpackage}.rst"] = subpackage_page(subpackage, inside)
    loose = [name for name in modules if name.count(".") == 1 and name not in subpackages]
    pages["irtps.modules.rst"] = _heading("Other modules", "=") + "".join(
        "\n" + _heading(name, "-") + f"\n.. automodule:: {name}\n   :members:\n" for name in loose
    )
    for name, text in pages.items():
        path = folder / name
        if not path.exists() or path.read_text() != text:
            path.write_text(text)
    for stale in set(folder.glob("*.rst")) - {folder / name for name in pages}:
        stale.unlink()


def _on_config_inited(app, config) -> None:
    write_pages(Path(app.srcdir))


def setup(app):
    app.connect("config-inited", _on_config_inited)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
