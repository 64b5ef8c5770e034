"""The argument parser of the ``irtps`` command, built from a table of its commands
(`COMMANDS`): each one's texts, the function that runs it and its arguments, made of its own
and of the parts that commands share (`irtps.cli.arguments`)."""

from __future__ import annotations

import argparse
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from irtps._shared.output_rule import escaped
from irtps.cli import handlers
from irtps.cli.arguments import (
    CLUSTER,
    ENCODING,
    EXCLUDE_IMAGES,
    EXCLUDE_IMAGES_BY_NAME,
    INTRINSICS,
    INTRINSICS_BY_NAME,
    LIGHTS,
    LIGHTS_BY_NAME,
    NORMAL_MAP,
    RECONSTRUCT,
    RENDER,
    SYNTH,
    TABLE,
    Argument,
    Options,
    Output,
)
from irtps.model.options import TableOptions, int_argument
from irtps.render.synth import SHAPES

__all__ = ["COMMANDS", "Command", "build_parser"]


@dataclass(frozen=True)
class Command:
    """One command of ``irtps``.

    Its help lists its arguments in the order of `parts`: its own `arguments`, the
    output's ``--out``, the `options`, then the output's ``--force`` and ``--quiet``.

    Attributes
    ----------
    name : str
    help : str
        One line in the list of commands.
    description : str
        What it does, at the top of its help.
    examples : tuple of str
        Command lines, at the end of its help.
    run : callable
        What it does with the parsed arguments (`irtps.cli.handlers`).
    arguments : tuple of Argument
        Its own arguments that come first: what it reads.
    output : Output, optional
        The folder it writes, if any.
    options : tuple of Argument or Options
        How it runs: the images to leave out, options of `irtps.model.options` and its own.
    """

    name: str
    help: str
    description: str
    examples: tuple[str, ...]
    run: Callable[[argparse.Namespace], None]
    arguments: tuple[Argument, ...] = ()
    output: Output | None = None
    options: tuple[Argument | Options, ...] = ()

    def parts(self) -> tuple[Argument | Options, ...]:
        """Its arguments, in the order that its help lists them."""
        if self.output is None:
            return (*self.arguments, *self.options)
        return (*self.arguments, *self.output.first(), *self.options, *self.output.last())


