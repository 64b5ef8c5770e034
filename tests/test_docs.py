"""The README, the pages of docs/ and benches/README.md name only what exists: every file path
of the package, the core, the tests and the benchmarks is a file; every dotted name
``irtps.a.b`` in code imports (the longest importable module, then attributes); every relative
link leads to a file, and every ``#anchor`` to a heading of its page."""

import importlib
import importlib.util
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "python" / "irtps"
PAGES = [ROOT / "README.md", ROOT / "benches" / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
#: The package's subpackages, by which a path in a module map starts (``model/scene.py``).
SUBPACKAGES = sorted(path.name for path in PACKAGE.iterdir() if (path / "__init__.py").is_file())

#: A path named in a page, and the folder it is relative to.
PATH_PATTERNS = [
    (re.compile(r"(?<![\w/.-])python/irtps(?:/[\w.]+)*"), ROOT),
    (re.compile(r"(?<![\w/.-])irtps/[\w/]+\.pyi?\b"), ROOT / "python"),
    (re.compile(rf"(?<![\w/.-])(?:{'|'.join(SUBPACKAGES)})/[\w/]+\.py\b"), PACKAGE),
    (re.compile(r"(?<![\w/.-])(?:rust|benches|tests|fuzz)/[\w/]+\.(?:rs|py)\b"), ROOT),
]
#: A dotted name in the package (``irtps.ps.fit.choose_robust``), not a record's format
#: (``irtps.run/1``).
DOTTED = re.compile(r"(?<![\w.])irtps(?:\.\w+)+(?![\w/])")
#: ``from irtps.x import a, b`` in an example: each imported name too.
FROM_IMPORT = re.compile(r"^\s*(?:>>> )?from (irtps(?:\.\w+)*) import ([\w, ]+)$", re.M)
FENCE = re.compile(r"^```.*?^```", re.S | re.M)
CODE = re.compile(r"```.*?```|`[^`\n]+`", re.S)
LINK = re.compile(r"\[[^\]]*\]\(([^)\s]+)\)")
HEADING = re.compile(r"^#{1,6} +(.+?) *$", re.M)
#: A MyST include (the site's front page includes the README): its anchors are the page's too.
INCLUDE = re.compile(r"^```\{include\} +(\S+)", re.M)


def _page_id(page: Path) -> str:
    return str(page.relative_to(ROOT))


def missing_paths(text: str) -> list[str]:
    """The file paths named in `text` that are not there."""
    missing = []
    for pattern, base in PATH_PATTERNS:
        missing += [path for path in pattern.findall(text) if not (base / path).exists()]
    return missing


def _resolves(name: str) -> bool:
    """Whether the dotted `name` imports: its longest importable module, then attributes."""
    parts = name.split(".")
    for length in range(len(parts), 0, -1):
        module_name = ".".join(parts[:length])
        try:
            target = importlib.import_module(module_name)
        except ModuleNotFoundError as error:
            if error.name is not None and module_name.startswith(error.name):
                continue
            raise
        for attribute in parts[length:]:
            if not hasattr(target, attribute):
                return False
            target = getattr(target, attribute)
        return True
    return False


def unresolved_names(text: str) -> list[str]:
    """The dotted names in `text`'s code (spans and blocks) that do not import."""
    names = set()
    for code in CODE.findall(text):
        names |= set(DOTTED.findall(code))
        for module, imported in FROM_IMPORT.findall(code):
            names |= {f"{module}.{name.strip()}" for name in imported.split(",") if name.strip()}
    return sorted(name for name in names if not _resolves(name))


def _slug(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation but hyphens dropped, spaces to hyphens."""
    text = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", heading).lower()
    return re.sub(r"[^\w\- ]", "", text).replace(" ", "-")


def _anchors(page: Path) -> set[str]:
    """The anchors of `page`: its headings' and those of the pages it includes."""
    text = page.read_text(encoding="utf-8")
    included = set().union(*(_anchors(page.parent / path) for path in INCLUDE.findall(text)))
    return {_slug(heading) for heading in HEADING.findall(FENCE.sub("", text))} | included


def broken_links(page: Path, text: str) -> list[str]:
    """The relative links of `text` (on `page`) whose file or heading is not there."""
    broken = []
    for target in LINK.findall(CODE.sub("", text)):
        if re.match(r"[a-z]+:", target):
            continue
        path, _, anchor = target.partition("#")
        destination = (page.parent / path).resolve() if path else page
        if not destination.exists():
            broken.append(target)
        elif anchor and destination.suffix == ".md" and anchor not in _anchors(destination):
            broken.append(target)
    return broken


@pytest.mark.parametrize("page", PAGES, ids=_page_id)
def test_paths_named_exist(page):
    assert missing_paths(page.read_text(encoding="utf-8")) == []


@pytest.mark.parametrize("page", PAGES, ids=_page_id)
def test_dotted_names_import(page):
    assert unresolved_names(page.read_text(encoding="utf-8")) == []


@pytest.mark.parametrize("page", PAGES, ids=_page_id)
def test_relative_links_lead_somewhere(page):
    assert broken_links(page, page.read_text(encoding="utf-8")) == []


def test_every_docs_page_is_listed_in_the_index():
    index = (ROOT / "docs" / "index.md").read_text(encoding="utf-8")
    listed = {(ROOT / "docs" / target.partition("#")[0]).resolve() for target in LINK.findall(index)}
    assert {page.resolve() for page in (ROOT / "docs").glob("*.md")} - {ROOT / "docs" / "index.md"} <= listed


def test_the_module_maps_layers_are_those_test_imports_checks():
    spec = importlib.util.spec_from_file_location("layers_checked", Path(__file__).with_name("test_imports.py"))
    assert spec is not None and spec.loader is not None
    checked = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(checked)
    line = re.search(r"^errors < .*$", (ROOT / "docs" / "architecture.md").read_text(encoding="utf-8"), re.M)
    assert line is not None, "the module map (docs/architecture.md) has no layer line"
    assert [layer.split(", ") for layer in line.group().split(" < ")] == checked.LAYERS


def test_the_checks_catch_made_up_names(tmp_path):
    """Each check fails on a name that is not there (so that the tests above can fail)."""
    assert missing_paths("see python/irtps/ps/no_such.py, irtps/io/nothing.py and rust/nowhere.rs") == [
        "python/irtps/ps/no_such.py",
        "irtps/io/nothing.py",
        "rust/nowhere.rs",
    ]
    assert missing_paths("`model/no_such.py`, `benches/none.py`, `tests/test_none.py`") == [
        "model/no_such.py",
        "benches/none.py",
        "tests/test_none.py",
    ]
    assert missing_paths("`model/scene.py`, `python/irtps/ps/fit.py`, `irtps.run/1`") == []
    assert unresolved_names("`irtps.ps.fit.no_such_function` and `irtps.nowhere.module`") == [
        "irtps.nowhere.module",
        "irtps.ps.fit.no_such_function",
    ]
    assert unresolved_names("```python\nfrom irtps.ps.fit import choose_robust, made_up\n```") == [
        "irtps.ps.fit.made_up"
    ]
    assert unresolved_names("`irtps.ps.fit.choose_robust`, `irtps.load_dataset(path)`, `irtps.run/1`") == []
    page = tmp_path / "page.md"
    page.write_text("# A heading\n", encoding="utf-8")
    text = "[a](page.md#a-heading) [b](missing.md) [c](#no-heading) [d](https://example.org)"
    assert broken_links(page, text) == ["missing.md", "#no-heading"]
    front = tmp_path / "front.md"
    front.write_text("```{include} page.md\n```\n\n## Its own\n", encoding="utf-8")
    text = "[a](front.md#a-heading) [b](front.md#its-own) [c](front.md#not-there)"
    assert broken_links(front, text) == ["front.md#not-there"]
