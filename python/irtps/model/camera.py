"""The camera of a scene (contract §1 and §1b): orthographic, or a perspective pinhole.

Both look along -z in the world frame (x to the right, y up, z toward the camera). An
orthographic camera is centred on the z axis and has a pixel size; a perspective camera has
its intrinsics (``fx``, ``fy``, ``cx``, ``cy``, in pixels) and its optical centre
``(0, 0, zc)``, and no pixel size: a pixel's world size grows with the depth it sees.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from irtps.errors import ArgumentError, DatasetError

__all__ = ["PRINCIPAL_POINT_MARGIN", "PROJECTIONS", "Camera", "intrinsics_problem"]

#: The projections a camera takes, the default first.
PROJECTIONS = ("orthographic", "perspective")

#: How far outside the image the principal point may lie, in image sizes: ``cx`` from
#: ``-W`` to ``2 W``, ``cy`` from ``-H`` to ``2 H``. A crop or a shift lens moves the
#: optical axis off the centre, but a principal point more than a whole image outside it
#: belongs to intrinsics of another image size (a K of the full sensor given to a copy
#: reduced 4x puts it near ``2 W``) or to a slip.
PRINCIPAL_POINT_MARGIN = 1.0

_INTRINSICS = ("fx", "fy", "cx", "cy")


@dataclass(frozen=True, repr=False)
class Camera:
    """The camera of a scene: orthographic (the default) or perspective.

    Attributes
    ----------
    width, height : int
        Image size in pixels.
    pixel_size : float or None
        Orthographic: the side of a pixel's square footprint, in world units. None for a
        perspective camera, whose pixels have no one world size (`orthographic_stand_in`
        gives the orthographic camera that matches it at one depth).
    projection : str
        ``"orthographic"`` or ``"perspective"`` (`PROJECTIONS`).
    fx, fy, cx, cy : float or None
        Perspective: focal lengths and principal point, in pixels (pixel (i, j) spans
        ``u`` in [j, j + 1) and ``v`` in [i, i + 1)); None for an orthographic camera.
    optical_center : tuple of float or None
        Perspective: the pinhole, the world point ``(0, 0, zc)``; None for an orthographic
        camera.
    pinhole : Camera or None
        An orthographic stand-in's perspective camera (`orthographic_stand_in`): the steps
        that fit, integrate and place orthographically take the stand-in's pixel size, and
        the renderer traces through this pinhole. None otherwise.

    Raises
    ------
    DatasetError
        On construction, naming the field: a projection not in `PROJECTIONS`; an orthographic
        camera without ``pixel_size`` or with a perspective field; a perspective camera with
        ``pixel_size``, without one of its fields, with a focal length that is not a positive
        finite number, a principal point more than `PRINCIPAL_POINT_MARGIN` image sizes
        outside the image (`intrinsics_problem`), or an optical centre off the z axis; a
        ``pinhole`` on a perspective camera, or one that is not a perspective camera of the
        same image size.

    Examples
    --------
    >>> Camera(4, 2, 0.5).pixel_size
    0.5
    >>> camera = Camera(4, 2, projection="perspective", fx=8.0, fy=8.0, cx=2.0, cy=1.0,
    ...                 optical_center=(0.0, 0.0, 10.0))
    >>> camera.ray_directions()[0, 0].tolist()
    [-0.1875, 0.0625, -1.0]
    >>> camera.orthographic_stand_in(4.0).pixel_size
    0.5
    """

    width: int
    height: int
    pixel_size: float | None = None
    projection: str = "orthographic"
    fx: float | None = None
    fy: float | None = None
    cx: float | None = None
    cy: float | None = None
    optical_center: tuple[float, float, float] | None = None
    pinhole: Camera | None = None

    def __post_init__(self) -> None:
        if self.projection not in PROJECTIONS:
            raise DatasetError(f"Camera.projection is {self.projection!r}: expected one of {', '.join(PROJECTIONS)}")
        perspective = {name: getattr(self, name) for name in (*_INTRINSICS, "optical_center")}
        if self.projection == "orthographic":
            if self.pixel_size is None:
                raise DatasetError("Camera.pixel_size is missing: an orthographic camera needs it")
            given = [name for name, value in perspective.items() if value is not None]
            if given:
                raise DatasetError(f"Camera.{given[0]} is given: only a perspective camera has it")
            pinhole = self.pinhole
            if pinhole is not None and not (
                isinstance(pinhole, Camera)
                and pinhole.projection == "perspective"
                and (pinhole.width, pinhole.height) == (self.width, self.height)
            ):
                raise DatasetError(
                    f"Camera.pinhole is {pinhole!r}: expected the perspective camera of a {self.width}x{self.height} "
                    "image that this orthographic camera stands in for"
                )
            return
        if self.pinhole is not None:
            raise DatasetError("Camera.pinhole is given: only an orthographic stand-in has it")
        if self.pixel_size is not None:
            raise DatasetError("Camera.pixel_size is given: a perspective camera has none (it has fx, fy, cx, cy)")
        missing = [name for name, value in perspective.items() if value is None]
        if missing:
            raise DatasetError(f"Camera.{missing[0]} is missing: a perspective camera needs it")
        fx, fy, cx, cy = (float(perspective[name]) for name in _INTRINSICS)
        problem = intrinsics_problem(fx, fy, cx, cy, (self.height, self.width))
        if problem is not None:
            raise DatasetError(f"Camera.{problem[0]} {problem[1]}")
        for name, value in zip(_INTRINSICS, (fx, fy, cx, cy), strict=True):
            object.__setattr__(self, name, value)
        center = tuple(float(value) for value in np.ravel(np.asarray(self.optical_center, dtype=np.float64)))
        if len(center) != 3 or not all(map(math.isfinite, center)) or center[:2] != (0.0, 0.0):
            raise DatasetError(
                f"Camera.optical_center must be (0, 0, zc), finite: the contract puts the pinhole on the z axis, got {self.optical_center!r}"
            )
        object.__setattr__(self, "optical_center", center)

    def __repr__(self) -> str:
        if self.projection == "orthographic":
            fields: dict[str, object] = {"width": self.width, "height": self.height, "pixel_size": self.pixel_size}
            if self.pinhole is not None:
                fields["pinhole"] = self.pinhole
        else:
            names = ("width", "height", "projection", *_INTRINSICS, "optical_center")
            fields = {name: getattr(self, name) for name in names}
        return f"Camera({', '.join(f'{name}={value!r}' for name, value in fields.items())})"

    @property
    def orthographic_pixel_size(self) -> float:
        """`pixel_size`, for the steps that trace or integrate only orthographically.

        Raises
        ------
        ArgumentError
            For a perspective camera: those steps take its stand-in
            (`irtps.model.scene.orthographic_scene`).
        """
        if self.pixel_size is None:
            raise ArgumentError(
                "camera",
                "is perspective: this step traces or integrates orthographically only (give it the camera's orthographic_stand_in)",
            )
        return self.pixel_size

    @property
    def center_z(self) -> float:
        """A perspective camera's optical centre height ``zc`` (`optical_center` is
        ``(0, 0, zc)``).

        Raises
        ------
        ArgumentError
            For an orthographic camera.
        """
        if self.optical_center is None:
            raise ArgumentError("camera", "is orthographic: it has no optical centre (a perspective camera has)")
        return self.optical_center[2]

    @property
    def focal_length(self) -> float:
        """A perspective camera's focal length in pixels, ``sqrt(fx * fy)``: that of the
        square pixels of `orthographic_stand_in`."""
        fx, fy, _, _ = self._intrinsics("focal_length")
        return math.sqrt(fx * fy)

    def intrinsics(self) -> np.ndarray:
        """The intrinsic matrix K of a perspective camera, float64 (3, 3):
        ``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]``.

        Raises
        ------
        ArgumentError
            For an orthographic camera.
        """
        fx, fy, cx, cy = self._intrinsics("intrinsics")
        return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])

    def ray_directions(self) -> np.ndarray:
        """The direction of each pixel's centre ray, in the world frame (contract §1b).

        Returns
        -------
        numpy.ndarray
            float64 (height, width, 3). Perspective: pixel (i, j)'s ray leaves the optical
            centre along ``((j + 0.5 - cx) / fx, -(i + 0.5 - cy) / fy, -1)``, so that the
            point at depth ``d`` along the optical axis is ``optical_center + d * direction``.
            Orthographic: ``(0, 0, -1)`` for every pixel.
        """
        rays = np.zeros((self.height, self.width, 3))
        rays[..., 2] = -1.0
        if self.projection == "perspective":
            fx, fy, cx, cy = self._intrinsics("ray_directions")
            rays[..., 0] = ((np.arange(self.width) + 0.5 - cx) / fx)[None, :]
            rays[..., 1] = (-(np.arange(self.height) + 0.5 - cy) / fy)[:, None]
        return rays

    def view_directions(self) -> np.ndarray:
        """The unit direction from each pixel's surface point toward the camera.

        Returns
        -------
        numpy.ndarray
            float64 (height, width, 3): perspective, each pixel's centre ray reversed and
            normalised (`ray_directions`); orthographic, ``(0, 0, 1)`` for every pixel.
        """
        rays = -self.ray_directions()
        return rays / np.linalg.norm(rays, axis=-1, keepdims=True)

    def surface_points(self, height: np.ndarray) -> np.ndarray:
        """The world point each pixel sees at its height.

        Parameters
        ----------
        height : numpy.ndarray
            (height, width) heights z of each pixel's surface point.

        Returns
        -------
        numpy.ndarray
            float64 (height, width, 3). Perspective (or an orthographic stand-in, through its
            `pinhole`): the point of height z on the pixel's centre ray, at depth
            ``zc - z`` (contract §1b); orthographic: the pixel centre at height z.
        """
        camera = self.pinhole if self.pinhole is not None else self
        z = np.asarray(height, dtype=np.float64)
        if camera.projection == "perspective":
            depth = camera.center_z - z
            points = camera.ray_directions() * depth[..., None]
            points[..., 2] += camera.center_z
            return points
        x, y = camera.pixel_centers()
        return np.stack([x, y, z], axis=-1)

    def pixel_centers(self) -> tuple[np.ndarray, np.ndarray]:
        """World coordinates of the pixel centres of an orthographic camera.

        Returns
        -------
        x, y : numpy.ndarray
            Two float64 arrays of shape (height, width): pixel (i, j) is centred at
            ``x = (j + 0.5 - W/2) * s`` and ``y = (H/2 - i - 0.5) * s``.

        Raises
        ------
        ArgumentError
            For a perspective camera, whose pixels see points that depend on their depth
            (`ray_directions`).
        """
        if self.pixel_size is None:
            raise ArgumentError(
                "camera", "is perspective: its pixel centres depend on the depth they see (use ray_directions)"
            )
        s = self.pixel_size
        x_row = (np.arange(self.width) + 0.5 - self.width / 2) * s
        y_column = (self.height / 2 - np.arange(self.height) - 0.5) * s
        return np.meshgrid(x_row, y_column)

    def orthographic_stand_in(self, depth: float) -> Camera:
        """The orthographic camera that matches this one at `depth` along the optical axis:
        the same image size, and a pixel size of ``depth / focal_length`` (a pixel's footprint
        at that depth). The principal point and the difference between ``fx`` and ``fy`` are
        left out: it is an approximation, for the steps that fit, integrate or place only
        orthographically; its `pinhole` is this camera, through which renderings trace. An
        orthographic camera is its own stand-in.

        Raises
        ------
        ArgumentError
            If `depth` is not a positive finite number.
        """
        if self.projection == "orthographic":
            return self
        if not (isinstance(depth, (int, float, np.floating, np.integer)) and math.isfinite(depth) and depth > 0):
            raise ArgumentError("depth", f"expected a positive finite number, got {depth!r}")
        return Camera(self.width, self.height, float(depth) / self.focal_length, pinhole=self)

    def _intrinsics(self, what: str) -> tuple[float, float, float, float]:
        """fx, fy, cx, cy of a perspective camera; `ArgumentError` naming `what` for an
        orthographic one."""
        if self.fx is None or self.fy is None or self.cx is None or self.cy is None:
            raise ArgumentError("camera", f"is orthographic: it has no {what} (a perspective camera has)")
        return self.fx, self.fy, self.cx, self.cy


def intrinsics_problem(fx: float, fy: float, cx: float, cy: float, size: tuple[int, int]) -> tuple[str, str] | None:
    """What makes intrinsics unusable for images of `size` (H, W), as (field, problem), or
    None: a focal length that is not a positive finite number, a principal point that is not
    finite or lies more than `PRINCIPAL_POINT_MARGIN` image sizes outside the image.

    Examples
    --------
    >>> intrinsics_problem(100.0, 100.0, 12.0, 12.0, (24, 24)) is None
    True
    >>> intrinsics_problem(3772.0, 3759.0, 305.875, 255.125, (24, 24))
    ('cx', '= 305.875 lies more than 1 image width outside the image, 24 pixels wide (expected -24 to 48): intrinsics of another image size?')
    """
    for name, value in (("fx", fx), ("fy", fy)):
        if not (math.isfinite(value) and value > 0.0):
            return name, f"= {value:g}: a focal length must be a positive finite number of pixels"
    height, width = size
    for name, value, extent, side in (("cx", cx, width, "width"), ("cy", cy, height, "height")):
        if not math.isfinite(value):
            return name, f"= {value:g}: the principal point must be finite"
        low, high = -PRINCIPAL_POINT_MARGIN * extent, (1.0 + PRINCIPAL_POINT_MARGIN) * extent
        if not low <= value <= high:
            span = f"{extent} pixels {'wide' if side == 'width' else 'high'}"
            return name, (
                f"= {value:g} lies more than {PRINCIPAL_POINT_MARGIN:g} image {side} outside the image, {span} "
                f"(expected {low:g} to {high:g}): intrinsics of another image size?"
            )
    return None
