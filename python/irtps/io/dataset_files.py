"""The files of a data set folder: the irtps layout's names, the layout a folder is in (told by
its marker file), and every file and folder each reader of `irtps.io.dataset` reads, found
without decoding an image (`dataset_inputs`, `ground_truth_inputs`, `scene_object_inputs`:
what a command that writes compares its output with).
"""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path
from typing import NamedTuple

from irtps._shared.checks import check_path
from irtps._shared.paths import check_file, check_folder, exists, folder_problem, optional_file, optional_folder
from irtps.errors import ArgumentError, DatasetError
from irtps.io.diligent import diligent_ground_truth_inputs, diligent_image_names, diligent_inputs
from irtps.io.rti import lp_file, rti_image_names, rti_inputs
from irtps.io.image_selection import ImageSelection, parse_image_list, select_images
from irtps.model.data import image_file_name
from irtps.model.environment import MeshEnvironment
from irtps.model.scene import Scene, load_scene

SCENE_FILE = "scene.json"
MASK_FILE = "mask.png"
IMAGES_FOLDER = "images"
GT_FOLDER = "gt"
DILIGENT_MARKER = "light_directions.txt"

_NUMBERED_IMAGE = re.compile(r"\d{3,}\.(exr|png)", re.IGNORECASE)


def is_data_set(path: str | Path) -> bool:
    """Whether `path` is a folder that holds a data set's marker file (``scene.json``,
    DiLiGenT's ``light_directions.txt``, or an RTI folder's ``*.lp``); what it holds is not
    read.

    Examples
    --------
    >>> is_data_set("/")
    False
    """
    if folder_problem(path) is not None:
        return False
    folder = Path(path)
    return exists(folder / SCENE_FILE) or exists(folder / DILIGENT_MARKER) or _has_lp_file(folder)


def dataset_layout(folder: Path, lights: str | Path | None = None) -> str:
    """``"irtps"``, ``"diligent"`` or ``"rti"``: the layout of a data set folder, told by its
    marker file; ``"rti"`` for a folder given its lights in a ``.lp`` file kept elsewhere
    (`lights`, `irtps.io.rti.load_rti`).

    Raises
    ------
    DatasetError
        For a folder that is not a data set.
    ArgumentError
        Naming ``lights``, for a folder in the irtps or the DiLiGenT layout: its lights are
        its own.
    """
    if lights is not None:
        for marker, layout in ((SCENE_FILE, "irtps"), (DILIGENT_MARKER, "DiLiGenT")):
            if exists(folder / marker):
                raise ArgumentError(
                    "lights",
                    f"{folder} is a data set in the {layout} layout, whose {marker} gives its lights; "
                    "a light position file is for a folder of images (an RTI folder)",
                )
        return "rti"
    if exists(folder / SCENE_FILE):
        return "irtps"
    if exists(folder / DILIGENT_MARKER):
        return "diligent"
    if lp_file(folder) is not None:
        return "rti"
    raise _not_a_dataset(folder)


def _has_lp_file(folder: Path) -> bool:
    try:
        return lp_file(folder) is not None
    except DatasetError:  # several: it is one, and reading it says what is wrong
        return True


def _not_a_dataset(folder: Path) -> DatasetError:
    return DatasetError(
        f"{folder}: not a data set: it holds neither {SCENE_FILE} (irtps layout) "
        f"nor {DILIGENT_MARKER} (DiLiGenT layout) nor a *.lp light position file (RTI)"
    )


def dataset_image_names(path: str | Path, *, lights: str | Path | None = None) -> tuple[str, ...]:
    """The file names of every image of a data set folder, in its order, without reading
    them: what a list of images to leave out (`irtps.io.image_selection`) is matched against.

    Parameters
    ----------
    path : str or pathlib.Path
    lights : str or pathlib.Path, optional
        As for `irtps.io.dataset.load_dataset`: the ``.lp`` file that lists the images.

    Raises
    ------
    DatasetError, ArgumentError
        As `irtps.io.dataset.load_dataset`, for a folder that is not a data set or whose
        images are missing.

    Examples
    --------
    >>> import tempfile
    >>> from irtps.io.dataset_writer import save_dataset
    >>> from irtps.render.synth import synthesize
    >>> data, _ = synthesize("cap", size=16, lights=4, bounces=0, environment="none")
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     save_dataset(data, folder + "/cap")
    ...     dataset_image_names(folder + "/cap")
    ('000.exr', '001.exr', '002.exr', '003.exr')
    """
    lights = None if lights is None else check_path("lights", lights)
    folder = check_folder(path)
    layout = dataset_layout(folder, lights)
    if layout == "diligent":
        return diligent_image_names(folder)
    if layout == "rti":
        return rti_image_names(folder, lights)
    scene = load_scene(folder / SCENE_FILE)
    return tuple(image.name for image in _numbered_images(folder / IMAGES_FOLDER, len(scene.lights)))


