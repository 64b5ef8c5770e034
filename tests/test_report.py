"""irtps report: the figures of a reconstruction folder and their page."""

import base64
import io
import json
import shutil
from html.parser import HTMLParser
from pathlib import Path

import matplotlib.image
import numpy as np
import pytest

from irtps.cli.main import main
from irtps.errors import DatasetError, IrtpsError
from irtps.report.build import build_report, write_report
from irtps.report.page import report_html

SMALL = Path(__file__).parent / "data" / "mitsuba_small" / "cap_cornell"
BALL = Path(__file__).parent / "data" / "diligent_ball_small"

BASE_FIGURES = ["normal", "albedo", "shading"]
ERROR_FIGURES = ["angular_error", "height_error", "albedo_error"]


@pytest.fixture(scope="module")
def irtps_run(tmp_path_factory):
    """An IRT-PS reconstruction of the small Cornell-box cap, which has ground truth."""
    out = tmp_path_factory.mktemp("runs") / "cap_irtps"
    code = main(
        [
            "reconstruct",
            str(SMALL),
            "--out",
            str(out),
            "--method",
            "irtps",
            "--iterations",
            "2",
            "--samples",
            "8",
            "--quiet",
        ]
    )
    assert code == 0
    return out


@pytest.fixture
def run_copy(irtps_run, tmp_path):
    """A copy of the IRT-PS run that a test may change."""
    copy = tmp_path / "run"
    shutil.copytree(irtps_run, copy)
    return copy


class _Images(HTMLParser):
    """The src of every <img> and every other src/href of a page."""

    def __init__(self):
        super().__init__()
        self.images, self.links = [], []

    def handle_starttag(self, tag, attrs):
        for name, value in attrs:
            if name == "src" and tag == "img":
                self.images.append(value)
            elif name in ("src", "href"):
                self.links.append(value)


def _parse(page: Path) -> _Images:
    parser = _Images()
    parser.feed(page.read_text(encoding="utf-8"))
    return parser


def _decode_png(data: bytes) -> np.ndarray:
    return matplotlib.image.imread(io.BytesIO(data), format="png")


def test_irtps_run_gets_every_figure_and_a_self_contained_page(run_copy):
    page = write_report(run_copy)
    assert page == run_copy / "report" / "index.html"
    expected = BASE_FIGURES + ["indirect"] + ERROR_FIGURES + ["convergence", "agreement"]
    assert sorted(p.name for p in page.parent.iterdir()) == sorted(
        [f"{name}.png" for name in expected] + ["index.html"]
    )
    parsed = _parse(page)
    assert len(parsed.images) == len(expected)
    for name, source in zip(expected, parsed.images):
        prefix = "data:image/png;base64,"
        assert source.startswith(prefix)
        embedded = base64.b64decode(source[len(prefix) :])
        assert embedded == (page.parent / f"{name}.png").read_bytes()  # the page shows the written figures, in order
        assert _decode_png(embedded).shape[0] > 100
    assert all(link.startswith("data:") for link in parsed.links)  # nothing loaded from elsewhere
    text = page.read_text(encoding="utf-8")
    run = json.loads((run_copy / "run.json").read_text())
    assert f"from the source data set {SMALL.resolve()}" in text
    assert "normal angle (deg)" in text and "n/a" not in text.split("normal angle (deg)")[1].split("\n")[0]
    assert "<th>estimator</th><td>physical</td>" in text
    assert text.count("<tr><td>") == len(run["history"])  # one row per pass
    # The placement and how it was decided, each pass's residual, and the pass chosen.
    assert (
        f"Placement: boundary at height {run['placement']['base_height']:.4g}, estimated from the floor around the object"
        in text
    )
    assert run["albedo_scale"]["source"] == "absolute" and "Albedo scale 1 (the irradiance is absolute)." in text
    chosen = run["chosen_pass"]
    assert f"the result is pass {chosen}" in text
    assert f"<tr><td>{chosen} (result)</td><td>{run['history'][chosen]['residual']['object']:.4f}</td>" in text