#: The commands of ``irtps``, in the order that its help lists them.
COMMANDS = (
    Command(
        "render",
        help="render a data set's true object: direct light and each inter-reflection bounce",
        description="Render the object of DATASET (scene.json, gt/height.exr, gt/albedo.exr, mask.png) under each of "
        "its lights and write a complete data set to OUT: images/ (direct plus all bounces), gt/direct/, gt/bounceN/, "
        "gt/height.exr, gt/normal.exr, gt/albedo.exr, scene.json, mask.png. OUT is replaced atomically.",
        examples=(
            "irtps render shared/data/mitsuba/cap_cornell --out cap_irtps",
            "irtps render my_scene --out my_render --bounces 2 --samples 64 --quiet",
        ),
        run=handlers.run_render,
        arguments=(Argument("dataset", type=Path, help="data set folder (contract layout)"),),
        output=Output("output data set folder", quiet="no progress bar or summary"),
        options=(RENDER,),
    ),
    Command(
        "synth",
        help="synthesize a scene with ground truth and render it",
        description="Make a synthetic data set: a height-field SHAPE with uniform or textured albedo, lit by LIGHTS "
        "distant lights, optionally inside a Cornell box, rendered with inter-reflections; written to OUT in the "
        "contract layout with ground truth and each bounce separately.",
        examples=(
            "irtps synth cap --out cap",
            "irtps synth grooves --out grooves --environment none --size 128 --lights 20",
            "irtps synth relief --out relief --albedo textured --seed 3",
        ),
        run=handlers.run_synth,
        arguments=(Argument("shape", choices=sorted(SHAPES), help="the object's shape"),),
        output=Output("output data set folder", quiet="no progress bar or summary"),
        options=(SYNTH, RENDER),
    ),
    Command(
        "reconstruct",
        help="recover normals, albedo, a height map and a mesh from a data set",
        description="Reconstruct the object of DATA (contract, DiLiGenT or RTI layout, detected, or a folder of "
        "images given --lights; its camera "
        "orthographic, or perspective: scene.json's, a DiLiGenT folder's K.txt or --intrinsics) and write OUT: "
        "normal.exr (R, G, B = nx, ny, nz), albedo.exr, height.exr, mask.png, mesh.ply (the height field with "
        "per-vertex albedo colour and normals), mesh.obj (the same mesh for any viewer), for other tools normal.png "
        "(16-bit normal map, --normal-map), height.tif (32-bit float), height.png (16-bit, its scale in run.json) "
        "and mesh.glb (glTF binary with vertex colours), and run.json (parameters, "
        "timings, versions, the data set's path, the placement, the robust mode used and the lobe share that auto "
        "chose it by, the images fitted and those left out, and how each image agrees with the fit: one whose "
        "brightness is far from the others' had another light or exposure than recorded, one whose spread is wider "
        "was taken as the object or the camera moved); with --method irtps also indirect/NAME.exr (for each image "
        "NAME.png or NAME.exr fitted, the estimated inter-reflected light, with the floor's light in the edge pixels, "
        "that was subtracted) and each pass's residual in run.json: the reconstruction rendered again and compared "
        "with the images, the number to judge a run by without ground truth. The result is the pass with the lowest "
        "residual (pass 0 is classic PS). When DATA has ground truth, the errors are printed too. OUT is replaced "
        "atomically.",
        examples=(
            "irtps reconstruct shared/data/diligent/ballPNG --out ball",
            "irtps reconstruct shared/data/mitsuba/cap_cornell --out cap_irtps --method irtps --bounces 3",
            "irtps reconstruct cavity --out cavity_ps --integration mestimator",
            "irtps reconstruct capture --out capture_ps --saturation 0.99 --base-height boundary",
            "irtps reconstruct shared/data/diligent/readingPNG --out reading --robust trim",
            "irtps reconstruct metal_capture --out metal --robust lobe",
            "irtps reconstruct rig_capture --out rig --method irtps --albedo-scale 0.8",
            "irtps reconstruct bearPNG --out bear --exclude-images 1-20",
            "irtps reconstruct capture --out capture_ps --intrinsics capture/K.txt",
            "irtps reconstruct dome_object --out dome_ps --lights dome_lights/lights.lp   # from irtps calibrate",
            "irtps reconstruct capture --out capture_ps --normal-map directx   # for Unreal",
        ),
        run=handlers.run_reconstruct,
        arguments=(Argument("data", type=Path, help="data set folder"),),
        output=Output("output folder", quiet="no progress bar or summary"),
        options=(EXCLUDE_IMAGES, INTRINSICS, LIGHTS, ENCODING, NORMAL_MAP, RECONSTRUCT),
    ),
    Command(
        "batch",
        help="reconstruct many data sets on a Dask cluster, with a summary",
        description="Reconstruct each DATA into OUT/NAME/ (NAME: the folder's name, made unique with -2, -3 ...), "
        "the files of 'irtps reconstruct', each written atomically by the worker that reconstructed it. Runs on a "
        "local Dask cluster (one worker process per core, one data set at a time each) or, with --scheduler, on a "
        "running Dask cluster whose workers see the same file system under the same paths. A data set that fails is "
        "reported and the others go on. Prints a summary (status, seconds, mean angular error when there is ground "
        "truth, the error of a failed data set) and writes it to OUT/batch.md and OUT/batch.json; exits with status "
        "2 if any data set failed. Needs Dask: pip install 'irtps[batch]'.\n\n"
        "A worker process that dies (killed, out of memory) loses nothing: its data set runs again on another worker "
        "or the restarted one, up to 3 times (Dask's distributed.scheduler.allowed-failures), and the summary counts "
        "the lost workers; a data set that kills every worker that runs it fails with a KilledWorker error. With "
        "--resume, a batch run again (e.g. after it was stopped) keeps each output folder that is complete and "
        "reports it as 'reused'.\n\n"
        "On a cluster with a shared file system: run 'dask scheduler' on one node, "
        "'RAYON_NUM_THREADS=1 dask worker tcp://HOST:8786 --nworkers $(nproc) --nthreads 1' on each compute node, "
        "then 'irtps batch ... --scheduler tcp://HOST:8786'.",
        examples=(
            "irtps batch shared/data/diligent/*PNG --out diligent_ps",
            "irtps batch shared/data/diligent/*PNG --out diligent_ps --exclude-images bearPNG=1-20",
            "irtps batch capture_a capture_b --out runs --intrinsics rig/K.txt --intrinsics capture_b=other/K.txt",
            "irtps batch session_*/ --out runs --lights rig_lights/lights.lp   # one calibration, many captures",
            "irtps batch scenes/* --out runs --method irtps --bounces 2 --workers 2 --threads-per-worker 4",
            "irtps batch /shared/scenes/* --out /shared/runs --method irtps --scheduler tcp://head-node:8786",
            "irtps batch scenes/* --out runs --method irtps --bounces 2 --resume   # after an interrupted run",
        ),
        run=handlers.run_batch,
        arguments=(Argument("data", type=Path, nargs="+", help="data set folders"),),
        output=Output(
            "folder for one reconstruction folder per data set and the summary", quiet="no progress bar", resume=True
        ),
        options=(
            EXCLUDE_IMAGES_BY_NAME,
            INTRINSICS_BY_NAME,
            LIGHTS_BY_NAME,
            ENCODING,
            NORMAL_MAP,
            RECONSTRUCT,
            CLUSTER,
        ),
    ),
    Command(
        "calibrate",
        help="each light's direction and strength from images of a mirror and a matte sphere",
        description="Calibrate a rig's lights from CAPTURE, a folder of images (JPEG, PNG, TIFF, EXR or camera RAW, one light "
        "each, in name order) of a mirror (chrome) sphere and, optionally, a matte white sphere, seen by a distant "
        "(orthographic) camera. The spheres are found (or given: --chrome, --matte); each light's direction is its "
        "highlight on the mirror sphere, mirrored about the view direction, and its RGB strength the matte sphere's "
        "brightness over n.l. The mirror sphere's outline is faint where it mirrors what is behind it, so with a "
        "matte sphere its circle is fitted to the highlights and the matte sphere's shading (each light's direction "
        "still comes from its own highlight); without a mirror sphere, the directions come from the matte sphere. "
        "Writes OUT: lights.lp ('name x y z' per image: 'irtps reconstruct CAPTURE --lights OUT/lights.lp' "
        "gives a capture's images these lights), with a matte sphere also "
        "light_intensities.txt (the strengths, one RGB line per image, which an RTI folder takes beside its .lp) and "
        "lights.json (the scene contract's 'lights'), calibration.json (the circles, each highlight, both "
        "spheres' directions and how far apart they are) and calibration.png (what was found). OUT is replaced "
        "atomically.",
        examples=(
            "irtps calibrate shared/data/calibration/spheres/png --out rig_lights",
            "irtps calibrate dome_spheres --out dome_lights --names-from dome_object   # lights.lp names its images",
            "irtps calibrate spheres --out lights --chrome 412,380,95 --matte 1210,380,96 --matte-albedo 0.99",
        ),
        run=handlers.run_calibrate,
        arguments=(Argument("capture", type=Path, help="folder of the calibration images"),),
        output=Output("output folder", quiet="print nothing"),
        options=(
            Argument(
                "--chrome",
                metavar="COLUMN,ROW,RADIUS",
                help="the mirror sphere's circle in pixels from the image's top-left corner (default: found)",
            ),
            Argument(
                "--matte",
                metavar="COLUMN,ROW,RADIUS",
                help="the matte sphere's circle in pixels from the image's top-left corner (default: found)",
            ),
            Argument(
                "--matte-albedo",
                type=float,
                help="the matte sphere's albedo: the strengths are then absolute irradiances, which reconstructions "
                "take as they are (albedos absolute; IRT-PS needs no scale from the images: give it for an object "
                "alone in the dark, captured with the calibration's exposure). Default: unknown, the strengths "
                "relative, their scale found from each capture",
            ),
            Argument(
                "--names-from",
                type=Path,
                metavar="FOLDER",
                help="name lights.lp's lines after the images of FOLDER (as many, taken under the same lights, in name "
                "order) instead of the capture's",
            ),
            ENCODING,
        ),
    ),
    Command(
        "evaluate",
        help="compare a reconstruction with ground truth",
        description="Print the errors of the reconstruction in OUT against the ground truth of the data set GT "
        "(gt/ folder, or DiLiGenT's Normal_gt.mat): mean and median angular error, the IRT-PS paper's normal, "
        "albedo and height errors, and the height error after removing the best constant offset.",
        examples=(
            "irtps evaluate ball --gt shared/data/diligent/ballPNG",
            "irtps evaluate cavity_ps --gt cavity --json",
        ),
        run=handlers.run_evaluate,
        arguments=(
            Argument("out", type=Path, help="reconstruction folder (from irtps reconstruct)"),
            Argument("--gt", type=Path, required=True, help="data set folder with ground truth"),
        ),
        options=(Argument("--json", action="store_true", help="print JSON"),),
    ),
    Command(
        "report",
        help="figures and a web page of a reconstruction",
        description="Draw the reconstruction in OUT as PNG figures: the normal map, the albedo, a shaded relief of the "
        "height field; with ground truth the angular, height and albedo error maps; for IRT-PS runs the estimated "
        "inter-reflected light and the convergence of the iterations. Write them with index.html, one self-contained "
        "page (figures embedded) that shows them beside the run's parameters and metrics, to OUT/report/ (replaced "
        "atomically). Ground truth comes from the data set recorded in OUT/run.json, or --truth.",
        examples=(
            "irtps report cap_irtps",
            "irtps report ball --truth shared/data/diligent/ballPNG",
            "irtps report cap_irtps --out cap_irtps_report --quiet",
        ),
        run=handlers.run_report,
        arguments=(
            Argument("out", metavar="OUT", type=Path, help="reconstruction folder (from irtps reconstruct)"),
            Argument(
                "--truth",
                metavar="DATASET",
                type=Path,
                default=None,
                help="data set with ground truth (default: the run's own data set, if it has any)",
            ),
        ),
        output=Output(
            "report folder (default OUT/report)",
            quiet="print nothing",
            required=False,
            metavar="DIR",
            dest="report_out",
        ),
    ),
    Command(
        "table",
        help="the IRT-PS paper's comparison table: PS against IRT-PS r1, r2, r3",
        description="Reconstruct each DATA (with ground truth) by classic photometric stereo and by IRT-PS estimating "
        "1, 2 and 3 bounces, and print the errors in the layout of the paper's Table 1: rows Height (as reconstructed "
        "and offset-aligned), Albedo, Normal (the paper's metrics) and mean angular error, per data set and overall, "
        "best value in bold. --out writes table.md and table.json.",
        examples=(
            "irtps table shared/data/mitsuba/cap_cornell shared/data/mitsuba/grooves_dark --out table",
            "irtps table cavity --bounces 3 --iterations 4 --samples 128",
            "irtps table rig_a rig_b --exclude-images rig_b=7,12",
        ),
        run=handlers.run_table,
        arguments=(Argument("data", type=Path, nargs="+", help="data set folders with ground truth"),),
        output=Output("folder for table.md and table.json", quiet="no progress bar", required=False),
        options=(EXCLUDE_IMAGES_BY_NAME, INTRINSICS_BY_NAME, TABLE),
    ),
    Command(
        "demo",
        help="synthesize a scene with strong inter-reflection, reconstruct it both ways, print the table",
        description="The main job on an embedded default: synthesize a spherical cap on the floor of a Cornell box "
        "(light bounced from the floor and colour bled from the red and green walls), reconstruct it by classic "
        "photometric stereo and by IRT-PS, print the comparison table and write everything to OUT.",
        examples=("irtps demo", "irtps demo --out demo --size 96 --samples 256"),
        run=handlers.run_demo,
        output=Output(
            "output folder (default irtps-demo)", quiet="no progress bar", required=False, default=Path("irtps-demo")
        ),
        options=(
            Argument("--size", type=int_argument, default=64, help="image size in pixels (default 64)"),
            Options(TableOptions, defaults={"iterations": 5, "samples": 128}),
        ),
    ),
)