def dataset_inputs(
    path: str | Path,
    *,
    ground_truth: bool = True,
    exclude_images: str | None = None,
    intrinsics: str | Path | None = None,
    lights: str | Path | None = None,
) -> list[Path]:
    """Every file and folder that `irtps.io.dataset.load_dataset` reads, found by the code
    that reads them (the small files that list the rest are read; no image is decoded).

    What a command that writes compares its output with (`irtps._shared.output_rule`): an image
    listed from outside the data set folder, or a folder of it that is a symbolic link to
    another place, is read all the same.

    Parameters
    ----------
    path, ground_truth, exclude_images, intrinsics, lights
        As for `irtps.io.dataset.load_dataset`.

    Returns
    -------
    list of pathlib.Path
        The data set folder, then the files and folders read, as the reader names them
        (symbolic links not resolved; the light position file `lights` and the intensities
        beside it among them), then the intrinsics file, if given.

    Raises
    ------
    DatasetError, ArgumentError
        As `irtps.io.dataset.load_dataset`, for what is found wrong without decoding an image.

    Examples
    --------
    >>> import tempfile
    >>> from irtps.io.dataset_writer import save_dataset
    >>> from irtps.render.synth import synthesize
    >>> data, _ = synthesize("cap", size=16, lights=3, bounces=0, environment="none")
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     save_dataset(data, folder + "/cap")
    ...     [path.relative_to(folder).as_posix() for path in dataset_inputs(folder + "/cap")][:6]
    ['cap', 'cap/scene.json', 'cap/images', 'cap/images/000.exr', 'cap/images/001.exr', 'cap/images/002.exr']
    """
    if exclude_images is not None:
        parse_image_list(exclude_images)
    camera = [] if intrinsics is None else [check_path("intrinsics", intrinsics)]
    lights = None if lights is None else check_path("lights", lights)
    folder = check_folder(check_path("path", path))
    layout = dataset_layout(folder, lights)
    if layout == "diligent":
        return diligent_inputs(folder, ground_truth=ground_truth, exclude_images=exclude_images) + camera
    if layout == "rti":
        return rti_inputs(folder, exclude_images=exclude_images, lights=lights) + camera
    return irtps_files(folder, ground_truth, exclude_images).paths() + camera


def ground_truth_inputs(path: str | Path) -> list[Path]:
    """Every file and folder that `irtps.io.dataset.load_ground_truth` reads (see
    `dataset_inputs`).

    Raises
    ------
    DatasetError
        As `irtps.io.dataset.load_ground_truth`, for what is found wrong without decoding a
        map.
    """
    folder = check_folder(check_path("path", path))
    layout = dataset_layout(folder)
    if layout == "diligent":
        return diligent_ground_truth_inputs(folder)
    if layout == "rti":
        return [folder]  # an RTI folder holds no ground truth
    scene, truth = ground_truth_files(folder)
    return [folder, *scene_paths(folder / SCENE_FILE, scene), *([] if truth is None else truth.paths())]


def scene_paths(scene_file: Path, scene: Scene) -> list[Path]:
    """``scene.json`` and the files it names: an environment mesh's (contract §3b)."""
    if isinstance(scene.environment, MeshEnvironment):
        return [scene_file, scene_file.parent / scene.environment.file]
    return [scene_file]


def scene_object_inputs(path: str | Path) -> list[Path]:
    """Every file and folder that `irtps.io.dataset.load_scene_object` reads (see
    `dataset_inputs`).

    Raises
    ------
    DatasetError
        As `irtps.io.dataset.load_scene_object`, for what is found wrong without decoding a
        map.
    """
    return scene_object_files(check_folder(check_path("path", path))).paths()


class IrtpsFiles(NamedTuple):
    """What reading a data set folder in the irtps layout reads, found (and ``scene.json``
    parsed) without decoding an image."""

    scene_file: Path
    #: The scene, with the lights of the images kept.
    scene: Scene
    images: list[Path]
    selection: ImageSelection
    mask: Path | None
    truth: TruthFiles | None

    def paths(self) -> list[Path]:
        mask = [] if self.mask is None else [self.mask]
        truth = [] if self.truth is None else self.truth.paths()
        return [
            self.scene_file.parent,
            *scene_paths(self.scene_file, self.scene),
            self.scene_file.parent / IMAGES_FOLDER,
            *self.images,
            *mask,
            *truth,
        ]


