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
PERSPECTIVE = Path(__file__).parent / "data" / "mitsuba_persp_small" / "cap_persp_cornell"

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
  const view = document.getElementById("irtps-shape");
  if (view) {  // the 3-D view as the screen shows it: its pixels copied off the canvas
    const copy = document.createElement("canvas");
    copy.width = view.width; copy.height = view.height;
    const context = copy.getContext("2d");
    context.drawImage(view, 0, 0);
    const pixels = context.getImageData(0, 0, copy.width, copy.height).data;
    let covered = 0;
    for (let i = 0; i < pixels.length; i += 4) if (pixels[i] < 250 || pixels[i + 1] < 250 || pixels[i + 2] < 250) covered++;
    const shape = document.createElement("pre");
    shape.id = "irtps-shape-probe";
    shape.textContent = JSON.stringify({drawn: Number(view.dataset.drawn || 0), covered, pixels: copy.width * copy.height});
    document.body.append(shape);
  }
});
</script>
"""


def open_in_browser(page_text: str, folder: Path) -> tuple[list[dict], list[str]]:
    """Load a page in headless Chromium; return its images' decoded sizes and its console messages."""
    images, console, _ = open_with_view(page_text, folder)
    return images, console


def open_with_view(page_text: str, folder: Path) -> tuple[list[dict], list[str], dict | None]:
    """As `open_in_browser`, and what the 3-D view shows: the triangles it drew and how many of
    its pixels are not the white background (None for a page without the view)."""
    probed = folder / "probed.html"
    probed.write_text(page_text.replace("</body>", PROBE + "</body>"), encoding="utf-8")
    command = [
        CHROMIUM,
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--use-angle=swiftshader",  # WebGL on the CPU, as a machine without a GPU draws it
        "--enable-unsafe-swiftshader",
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
    console = [
        line
        for line in result.stderr.splitlines()
        if ":CONSOLE" in line and "GPU stall due to ReadPixels" not in line  # the probe's own reading of the canvas
    ]
    view = re.search(r'<pre id="irtps-shape-probe">(.*?)</pre>', result.stdout, re.DOTALL)
    shown = None if view is None else json.loads(html.unescape(view.group(1)))
    return json.loads(html.unescape(found.group(1))), console, shown


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
    images, console, view = open_with_view(page, tmp_path)
    assert len(images) == len(list((run / "report").glob("*.png"))) == 9
    for image in images:
        assert image["complete"] and image["width"] > 100 and image["height"] > 100, image
    assert console == []
    # the reconstruction and the true surface: 2 x 2 x 95 x 95 triangles at most (96 x 96 pixels)
    assert view is not None and 2 * 2000 < view["drawn"] <= 4 * 95 * 95
    assert 0.05 * view["pixels"] < view["covered"] < 0.9 * view["pixels"]


def test_the_3d_view_draws_a_perspective_reconstruction(tmp_path):
    run = tmp_path / "persp"
    assert main(["reconstruct", str(PERSPECTIVE), "--out", str(run), "--quiet"]) == 0
    assert main(["report", str(run), "--quiet"]) == 0
    page = (run / "report" / "index.html").read_text(encoding="utf-8")
    assert "through the pinhole" in page
    _, console, view = open_with_view(page, tmp_path)
    assert console == []
    assert view is not None and view["drawn"] > 100 and view["covered"] > 0.01 * view["pixels"]


def test_the_view_probe_sees_a_canvas_with_nothing_drawn(tmp_path):
    blank = (
        "<!DOCTYPE html><html><head><meta charset='utf-8'><title>blank</title></head><body>"
        "<canvas id='irtps-shape' width='64' height='32'></canvas><script>"
        "const gl = document.getElementById('irtps-shape').getContext('webgl', {preserveDrawingBuffer: true});"
        "gl.clearColor(1, 1, 1, 1); gl.clear(gl.COLOR_BUFFER_BIT);</script></body></html>"
    )
    _, console, view = open_with_view(blank, tmp_path)
    assert console == [] and view == {"drawn": 0, "covered": 0, "pixels": 64 * 32}


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
