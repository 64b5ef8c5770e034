"""The arguments of the ``irtps`` commands, declared once: the kinds of part a command's
arguments are made of (`Argument`, `Options`, `Output`) and the parts that several commands
share (the images to leave out, the options of `irtps.model.options`, the output folder with
``--force`` and ``--quiet``)."""

from __future__ import annotations

import argparse
import copy
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from irtps.io.exchange import NORMAL_MAP_CONVENTIONS
from irtps.io.imageio import ENCODINGS
from irtps.model.options import (
    ClusterOptions,
    ReconstructOptions,
    RenderOptions,
    SynthOptions,
    TableOptions,
    add_arguments,
)

__all__ = [
    "CLUSTER",
    "ENCODING",
    "EXCLUDE_IMAGES",
    "EXCLUDE_IMAGES_BY_NAME",
    "INTRINSICS",
    "INTRINSICS_BY_NAME",
    "NORMAL_MAP",
    "RECONSTRUCT",
    "RENDER",
    "SYNTH",
    "TABLE",
    "Argument",
    "Options",
    "Output",
]


class Argument:
    """One argument of a command: the names and keywords of
    `argparse.ArgumentParser.add_argument`.

    Parameters
    ----------
    *names : str
        The argument's name, or its option strings (``"--out"``).
    **settings
        The keywords of ``add_argument`` (``type``, ``help``, ``default`` ...).
    """

    def __init__(self, *names: str, **settings: Any) -> None:
        self.names = names
        self.settings = settings

    def add_to(self, parser: argparse.ArgumentParser) -> None:
        """Add the argument to `parser`, with a copy of its settings of its own (a list default
        included)."""
        parser.add_argument(*self.names, **copy.deepcopy(self.settings))


@dataclass(frozen=True)
class Options:
    """The options of an options class of `irtps.model.options`, one per field
    (`irtps.model.options.add_arguments`).

    Attributes
    ----------
    kind : type
        The options class, e.g. `irtps.model.options.RenderOptions`.
    title : str, optional
        The title of an argument group that holds them all.
    groups : dict, optional
        Titles of argument groups by the fields' group name.
    defaults : dict, optional
        Defaults that differ from the class's for the command.
    """

    kind: type
    title: str | None = None
    groups: dict[str, str] | None = None
    defaults: dict[str, Any] | None = None

    def add_to(self, parser: argparse.ArgumentParser) -> None:
        """Add the options to `parser`."""
        target = parser if self.title is None else parser.add_argument_group(self.title)
        add_arguments(target, self.kind, defaults=self.defaults, groups=self.groups)


@dataclass(frozen=True)
class Output:
    """The output folder of a command that writes one: ``--out``, which the command's help
    lists after the command's own first arguments (`first`), and ``--force`` (with
    ``--resume``, if it takes it) and ``--quiet``, which it lists last (`last`).

    Attributes
    ----------
    help : str
        The help of ``--out``.
    quiet : str
        The help of ``--quiet``: what it leaves out.
    required : bool
        Whether ``--out`` must be given.
    default : pathlib.Path, optional
        The folder when ``--out`` is not given.
    metavar : str, optional
        The name of ``--out``'s value in the help (default ``OUT``).
    dest : str
        The attribute of the parsed arguments that holds the folder.
    resume : bool
        Whether the command takes ``--resume`` (`RESUME`).
    """

    help: str
    quiet: str
    required: bool = True
    default: Path | None = None
    metavar: str | None = None
    dest: str = "out"
    resume: bool = False

    def first(self) -> tuple[Argument, ...]:
        """The arguments that come before the command's options: ``--out``."""
        folder = Argument(
            "--out",
            type=Path,
            required=self.required,
            default=self.default,
            metavar=self.metavar,
            dest=self.dest,
            help=self.help,
        )
        return (folder,)

    def last(self) -> tuple[Argument, ...]:
        """The arguments that come after the command's options: ``--force``, ``--resume``, ``--quiet``."""
        quiet = Argument("--quiet", action="store_true", help=self.quiet)
        return (FORCE, RESUME, quiet) if self.resume else (FORCE, quiet)


#: Replace an output folder that irtps did not write (`Output`).
FORCE = Argument(
    "--force",
    action="store_true",
    help="replace OUT even if it is an existing file, or a folder with content that irtps did not write (never an input)",
)

#: Keep the output folders of an earlier batch that are complete (`Output.resume`).
RESUME = Argument(
    "--resume",
    action="store_true",
    help="keep each output folder that is complete (run.json, written last, records the same data set, options and "
    "images left out, and every file it goes with is there) instead of reconstructing it again; others are redone",
)