def test_normal_figure_shows_the_encoded_normals(irtps_run):
    report = build_report(irtps_run)
    image = _decode_png(report.figures[0].png)[..., :3]
    # Sample the drawn map: the cap's top-left is tilted left and up, so red < 0.5 < green.
    coloured = np.abs(image - 0.5).max(axis=2) > 0.05
    rows, cols = np.nonzero(coloured)
    top_left = image[rows.min() + (rows.max() - rows.min()) // 4, cols.min() + (cols.max() - cols.min()) // 4]
    assert top_left[0] < 0.5 < top_left[1] and top_left[2] > 0.5


def test_without_ground_truth_there_are_no_error_figures_and_the_page_says_why(run_copy):
    record = json.loads((run_copy / "run.json").read_text())
    record["source"] = None
    (run_copy / "run.json").write_text(json.dumps(record))
    report = build_report(run_copy)
    names = [figure.name for figure in report.figures]
    assert names == BASE_FIGURES + ["indirect", "convergence", "agreement"]
    assert report.metrics is None
    text = report_html(report)
    assert "Ground truth: none, so no error maps: run.json names no source data set" in text
    assert "pixels evaluated" not in text


def test_a_moved_source_data_set_is_reported_and_truth_can_be_given(run_copy, tmp_path):
    record = json.loads((run_copy / "run.json").read_text())
    record["source"] = str(tmp_path / "moved")
    (run_copy / "run.json").write_text(json.dumps(record))
    assert "is not there" in build_report(run_copy).ground_truth
    report = build_report(run_copy, truth=SMALL)
    assert [f.name for f in report.figures if f.name in ERROR_FIGURES] == ERROR_FIGURES
    assert report.metrics.pixels > 0


@pytest.mark.parametrize("source", ["the run itself", "/", "a name too long for the system"])
def test_a_recorded_source_that_is_no_data_set_leaves_the_report_without_truth(source, run_copy, tmp_path):
    record = json.loads((run_copy / "run.json").read_text())
    record["source"] = {"the run itself": str(run_copy), "/": "/", "a name too long for the system": "z" * 100_000}[
        source
    ]
    (run_copy / "run.json").write_text(json.dumps(record))
    out = tmp_path / "report"
    assert main(["report", str(run_copy), "--out", str(out), "--quiet"]) == 0
    expected = "is not there" if source.startswith("a name") else "is not a data set"
    assert expected in build_report(run_copy).ground_truth and len(build_report(run_copy).ground_truth) < 400


def test_truth_without_ground_truth_is_an_error_naming_it(run_copy, tmp_path):
    bare = tmp_path / "bare"
    shutil.copytree(SMALL, bare, ignore=shutil.ignore_patterns("gt"))
    with pytest.raises(IrtpsError, match=f"{bare}: has no ground truth"):
        build_report(run_copy, truth=bare)


def test_classic_run_of_a_diligent_capture_has_no_iteration_figures(tmp_path):
    out = tmp_path / "ball"
    assert main(["reconstruct", str(BALL), "--out", str(out), "--quiet"]) == 0
    report = build_report(out)
    # DiLiGenT has true normals only: the angular error map, no height or albedo error.
    assert [figure.name for figure in report.figures] == BASE_FIGURES + ["angular_error", "agreement"]
    assert "Iterations" not in report_html(report)


def test_a_run_without_image_figures_has_no_agreement_figure(run_copy):
    """Folders of older versions have none; a record that does not fit the images is ignored."""
    record = json.loads((run_copy / "run.json").read_text())
    for agreement in (None, {"brightness": [1.0], "spread": [0.01]}):
        record["image_agreement"] = agreement
        (run_copy / "run.json").write_text(json.dumps(record))
        report = build_report(run_copy)
        assert "agreement" not in [figure.name for figure in report.figures]
        assert "Images' spread" not in report_html(report)


def test_a_run_without_recorded_pixel_size_gets_a_note(run_copy):
    record = json.loads((run_copy / "run.json").read_text())
    del record["pixel_size"]
    (run_copy / "run.json").write_text(json.dumps(record))
    report = build_report(run_copy)
    assert len(report.notes) == 1 and "pixel size" in report.notes[0]
    assert report.notes[0] in report_html(report)


def test_a_folder_that_is_not_a_reconstruction_is_named(tmp_path):
    with pytest.raises(DatasetError, match=f"{tmp_path / 'missing'}: no such reconstruction folder"):
        build_report(tmp_path / "missing")
    with pytest.raises(DatasetError, match=f"{SMALL / 'run.json'}: missing .not a reconstruction folder"):
        build_report(SMALL)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (lambda text: "{not json", "run.json: invalid JSON at line 1, column 2"),
        (
            lambda text: text.replace('"pixel_size": ', '"pixel_size": ' + "9" * 5000 + ', "x": '),
            "run.json: line [0-9]+, column [0-9]+: a number with 5000 digits",
        ),
        (lambda text: "[" * 5000 + "]" * 5000, "run.json: arrays and objects nested 5000 deep"),
        (lambda text: "[]", "run.json: the file must be an object"),
        (
            lambda text: text.replace('"format": "irtps.run/1"', '"format": "irtps.table/1"'),
            "run.json: format 'irtps.table/1' is not a reconstruction's",
        ),
        (lambda text: text.replace('"history": [', '"history": [1, '), r"run.json: history\[0\] must be an object"),
        (lambda text: text.replace('"source": "', '"source": 3, "x": "'), "run.json: source must be a string or null"),
        (lambda text: text.replace('"index": 1', '"index": "one"'), r"run.json: history\[1\].index must be a number"),
        (
            lambda text: text.replace('"robust_used": "', '"robust_used": 4, "x": "'),
            "run.json: robust_used must be a string or null",
        ),
    ],
)
def test_a_malformed_run_json_names_the_field(run_copy, change, message):
    path = run_copy / "run.json"
    path.write_text(change(path.read_text()))
    with pytest.raises(DatasetError, match=message):
        build_report(run_copy)