#: Command lines of the ``irtps`` command's help.
EXAMPLES = (
    "irtps demo",
    "irtps synth cavity --out cavity",
    "irtps reconstruct cavity --out cavity_ps",
    "irtps evaluate cavity_ps --gt cavity",
    "irtps batch cavity cap --out runs",
    "irtps report cavity_ps",
    "irtps render cavity --out cavity_rerendered --samples 512",
)


class _Parser(argparse.ArgumentParser):
    """An argument parser whose errors are one line, like every other error of irtps."""

    def error(self, message: str):
        self.exit(2, f"irtps: error: {escaped(message)} (see '{self.prog} --help')\n")


def _examples(lines: tuple[str, ...]) -> str:
    """The examples section of a help text."""
    return "examples:\n" + "\n".join(f"  {line}" for line in lines)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``irtps`` command: one subcommand per entry of `COMMANDS`,
    whose ``run`` is the function that runs it."""
    parser = _Parser(
        prog="irtps",
        description="Iterative Ray Tracing Photometric Stereo: shape and colour from photometric-stereo images, "
        "with inter-reflections removed by ray tracing.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog=_examples(EXAMPLES) + "\n\nRun 'irtps COMMAND --help' for a command's options.",
    )
    subcommands = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for command in COMMANDS:
        subparser = subcommands.add_parser(
            command.name,
            help=command.help,
            description=command.description,
            formatter_class=argparse.RawDescriptionHelpFormatter,
            epilog=_examples(command.examples),
        )
        for part in command.parts():
            part.add_to(subparser)
        subparser.set_defaults(run=command.run)
    return parser