#: The images of one data set to leave out.
EXCLUDE_IMAGES = Argument(
    "--exclude-images",
    metavar="LIST",
    help="images to leave out (not read): numbers and ranges of numbers that match the images' numbered file names "
    "(1-20,37: DiLiGenT's 001.png ... 020.png and 037.png; the irtps layout's images count from 000.exr), or file "
    "names; for images a light misfired in, that the object moved in, or that cannot be read",
)

#: The perspective camera of one data set.
INTRINSICS = Argument(
    "--intrinsics",
    type=Path,
    metavar="K.txt",
    help="the camera's 3x3 intrinsic matrix in pixels (lines 'fx 0 cx', '0 fy cy', '0 0 1'): DATA is then seen by "
    "that perspective camera, whatever its folder says (a DiLiGenT folder's own K.txt is read without it); renderings "
    "trace through the pinhole, and the steps that take a pixel size use its orthographic stand-in at the object's "
    "distance, and say so",
)

#: The lights of a folder of images, from a light position file kept elsewhere.
LIGHTS = Argument(
    "--lights",
    type=Path,
    metavar="FILE.lp",
    help="a light position file ('irtps calibrate' writes one: a count, then 'filename x y z' per image) that gives "
    "DATA, a folder of images, its lights without copying anything into it: the images it names are read from DATA, "
    "the strengths from the light_intensities.txt beside it (estimated from the images without one); a .lp file "
    "DATA holds is then not read, and a data set whose lights are its own (scene.json, light_directions.txt) is "
    "refused; recorded in run.json with a digest of both files",
)

#: How the images' values map to light.
ENCODING = Argument(
    "--encoding",
    choices=ENCODINGS,
    help="how the images' values map to light, whatever the layout's default: srgb (a camera's JPEG or 8-bit "
    "files) or linear; by default the irtps and DiLiGenT layouts are linear and an RTI folder's 8-bit images sRGB, "
    "its 16-bit and float ones linear; recorded in run.json",
)

#: The convention of the normal map written for other tools.
NORMAL_MAP = Argument(
    "--normal-map",
    choices=NORMAL_MAP_CONVENTIONS,
    default="opengl",
    help="the convention of normal.png, the 16-bit normal map for other tools: opengl (green up the image: Blender, "
    "RTI viewers, Unity) or directx (green down: Unreal, 3ds Max); recorded in run.json (default: opengl)",
)

#: The images to leave out of the commands that take many data sets: of all, or of one by name.
EXCLUDE_IMAGES_BY_NAME = Argument(
    "--exclude-images",
    metavar="[NAME=]LIST",
    action="append",
    default=[],
    help="images to leave out (not read), as for 'irtps reconstruct': LIST for every DATA, NAME=LIST for the DATA "
    "named NAME (its folder's name, as in the summary: bearPNG=1-20); repeat it for more, a data set's lists are joined",
)

#: The perspective cameras of the commands that take many data sets: of all, or of one by name.
INTRINSICS_BY_NAME = Argument(
    "--intrinsics",
    metavar="[NAME=]K.txt",
    action="append",
    default=[],
    help="the camera's 3x3 intrinsic matrix in pixels, as for 'irtps reconstruct': K.txt for every DATA, "
    "NAME=K.txt for the DATA named NAME (its folder's name, as in the summary), which takes it instead; each file "
    "is checked before anything runs, and recorded in run.json (--resume reconstructs again when it changed)",
)

#: The light position files of the commands that take many data sets: of all, or of one by name.
LIGHTS_BY_NAME = Argument(
    "--lights",
    metavar="[NAME=]FILE.lp",
    action="append",
    default=[],
    help="a light position file, as for 'irtps reconstruct': FILE.lp for every DATA, NAME=FILE.lp for the DATA named "
    "NAME (its folder's name, as in the summary), which takes it instead; each file is read before anything runs, "
    "and recorded in run.json with a digest (--resume reconstructs again when it or its intensities changed)",
)

#: How to reconstruct, the options of IRT-PS in a group of their own.
RECONSTRUCT = Options(ReconstructOptions, groups={"IRT-PS": "IRT-PS (--method irtps)"})
#: The Dask cluster of a batch.
CLUSTER = Options(ClusterOptions, title="cluster")
#: How to render.
RENDER = Options(RenderOptions)
#: The scene that ``irtps synth`` makes.
SYNTH = Options(SynthOptions)
#: The comparison table's variants and settings.
TABLE = Options(TableOptions)
