"""The gallery of the report's figures, made by irtps itself when the site is built.

When the build starts, each run of `RUNS` is carried out on a data set synthesized with
ground truth (`irtps.synthesize`, then `irtps.reconstruct` and
`irtps.report.build.build_report`, as a user's ``irtps synth``, ``irtps reconstruct`` and
``irtps report`` would, the report drawn once); its figures go to
``docs/_generated/gallery/RUN/`` and its report page, as ``irtps report`` writes it, into
the site as ``gallery/RUN/index.html``. The directive
``.. irtps-report-gallery::`` shows them with the captions that the report gives them, so
the gallery is always what the installed irtps draws.
"""

from __future__ import annotations

import shutil
import tempfile
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import irtps
from cli_reference import plain
from docutils import nodes
from docutils.parsers.rst import Directive
from docutils.statemachine import StringList
from irtps.report.build import PAGE_FILE, build_report
from irtps.report.page import report_html
from sphinx.util import logging
from sphinx.util.nodes import nested_parse_with_titles

LOGGER = logging.getLogger(__name__)


@dataclass(frozen=True)
class GalleryRun:
    """One reconstruction of the gallery: what is synthesized and how it is reconstructed."""

    name: str
    title: str
    text: str
    command: str
    synth: dict = field(default_factory=dict)
    reconstruct: dict = field(default_factory=dict)


#: The gallery's runs, small enough to make in seconds.
RUNS = (
    GalleryRun(
        "cap_cornell_irtps",
        "A cap in a Cornell box, IRT-PS",
        "A spherical cap on the floor of a Cornell box with a red and a green wall, 8 distant "
        "lights, reconstructed by IRT-PS: the figures of a run with ground truth and its passes.",
        "irtps synth cap --out cap --size 64 --lights 8\n"
        "irtps reconstruct cap --out cap_irtps --method irtps\nirtps report cap_irtps",
        synth={"shape": "cap", "size": 64, "lights": 8, "environment": "cornell"},
        reconstruct={"method": "irtps"},
    ),
    GalleryRun(
        "relief_pinhole",
        "A relief through a pinhole",
        "A textured relief filling the frame of a pinhole camera, 8 distant lights, reconstructed "
        "by classic photometric stereo: the depth discontinuities the integration kept, the error maps.",
        "irtps synth relief --out relief --size 64 --lights 8 --albedo textured --fill --camera perspective\n"
        "irtps reconstruct relief --out relief_ps\nirtps report relief_ps",
        synth={"shape": "relief", "size": 64, "lights": 8, "albedo": "textured", "fill": True, "camera": "perspective"},
    ),
    GalleryRun(
        "cavity_rig",
        "A cavity in a light box, lit by near LEDs",
        "A cavity inside a light box given as a mesh (grey floor and walls, an orange wall), lit by "
        "point lights two image widths away, as a rig's LEDs, reconstructed by IRT-PS: the rig "
        "around the reconstruction.",
        "irtps synth cavity --out cavity --size 64 --lights 8 --environment light-box --lights-near 2\n"
        "irtps reconstruct cavity --out cavity_irtps --method irtps\nirtps report cavity_irtps",
        synth={"shape": "cavity", "size": 64, "lights": 8, "environment": "light-box", "lights_near": 2.0},
        reconstruct={"method": "irtps"},
    ),
)


def _folder(source_folder: Path) -> Path:
    return source_folder / "_generated" / "gallery"


def make_gallery(source_folder: Path) -> None:
    """Carry out every run of `RUNS`; write its figures and report page for the site."""
    figures_root = _folder(source_folder)
    pages_root = source_folder / "_generated" / "site" / "gallery"
    for root in (figures_root, pages_root):
        shutil.rmtree(root, ignore_errors=True)
        root.mkdir(parents=True)
    with tempfile.TemporaryDirectory() as work:
        for run in RUNS:
            LOGGER.info(f"gallery: {run.name}")
            dataset_folder = Path(work) / run.name
            run_folder = Path(work) / f"{run.name}_out"
            dataset, _ = irtps.synthesize(**run.synth, seed=0)
            irtps.save_dataset(dataset, dataset_folder)
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always", irtps.IrtpsWarning)
                result = irtps.reconstruct(irtps.load_dataset(dataset_folder), **run.reconstruct)
            for warning in caught:
                LOGGER.info(f"gallery: {run.name}: {warning.message}")
            irtps.save_reconstruction(result, run_folder, source=str(dataset_folder))
            report = build_report(run_folder)
            lines = []
            for folder in (figures_root / run.name, pages_root / run.name):
                folder.mkdir()
                for figure in report.figures:
                    (folder / f"{figure.name}.png").write_bytes(figure.png)
            for figure in report.figures:
                lines.append(f"{figure.name}\t{figure.title}\t{figure.caption}\t{'wide' if figure.wide else ''}")
            (figures_root / run.name / "figures.tsv").write_text("\n".join(lines) + "\n")
            (pages_root / run.name / PAGE_FILE).write_text(report_html(report), encoding="utf-8")


def gallery_lines(source_folder: Path) -> list[str]:
    """The reST of the gallery: a section per run, its commands, its figures, its page."""
    lines = []
    for run in RUNS:
        figures = (_folder(source_folder) / run.name / "figures.tsv").read_text().splitlines()
        lines += [run.title, "-" * len(run.title), "", plain(run.text), "", ".. code-block:: console", ""]
        lines += [f"   $ {line}" if not line.startswith(" ") else f"   {line}" for line in run.command.splitlines()]
        lines += ["", f"`The report page, with its 3-D view <gallery/{run.name}/index.html>`__", ""]
        lines += [".. container:: irtps-gallery", ""]
        for row in figures:
            name, title, caption, wide = row.split("\t")
            lines += [f"   .. figure:: /_generated/gallery/{run.name}/{name}.png", "      :width: 100%"]
            lines += [
                f"      :figclass: {wide}" if wide else "",
                "",
                f"      **{plain(title)}** ({name}.png): {plain(caption)}",
                "",
            ]
    return lines


class ReportGallery(Directive):
    """``.. irtps-report-gallery::``: the figures of every run of `RUNS`, with their captions."""

    has_content = False

    def run(self):
        # Read again at every build: what it shows comes from the code, not from this page.
        self.state.document.settings.env.note_reread()
        source_folder = Path(self.state.document.settings.env.srcdir)
        text = StringList(gallery_lines(source_folder), source="report_gallery.RUNS")
        node = nodes.section()
        node.document = self.state.document
        nested_parse_with_titles(self.state, text, node)
        return node.children


def _on_config_inited(app, config) -> None:
    (Path(app.srcdir) / "_generated" / "site").mkdir(parents=True, exist_ok=True)


def _on_builder_inited(app) -> None:
    make_gallery(Path(app.srcdir))


def setup(app):
    app.connect("config-inited", _on_config_inited)
    app.connect("builder-inited", _on_builder_inited)
    app.add_directive("irtps-report-gallery", ReportGallery)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