def test_report_is_replaced_atomically_and_a_failure_keeps_the_old_one(run_copy):
    write_report(run_copy)
    (run_copy / "report" / "stale.txt").write_text("from an older report")
    write_report(run_copy)
    assert not (run_copy / "report" / "stale.txt").exists()
    before = {p.name: p.read_bytes() for p in (run_copy / "report").iterdir()}
    (run_copy / "albedo.exr").write_bytes(b"not an image")
    with pytest.raises(IrtpsError, match="albedo.exr"):
        write_report(run_copy)
    assert {p.name: p.read_bytes() for p in (run_copy / "report").iterdir()} == before
    assert not [p for p in run_copy.iterdir() if p.name.startswith(".")]  # no temporary left


def test_report_cannot_replace_the_reconstruction(run_copy):
    with pytest.raises(IrtpsError, match=r"holds the input .*/normal.exr; writing there would delete it"):
        write_report(run_copy, run_copy.parent)
    with pytest.raises(IrtpsError, match=r"lies inside the input .*/indirect"):
        write_report(run_copy, run_copy / "indirect" / "report")
    assert (run_copy / "normal.exr").is_file()


def test_cli_report_writes_the_page_and_quiet_prints_nothing(run_copy, tmp_path, capsys):
    assert main(["report", str(run_copy)]) == 0
    printed = capsys.readouterr().out
    assert "9 figures" in printed and str(run_copy / "report" / "index.html") in printed
    elsewhere = tmp_path / "elsewhere"
    assert main(["report", str(run_copy), "--out", str(elsewhere), "--truth", str(SMALL), "--quiet"]) == 0
    assert capsys.readouterr().out == ""
    assert (elsewhere / "index.html").is_file() and (elsewhere / "angular_error.png").is_file()


def test_cli_report_on_a_data_set_folder_is_a_clear_error(capsys):
    assert main(["report", str(SMALL), "--quiet"]) == 2
    error = capsys.readouterr().err
    assert error.startswith("irtps: error: ") and str(SMALL / "run.json") in error
    assert "Traceback" not in error
