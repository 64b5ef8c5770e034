"""The interactive examples of the README and of every page of docs/ run and print what they show."""

import doctest
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]


def test_pycon_blocks_run_as_shown(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    parser, runner = doctest.DocTestParser(), doctest.DocTestRunner(optionflags=doctest.ELLIPSIS)
    for page in PAGES:
        blocks = re.findall(r"```pycon\n(.*?)```", page.read_text(encoding="utf-8"), re.S)
        for number, block in enumerate(blocks):
            name = f"{page.relative_to(ROOT)} block {number}"
            runner.run(parser.get_doctest(block, {}, name, str(page), 0))
    assert runner.failures == 0 and runner.tries > 0