def irtps_files(folder: Path, ground_truth: bool, exclude_images: str | None) -> IrtpsFiles:
    """The files that `irtps.io.dataset.load_dataset` reads in `folder` (irtps layout)."""
    scene = load_scene(folder / SCENE_FILE)
    paths = _numbered_images(folder / IMAGES_FOLDER, len(scene.lights))
    selection = select_images([path.name for path in paths], exclude_images, where=str(folder))
    kept = dataclasses.replace(scene, lights=tuple(scene.lights[k] for k in selection.kept))
    mask = _optional_path(folder / MASK_FILE)
    truth = _truth_files(folder / GT_FOLDER, len(scene.lights), selection.kept) if ground_truth else None
    return IrtpsFiles(folder / SCENE_FILE, kept, [paths[k] for k in selection.kept], selection, mask, truth)


class TruthFiles(NamedTuple):
    """The ground-truth files of a data set folder in the irtps layout that are there to read."""

    folder: Path
    height: Path | None
    normal: Path | None
    albedo: Path | None
    #: The direct-light images of the lights kept (none when they are not read).
    direct: list[Path]
    #: A perspective camera's depth map (contract §1b).
    depth: Path | None = None

    def paths(self) -> list[Path]:
        maps = [path for path in (self.height, self.normal, self.albedo, self.depth) if path is not None]
        return [self.folder, *maps, *self.direct]


def _truth_files(folder: Path, count: int, kept: list[int] | None = None, direct: bool = True) -> TruthFiles | None:
    """The ground-truth files in `folder`, if it is there: the maps present and, with
    `direct`, the direct-light images of the lights `kept` (default all `count`)."""
    if not optional_folder(folder):
        return None
    height, normal, albedo, depth = (
        _optional_path(folder / f"{name}.exr") for name in ("height", "normal", "albedo", "depth")
    )
    direct_paths: list[Path] = []
    if direct and optional_folder(folder / "direct"):
        direct_paths = _numbered_images(folder / "direct", count)
        direct_paths = direct_paths if kept is None else [direct_paths[k] for k in kept]
    return TruthFiles(folder, height, normal, albedo, direct_paths, depth)


def ground_truth_files(folder: Path) -> tuple[Scene, TruthFiles | None]:
    """The scene of a data set folder in the irtps layout, and its ground-truth maps."""
    scene = load_scene(folder / SCENE_FILE)
    return scene, _truth_files(folder / GT_FOLDER, len(scene.lights), direct=False)


class SceneObjectFiles(NamedTuple):
    """What `irtps.io.dataset.load_scene_object` reads, found (and ``scene.json`` parsed)
    without decoding a map."""

    scene: Scene
    height: Path
    albedo: Path
    mask: Path | None

    def paths(self) -> list[Path]:
        folder = self.height.parent.parent
        return [
            folder,
            *scene_paths(folder / SCENE_FILE, self.scene),
            self.height.parent,
            self.height,
            self.albedo,
            *([] if self.mask is None else [self.mask]),
        ]


def scene_object_files(folder: Path) -> SceneObjectFiles:
    """The files that `irtps.io.dataset.load_scene_object` reads in `folder`."""
    scene = load_scene(folder / SCENE_FILE)
    height, albedo = folder / GT_FOLDER / "height.exr", folder / GT_FOLDER / "albedo.exr"
    for required in (height, albedo):
        check_file(required, "rendering needs the true height and albedo")
    return SceneObjectFiles(scene, height, albedo, _optional_path(folder / MASK_FILE))


def _numbered_images(folder: Path, count: int) -> list[Path]:
    """``folder/000.exr`` (or ``.png``) ... for ``count`` lights; no more, no fewer."""
    context = f"{SCENE_FILE} has {count} lights, one image each"
    check_folder(folder, missing="missing folder", context=context)
    paths = []
    for k in range(count):
        candidates = [folder / image_file_name(k, suffix) for suffix in (".exr", ".png")]
        present = [candidate for candidate in candidates if exists(candidate)]
        if not present:
            raise DatasetError(f"{candidates[0]}: missing ({context})")
        if len(present) > 1:
            raise DatasetError(f"{folder}: both {present[0].name} and {present[1].name} exist; keep one")
        paths.append(check_file(present[0], context))
    numbered = sorted(entry.name for entry in folder.iterdir() if _NUMBERED_IMAGE.fullmatch(entry.name))
    if len(numbered) > count:
        unexpected = sorted(set(numbered) - {path.name for path in paths})
        raise DatasetError(
            f"{folder}: {len(numbered)} images for {count} lights in {SCENE_FILE} ({unexpected[0]} has no light)"
        )
    return paths


def _optional_path(path: Path) -> Path | None:
    """`path` if an optional file is there to read, None if nothing is at it (`optional_file`)."""
    return path if optional_file(path) else None
