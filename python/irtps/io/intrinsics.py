"""Intrinsics files (``K.txt``): a perspective camera for a data set.

A ``K.txt`` holds a camera's 3×3 intrinsic matrix in pixels, one row a line, numbers
separated by blanks or commas (DiLiGenT's, or ``numpy.savetxt``'s)::

    fx  0  cx
     0 fy  cy
     0  0   1

Pixel (row i, column j) spans ``u`` in [j, j + 1) and ``v`` in [i, i + 1), image columns along
the world's x and rows against its y, as contract §1b says (DiLiGenT's ``K.txt`` and
``depth_gt`` follow it too: docs/data.md). A DiLiGenT folder holding a ``K.txt`` is read as
perspective; ``irtps reconstruct --intrinsics K.txt`` gives any data set that camera.

K does not place the camera in the world. `with_intrinsics` keeps the optical centre of a
perspective scene; for a scene that had an orthographic camera of pixel size ``s`` it puts the
optical centre at ``s * f`` (``f = sqrt(fx * fy)``) above the object's base (the floor, or
0), the distance at which a pixel at the base is ``s`` wide, so that the world units stay the
data set's. DiLiGenT's normals fix the shape only up to scale, and its world unit is one pixel
at the object (``s = 1``), as when it was read as orthographic.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import NamedTuple

from irtps._shared.guarded import read_text
from irtps._shared.paths import check_file
from irtps.errors import DatasetError
from irtps.io.number_lines import three_numbers
from irtps.model.camera import Camera, intrinsics_problem
from irtps.model.scene import Scene

__all__ = ["INTRINSICS_FILE", "Intrinsics", "read_intrinsics", "with_intrinsics"]

#: The name of the intrinsics file in a DiLiGenT folder.
INTRINSICS_FILE = "K.txt"


class Intrinsics(NamedTuple):
    """A camera's intrinsics, in pixels, and the file they were read from."""

    fx: float
    fy: float
    cx: float
    cy: float
    source: Path


def read_intrinsics(path: str | Path) -> Intrinsics:
    """Read and check a ``K.txt``: a 3×3 intrinsic matrix of finite numbers, zero skew,
    positive focal lengths, last row ``0 0 1``. The principal point is checked against an
    image size by `with_intrinsics`.

    Raises
    ------
    DatasetError
        ``"PATH: PROBLEM"``, one line: a missing or unreadable file, not 3 rows of 3 numbers,
        a value that is not a finite number, a non-zero skew or lower-left entry, a last row
        other than ``0 0 1``, a focal length that is not positive.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     path = pathlib.Path(folder) / "K.txt"
    ...     _ = path.write_text("100 0 12\\n0 100 12\\n0 0 1\\n")
    ...     read_intrinsics(path)[:4]
    (100.0, 100.0, 12.0, 12.0)
    """
    path = check_file(path, "intrinsics: a 3x3 matrix in pixels")
    text = read_text(path)
    lines = [(number, line.strip()) for number, line in enumerate(text.splitlines(), start=1) if line.strip()]
    if len(lines) != 3:
        raise DatasetError(f"{path}: expected a 3x3 intrinsic matrix (3 lines of 3 numbers), got {len(lines)} lines")
    rows = [three_numbers(path, number, line) for number, line in lines]
    (fx, skew, cx), (lower, fy, cy), last = rows
    if skew != 0.0:
        raise DatasetError(
            f"{path}: skew K[0][1] = {skew:g}: only cameras whose pixel rows and columns are square to each other (zero skew) are supported"
        )
    if lower != 0.0:
        raise DatasetError(f"{path}: K[1][0] = {lower:g}: an intrinsic matrix has 0 there")
    if last != [0.0, 0.0, 1.0]:
        raise DatasetError(
            f"{path}: the last row is {' '.join(f'{v:g}' for v in last)}: an intrinsic matrix ends in 0 0 1"
        )
    for name, value in (("fx", fx), ("fy", fy)):
        if value <= 0.0:
            raise DatasetError(f"{path}: {name} = {value:g}: a focal length must be a positive number of pixels")
    return Intrinsics(fx, fy, cx, cy, path)


def with_intrinsics(scene: Scene, intrinsics: Intrinsics) -> Scene:
    """`scene` seen by the perspective camera of `intrinsics`, of the same image size.

    The optical centre is the scene's where its camera is perspective; else ``s * f`` above
    `irtps.model.scene.Scene.base_height`, ``s`` the orthographic camera's pixel size and
    ``f = sqrt(fx * fy)`` (see the module's notes).

    Raises
    ------
    DatasetError
        Naming the intrinsics file: a principal point more than
        `irtps.model.camera.PRINCIPAL_POINT_MARGIN` image sizes outside the scene's images
        (`irtps.model.camera.intrinsics_problem`): intrinsics of another image size.
    """
    camera = scene.camera
    fx, fy, cx, cy, source = intrinsics
    problem = intrinsics_problem(fx, fy, cx, cy, (camera.height, camera.width))
    if problem is not None:
        raise DatasetError(f"{source}: {problem[0]} {problem[1]}")
    center = camera.optical_center
    if center is None:
        center = (0.0, 0.0, scene.base_height + camera.orthographic_pixel_size * math.sqrt(fx * fy))
    perspective = Camera(
        camera.width, camera.height, projection="perspective", fx=fx, fy=fy, cx=cx, cy=cy, optical_center=center
    )
    return dataclasses.replace(scene, camera=perspective)
