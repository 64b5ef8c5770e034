"""The report page in a real headless browser: it loads, every figure decodes, the console stays quiet.

The page is opened by Chromium (``chromium --headless --dump-dom``) with a probe script
appended that, once the page has loaded, writes each <img>'s decoded size into the DOM;
Chromium's log (``--enable-logging=stderr``) carries the page's console messages and
uncaught errors. Without Chromium these tests skip.
"""

import html
import json
import re
import shutil
import subprocess
from pathlib import Path

import pytest

from irtps.cli.main import main

SMALL = Path(__file__).parent / "data" / "mitsuba_small" / "cap_cornell"

CHROMIUM = next(filter(None, map(shutil.which, ("chromium", "chromium-browser", "google-chrome"))), None)
pytestmark = pytest.mark.skipif(
    CHROMIUM is None,
    reason="no Chromium on PATH (Debian: apt-get install chromium), so the report page is not opened in a browser",
)

PROBE = """<script>
window.addEventListener("load", () => {
  const probe = document.createElement("pre");
  probe.id = "irtps-probe";
  probe.textContent = JSON.stringify(Array.from(document.images, (image) => ({
    alt: image.alt, complete: image.complete, width: image.naturalWidth, height: image.naturalHeight,
  })));
  document.body.append(probe);
});
</script>
"""


def open_in_browser(page_text: str, folder: Path) -> tuple[list[dict], list[str]]:
    """Load a page in headless Chromium; return its images' decoded sizes and its console messages."""
    probed = folder / "probed.html"
    probed.write_text(page_text.replace("</body>", PROBE + "</body>"), encoding="utf-8")
    command = [
        CHROMIUM,
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        f"--user-data-dir={folder / 'profile'}",
        "--enable-logging=stderr",
        "--v=0",
        "--virtual-time-budget=10000",
        "--dump-dom",
        probed.as_uri(),
    ]
    result = subprocess.run(command, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    found = re.search(r'<pre id="irtps-probe">(.*?)</pre>', result.stdout, re.DOTALL)
    assert found, f"the page never finished loading; Chromium said:\n{result.stderr}"
    console = [line for line in result.stderr.splitlines() if ":CONSOLE" in line]
    return json.loads(html.unescape(found.group(1))), console


def test_the_report_page_shows_every_figure_without_console_errors(tmp_path):
    run = tmp_path / "cap_irtps"
    assert (
        main(
            [
                "reconstruct",
                str(SMALL),
                "--out",
                str(run),
                "--method",
                "irtps",
                "--iterations",
                "2",
                "--samples",
                "8",
                "--quiet",
            ]
        )
        == 0
    )
    assert main(["report", str(run), "--quiet"]) == 0
    page = (run / "report" / "index.html").read_text(encoding="utf-8")
    images, console = open_in_browser(page, tmp_path)
    assert len(images) == len(list((run / "report").glob("*.png"))) == 9
    for image in images:
        assert image["complete"] and image["width"] > 100 and image["height"] > 100, image
    assert console == []


def test_the_browser_check_catches_a_broken_page(tmp_path):
    broken = (
        "<!DOCTYPE html><html><head><meta charset='utf-8'><title>broken</title></head><body>"
        "<img alt='truncated' src='data:image/png;base64,iVBORw0KGgo='>"
        "<script>console.error('boom'); notDefined();</script></body></html>"
    )
    images, console = open_in_browser(broken, tmp_path)
    assert images == [{"alt": "truncated", "complete": True, "width": 0, "height": 0}]
    assert any('"boom"' in line for line in console)
    assert any("Uncaught ReferenceError: notDefined" in line for line in console)
