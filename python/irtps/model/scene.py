"""The scene description of a data set (``scene.json``, contract ``irtps.scene/1``).

The world frame is right-handed: x to the right, y up, z toward the camera. The
camera (`irtps.model.camera`) looks along -z: orthographic, or a perspective pinhole.
"""

from __future__ import annotations

import dataclasses
import json
import math
import numbers
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import NoReturn

import numpy as np

from irtps._shared.checks import check_path
from irtps._shared.atomic import atomic_write_text
from irtps.errors import DatasetError, IrtpsWarning
from irtps.model.camera import Camera, intrinsics_problem
from irtps.model.environment import MeshEnvironment, read_environment_mesh, view_problem, write_environment_mesh
from irtps.model.constants import MAX_IMAGE_PIXELS
from irtps._shared.guarded import read_json, shown
from irtps._shared.paths import exists

FORMAT = "irtps.scene/1"
"""The value of the ``format`` field this version reads and writes."""

MIN_LIGHTS = 3
"""Photometric stereo needs at least three lights."""

UNIT_TOLERANCE = 1e-3
"""How far the norm of a light direction may be from 1."""

_WALLS = ("left", "right", "back", "front")
_SCENE_KEYS = ("format", "camera", "lights", "floor", "environment")
#: Values of the optional top-level ``irradiance`` field.
IRRADIANCE_KINDS = ("absolute", "relative")
_BOX_KEYS = ("type", "x", "y", "z_top", "albedo")
#: The fields of each projection's ``camera`` object besides ``projection`` (contract §1, §1b).
_CAMERA_KEYS = {
    "orthographic": ("width", "height", "pixel_size"),
    "perspective": ("width", "height", "fx", "fy", "cx", "cy", "optical_center"),
}


@dataclass(frozen=True, eq=False)
class Light:
    """A distant directional light.

    Attributes
    ----------
    direction : numpy.ndarray
        Unit vector (3,) from the surface toward the light, z > 0. Read-only.
    irradiance : numpy.ndarray
        RGB irradiance (3,) on a surface facing the light. Read-only.
    """

    direction: np.ndarray
    irradiance: np.ndarray

    def __post_init__(self) -> None:
        for name in ("direction", "irradiance"):
            vector = np.array(getattr(self, name), dtype=np.float64)
            if vector.shape != (3,):
                raise DatasetError(f"Light.{name} must have 3 components, got shape {vector.shape}")
            vector.flags.writeable = False
            object.__setattr__(self, name, vector)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Light):
            return NotImplemented
        return bool(
            np.array_equal(self.direction, other.direction) and np.array_equal(self.irradiance, other.irradiance)
        )

    def __hash__(self) -> int:
        return hash((tuple(self.direction), tuple(self.irradiance)))


@dataclass(frozen=True, eq=False)
class PointLight:
    """An isotropic point light near the object (contract §4b): a surface point p at
    distance r from it, with unit vector l toward it, receives ``intensity · max(0, n·l) / r²``.

    Attributes
    ----------
    position : numpy.ndarray
        World position (3,). Read-only.
    intensity : numpy.ndarray
        RGB radiant intensity (3,), W/sr. Read-only.
    """

    position: np.ndarray
    intensity: np.ndarray

    def __post_init__(self) -> None:
        for name in ("position", "intensity"):
            vector = np.array(getattr(self, name), dtype=np.float64)
            if vector.shape != (3,):
                raise DatasetError(f"PointLight.{name} must have 3 components, got shape {vector.shape}")
            vector.flags.writeable = False
            object.__setattr__(self, name, vector)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, PointLight):
            return NotImplemented
        return bool(np.array_equal(self.position, other.position) and np.array_equal(self.intensity, other.intensity))

    def __hash__(self) -> int:
        return hash((tuple(self.position), tuple(self.intensity)))


@dataclass(frozen=True)
class Floor:
    """The plane ``z = height`` with a uniform RGB albedo in [0, 1]."""

    height: float
    albedo: tuple[float, float, float]

    def __post_init__(self) -> None:
        object.__setattr__(self, "albedo", tuple(float(v) for v in self.albedo))


@dataclass(frozen=True)
class CornellBox:
    """Four Lambertian walls from the floor up to ``z_top``, open at the top.

    The left wall is at ``x = x[0]``, the right at ``x = x[1]``, the front at
    ``y = y[0]`` and the back at ``y = y[1]``; each faces the inside and is black
    outside. Albedos are RGB triples in [0, 1].
    """

    x: tuple[float, float]
    y: tuple[float, float]
    z_top: float
    albedo_left: tuple[float, float, float]
    albedo_right: tuple[float, float, float]
    albedo_back: tuple[float, float, float]
    albedo_front: tuple[float, float, float]

    def __post_init__(self) -> None:
        for name in ("x", "y", *(f"albedo_{wall}" for wall in _WALLS)):
            object.__setattr__(self, name, tuple(float(v) for v in getattr(self, name)))


@dataclass(frozen=True)
class Scene:
    """Camera, lights and surroundings of a data set.

    Attributes
    ----------
    camera : Camera
    lights : tuple of Light or PointLight
        Image k of the data set is taken under ``lights[k]`` alone: a distant light, or a
        point light near the object.
    floor : Floor or None
        None means there is no floor.
    environment : CornellBox, MeshEnvironment or None
        None means nothing surrounds the object and the floor.
    relative_irradiance : bool
        The lights' irradiance is known only up to one common factor (``"irradiance":
        "relative"`` in ``scene.json``; DiLiGenT's intensities): the fitted albedo is the
        reflectance over that factor, which IRT-PS estimates (`irtps.render.radiometry`).
    """

    camera: Camera
    lights: tuple[Light | PointLight, ...]
    floor: Floor | None = None
    environment: CornellBox | MeshEnvironment | None = None
    relative_irradiance: bool = False

    def __post_init__(self) -> None:
        object.__setattr__(self, "lights", tuple(self.lights))
        if self.camera.optical_center is not None and self.camera.optical_center[2] <= self.base_height:
            raise DatasetError(
                f"Scene.camera.optical_center {_optical_center_problem(self.camera.optical_center[2], self.base_height)}"
            )
        if isinstance(self.environment, MeshEnvironment):
            center = self.camera.optical_center
            problem = view_problem(self.environment, None if center is None else center[2], self.base_height)
            if problem is not None:
                raise DatasetError(f"Scene.environment ({self.environment.file}) {problem}")

    @property
    def base_height(self) -> float:
        """The height the object stands on: the floor's, 0 where there is no floor (the
        contract's skirts run down to it)."""
        return 0.0 if self.floor is None else self.floor.height

    @property
    def has_point_lights(self) -> bool:
        """Whether any light is a point light near the object (contract §4b)."""
        return any(isinstance(light, PointLight) for light in self.lights)

    @property
    def light_directions(self) -> np.ndarray:
        """Unit light directions, float64 array (K, 3), of distant lights.

        Raises
        ------
        DatasetError
            If a light is a point light, whose direction changes across the object.
        """
        return np.stack([self._distant(k).direction for k in range(len(self.lights))])

    @property
    def light_irradiance(self) -> np.ndarray:
        """RGB irradiance of each distant light, float64 array (K, 3).

        Raises
        ------
        DatasetError
            If a light is a point light, whose irradiance changes across the object.
        """
        return np.stack([self._distant(k).irradiance for k in range(len(self.lights))])

    @property
    def light_emission(self) -> np.ndarray:
        """float64 (K, 3): each distant light's irradiance, each point light's intensity."""
        return np.stack([emission_of(light) for light in self.lights])

    @property
    def light_positions(self) -> np.ndarray:
        """float64 (K, 3): each point light's position, NaN for a distant light."""
        return np.stack(
            [light.position if isinstance(light, PointLight) else np.full(3, np.nan) for light in self.lights]
        )

    @property
    def nominal_light_directions(self) -> np.ndarray:
        """float64 (K, 3): each distant light's direction, and the unit vector from the world
        origin (under the object) toward each point light: to tell which lights lie apart."""
        return np.stack(
            [
                light.position / max(float(np.linalg.norm(light.position)), 1e-300)
                if isinstance(light, PointLight)
                else light.direction
                for light in self.lights
            ]
        )

    def _distant(self, k: int) -> Light:
        light = self.lights[k]
        if isinstance(light, PointLight):
            raise DatasetError(
                f"lights[{k}] is a point light (at {light.position.tolist()}): its direction and irradiance "
                "change across the object, and this step takes distant lights only (point lights are "
                "rendered, not yet fitted)"
            )
        return light


def parse_scene(obj: object, source: str = "scene.json", folder: str | Path | None = None) -> Scene:
    """Validate a parsed ``scene.json`` and build the scene.

    Parameters
    ----------
    obj : object
        The parsed JSON value.
    source : str
        Name of the file it came from, used as the prefix of error messages.
    folder : str or pathlib.Path, optional
        The data set folder, where an environment mesh's file is read (contract §3b); by
        default the folder of `source`.

    Returns
    -------
    Scene

    Raises
    ------
    DatasetError
        If any field is missing, of the wrong JSON type, unknown or out of range;
        the message names the field path, e.g. ``lights[3].direction``. An environment
        mesh that cannot be read, or that hides the object from the camera, is named by its
        file.
    """
    fields = _Fields(source)
    scene_format = fields.mapping(obj, "", required=("format",), optional=(*_SCENE_KEYS, "irradiance"))["format"]
    if scene_format != FORMAT:
        fields.fail("format", f"is {shown(scene_format)}: unknown format (expected {FORMAT!r})")
    root = fields.mapping(obj, "", required=_SCENE_KEYS, optional=("irradiance",))
    irradiance = root.get("irradiance", "absolute")
    if irradiance not in IRRADIANCE_KINDS:
        fields.fail("irradiance", f"is {shown(irradiance)}: expected one of {', '.join(map(repr, IRRADIANCE_KINDS))}")
    camera = _parse_camera(fields, root["camera"])
    lights = _parse_lights(fields, root["lights"])
    floor = None if root["floor"] is None else _parse_floor(fields, root["floor"])
    floor_height = 0.0 if floor is None else floor.height
    folder = Path(source).parent if folder is None else Path(folder)
    environment = _parse_environment(fields, root["environment"], floor_height, folder)
    if camera.optical_center is not None and camera.optical_center[2] <= floor_height:
        fields.fail("camera.optical_center", _optical_center_problem(camera.optical_center[2], floor_height))
    if isinstance(environment, MeshEnvironment):
        center = camera.optical_center
        problem = view_problem(environment, None if center is None else center[2], floor_height)
        if problem is not None:
            raise DatasetError(f"{folder / environment.file}: {problem}")
    return Scene(
        camera=camera, lights=lights, floor=floor, environment=environment, relative_irradiance=irradiance == "relative"
    )


#: What the warning of `orthographic_scene` says, up to the stand-in's pixel size.
STAND_IN_WARNING = "the perspective camera is fitted, integrated and placed as an orthographic camera of pixel size"


def orthographic_scene(scene: Scene, where: str) -> Scene:
    """The scene as the steps that fit, integrate or place only orthographically see it.

    `scene` itself when its camera is orthographic. For a perspective camera, the same scene
    seen by the camera's orthographic stand-in (`irtps.model.camera.Camera.orthographic_stand_in`,
    whose renderings trace through the pinhole)
    at the depth of the object's base: the optical centre's height minus `Scene.base_height`
    (the floor's, or 0), a pixel size of that depth over the focal length; with an
    `IrtpsWarning` that says so. (A camera given by its intrinsics alone, DiLiGenT's ``K.txt``,
    has its optical centre where that pixel size is the data set's, 1 for DiLiGenT:
    `irtps.io.intrinsics`.)

    Parameters
    ----------
    scene : Scene
    where : str
        What the scene belongs to (a data set folder), named by the warning.

    Raises
    ------
    DatasetError
        Naming `where`: a stand-in whose pixel size is outside the range of an orthographic
        camera's (`MIN_PIXEL_SIZE` to `MAX_PIXEL_SIZE`).

    Warns
    -----
    IrtpsWarning
        For a perspective camera, naming `where`, the stand-in's pixel size and depth.
    """
    stand_in = stand_in_scene(scene, where)
    if stand_in is not scene:
        depth = scene.camera.center_z - scene.base_height
        warnings.warn(
            f"{where}: {STAND_IN_WARNING} {stand_in.camera.pixel_size:.6g} (its pixel footprint at the object's base, "
            f"{depth:g} from the optical centre); renderings trace through the pinhole",
            IrtpsWarning,
            stacklevel=3,
        )
    return stand_in


def stand_in_scene(scene: Scene, where: str) -> Scene:
    """`orthographic_scene` without its warning: the renderer's view of a perspective scene
    (it traces through the stand-in's `pinhole` and sets its tolerances by the stand-in's
    pixel size).

    Raises
    ------
    DatasetError
        As `orthographic_scene`.
    """
    camera = scene.camera
    if camera.optical_center is None:
        return scene
    depth = camera.optical_center[2] - scene.base_height
    stand_in = camera.orthographic_stand_in(depth)
    if not MIN_PIXEL_SIZE <= stand_in.orthographic_pixel_size <= MAX_PIXEL_SIZE:
        raise DatasetError(
            f"{where}: the perspective camera's orthographic stand-in has pixel size {stand_in.pixel_size:g} "
            f"(depth {depth:g} over focal length {camera.focal_length:g}), out of range: expected "
            f"{MIN_PIXEL_SIZE:g} to {MAX_PIXEL_SIZE:g}"
        )
    return dataclasses.replace(scene, camera=stand_in)


def scene_to_dict(scene: Scene) -> dict:
    """The JSON object of a scene; ``parse_scene`` inverts it exactly.

    Parameters
    ----------
    scene : Scene

    Returns
    -------
    dict
        Plain Python values (dict, list, str, int, float, None), with ``format``.
    """
    return {
        "format": FORMAT,
        "camera": camera_to_dict(scene.camera),
        "lights": [_light_to_dict(light) for light in scene.lights],
        "floor": None
        if scene.floor is None
        else {"height": float(scene.floor.height), "albedo": _floats(scene.floor.albedo)},
        "environment": _environment_to_dict(scene.environment),
    } | ({"irradiance": "relative"} if scene.relative_irradiance else {})


def load_scene(path: str | Path) -> Scene:
    """Read and validate a ``scene.json`` file.

    Parameters
    ----------
    path : str or pathlib.Path

    Returns
    -------
    Scene

    Raises
    ------
    DatasetError
        If the file is missing, not a readable regular file (a directory, a FIFO, a
        symlink loop ...; checked before opening it), is not valid JSON (the message gives
        the line and column) or is JSON past the bounds of `irtps._shared.guarded` (nesting, digits,
        size, repeated keys), or does not follow the contract.
    """
    path = check_path("path", path)
    if not exists(path):
        raise DatasetError(f"{path}: file not found")
    obj = read_json(path)
    return parse_scene(obj, str(path))


def write_scene(scene: Scene, path: str | Path) -> None:
    """Validate a scene and write it atomically as ``scene.json``; an environment mesh is
    written beside it, under its ``file`` name (contract §3b), first.

    Parameters
    ----------
    scene : Scene
    path : str or pathlib.Path

    Raises
    ------
    DatasetError
        If the scene breaks the contract (the file is then not written).
    """
    obj = scene_to_dict(scene)
    path = Path(path)
    if isinstance(scene.environment, MeshEnvironment):
        write_environment_mesh(scene.environment, path.parent / scene.environment.file)
    parse_scene(obj, str(path))
    atomic_write_text(path, json.dumps(obj, indent=1) + "\n")


#: Range of a pixel's world size. The core's geometry is float32; it renders in a frame of
#: one unit a pixel (z from the middle of the object's heights), so every pixel size in the
#: range renders alike, and the squares of world coordinates (up to the image size times
#: this) stay finite and above float32's smallest normal number.
MIN_PIXEL_SIZE, MAX_PIXEL_SIZE = 1e-9, 1e9


#: Range of each positive channel of a light's irradiance (0 is a channel the light lacks).
#: The core works in float32: the images divided by the irradiance, the albedo fitted in its
#: units (relative irradiance) and the renderings of albedo times irradiance must stay finite
#: and above its smallest normal number (at 1e-40 the residual's ratios overflowed).
MIN_IRRADIANCE, MAX_IRRADIANCE = 1e-9, 1e9


def upward_problem(z: float) -> str | None:
    """Why a light direction whose z component is `z` does not point toward the camera side,
    or None: z must be above 0 as the core holds it, in float32.

    Examples
    --------
    >>> upward_problem(0.5) is None
    True
    >>> upward_problem(1e-50)
    'must point toward the camera side (z > 0), got z = 1e-50, which is 0 in float32'
    """
    if np.float32(z) > 0.0:
        return None
    zero = ", which is 0 in float32" if z > 0.0 else ""
    return f"must point toward the camera side (z > 0), got z = {z:g}{zero}"


def irradiance_problem(irradiance) -> str | None:
    """What makes an RGB irradiance unusable, or None: a negative channel, or a positive one
    outside [`MIN_IRRADIANCE`, `MAX_IRRADIANCE`].

    Examples
    --------
    >>> irradiance_problem([1.0, 0.0, 2.5]) is None
    True
    >>> irradiance_problem([1e308, 1.0, 1.0])
    'has channel 0 = 1e+308, out of range: expected 0 or a number from 1e-09 to 1e+09'
    """
    values = [float(value) for value in irradiance]
    if min(values) < 0.0:
        return f"must not be negative, got {values}"
    for channel, value in enumerate(values):
        if value != 0.0 and not MIN_IRRADIANCE <= value <= MAX_IRRADIANCE:
            return f"has channel {channel} = {value:g}, out of range: expected 0 or a number from {MIN_IRRADIANCE:g} to {MAX_IRRADIANCE:g}"
    return None


def _parse_camera(fields: _Fields, value: object) -> Camera:
    kind = fields.mapping(
        value, "camera", required=("projection",), optional=_CAMERA_KEYS["perspective"] + ("pixel_size",)
    )
    projection = kind["projection"]
    if projection not in _CAMERA_KEYS:
        fields.fail(
            "camera.projection", f"is {shown(projection)}: expected one of {', '.join(map(repr, _CAMERA_KEYS))}"
        )
    camera = fields.mapping(value, "camera", required=("projection", *_CAMERA_KEYS[projection]))
    width = fields.positive_int(camera["width"], "camera.width")
    height = fields.positive_int(camera["height"], "camera.height")
    if width * height > MAX_IMAGE_PIXELS:
        fields.fail("camera", f"size {width}x{height} exceeds the largest supported image ({MAX_IMAGE_PIXELS} pixels)")
    if projection == "perspective":
        return _parse_perspective(fields, camera, width, height)
    pixel_size = fields.positive_number(camera["pixel_size"], "camera.pixel_size")
    if not MIN_PIXEL_SIZE <= pixel_size <= MAX_PIXEL_SIZE:
        fields.fail(
            "camera.pixel_size",
            f"{pixel_size:g} is out of range: expected a number from {MIN_PIXEL_SIZE:g} to {MAX_PIXEL_SIZE:g} (world units per pixel)",
        )
    return Camera(width=width, height=height, pixel_size=pixel_size)


def _parse_perspective(fields: _Fields, camera: dict, width: int, height: int) -> Camera:
    """The perspective camera of contract §1b, from its checked ``camera`` object."""
    fx, fy, cx, cy = (fields.number(camera[name], f"camera.{name}") for name in ("fx", "fy", "cx", "cy"))
    problem = intrinsics_problem(fx, fy, cx, cy, (height, width))
    if problem is not None:
        fields.fail(f"camera.{problem[0]}", problem[1])
    center = fields.vector3(camera["optical_center"], "camera.optical_center")
    if center[:2] != (0.0, 0.0):
        fields.fail("camera.optical_center", f"must be [0, 0, zc] (the pinhole on the z axis), got {list(center)}")
    return Camera(width, height, projection="perspective", fx=fx, fy=fy, cx=cx, cy=cy, optical_center=center)


def _optical_center_problem(zc: float, base_height: float) -> str:
    return f"is at height {zc:g}, not above the object's base ({base_height:g}: the floor, or 0 without one)"


def camera_to_dict(camera: Camera) -> dict:
    """The JSON object of a camera, as ``scene.json`` holds it (contract §1, §1b); an
    orthographic stand-in's is its own (orthographic) one."""
    size = {"width": int(camera.width), "height": int(camera.height)}
    if camera.pixel_size is not None:
        return {"projection": "orthographic", **size, "pixel_size": float(camera.pixel_size)}
    return {
        "projection": "perspective",
        **size,
        **{name: float(getattr(camera, name)) for name in ("fx", "fy", "cx", "cy")},
        "optical_center": _floats(camera.optical_center),
    }


def _parse_lights(fields: _Fields, value: object) -> tuple[Light | PointLight, ...]:
    entries = fields.array(value, "lights")
    if len(entries) < MIN_LIGHTS:
        fields.fail("lights", f"has {len(entries)} lights: photometric stereo needs at least {MIN_LIGHTS}")
    lights: list[Light | PointLight] = []
    for k, entry in enumerate(entries):
        where = f"lights[{k}]"
        if isinstance(entry, dict) and "type" in entry:
            kind = entry["type"]
            if kind != "point":
                fields.fail(f"{where}.type", f"is {shown(kind)}: expected 'point' (a distant light has no type)")
            lights.append(_parse_point_light(fields, entry, where))
            continue
        light = fields.mapping(entry, where, required=("direction", "irradiance"))
        direction = fields.vector3(light["direction"], f"{where}.direction")
        norm = math.hypot(*direction)
        if abs(norm - 1.0) > UNIT_TOLERANCE:
            fields.fail(f"{where}.direction", f"is not a unit vector (norm {norm:.6g})")
        upward = upward_problem(direction[2])
        if upward is not None:
            fields.fail(f"{where}.direction", upward)
        irradiance = fields.vector3(light["irradiance"], f"{where}.irradiance")
        problem = irradiance_problem(irradiance)
        if problem is not None:
            fields.fail(f"{where}.irradiance", problem)
        lights.append(Light(direction=np.array(direction), irradiance=np.array(irradiance)))
    return tuple(lights)


def _parse_point_light(fields: _Fields, entry: dict, where: str) -> PointLight:
    light = fields.mapping(entry, where, required=("type", "position", "intensity"))
    position = fields.vector3(light["position"], f"{where}.position")
    intensity = fields.vector3(light["intensity"], f"{where}.intensity")
    problem = irradiance_problem(intensity)
    if problem is not None:
        fields.fail(f"{where}.intensity", problem)
    return PointLight(position=np.array(position), intensity=np.array(intensity))


def _light_to_dict(light: Light | PointLight) -> dict:
    if isinstance(light, PointLight):
        return {"type": "point", "position": _floats(light.position), "intensity": _floats(light.intensity)}
    return {"direction": _floats(light.direction), "irradiance": _floats(light.irradiance)}


def lights_at(scene: Scene, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each light's unit direction and irradiance at world points.

    A distant light's are its own everywhere; a point light at distance r in direction l
    gives ``intensity / r²`` (contract §4b; the Lambert cosine is the fit's).

    Parameters
    ----------
    scene : Scene
    points : numpy.ndarray
        (N, 3) world points.

    Returns
    -------
    directions, irradiance : numpy.ndarray
        float64 (N, K, 3) each, light k at point n in row ``[n, k]``.
    """
    points = np.asarray(points, dtype=np.float64)
    count = len(scene.lights)
    directions = np.empty((len(points), count, 3))
    irradiance = np.empty((len(points), count, 3))
    for k, light in enumerate(scene.lights):
        if isinstance(light, PointLight):
            offset = light.position - points
            squared = np.maximum((offset * offset).sum(axis=-1, keepdims=True), 1e-300)
            directions[:, k] = offset / np.sqrt(squared)
            irradiance[:, k] = light.intensity / squared
        else:
            directions[:, k] = light.direction
            irradiance[:, k] = light.irradiance
    return directions, irradiance


def emission_of(light: Light | PointLight) -> np.ndarray:
    """A distant light's irradiance, or a point light's intensity (3,)."""
    return light.intensity if isinstance(light, PointLight) else light.irradiance


def with_emission(light: Light | PointLight, emission: np.ndarray) -> Light | PointLight:
    """`light` with its irradiance (a point light's intensity) replaced by `emission`."""
    if isinstance(light, PointLight):
        return PointLight(position=light.position, intensity=emission)
    return Light(direction=light.direction, irradiance=emission)


def _parse_floor(fields: _Fields, value: object) -> Floor:
    floor = fields.mapping(value, "floor", required=("height", "albedo"))
    return Floor(
        height=fields.number(floor["height"], "floor.height"),
        albedo=fields.rgb01(floor["albedo"], "floor.albedo"),
    )


def _parse_environment(
    fields: _Fields, value: object, floor_height: float, folder: Path
) -> CornellBox | MeshEnvironment | None:
    kind = fields.mapping(value, "environment", required=("type",), optional=(*_BOX_KEYS, "file"))["type"]
    if kind == "none":
        fields.mapping(value, "environment", required=("type",))
        return None
    if kind == "mesh":
        mesh = fields.mapping(value, "environment", required=("type", "file"), optional=("albedo",))
        name = mesh["file"]
        if not isinstance(name, str):
            fields.expect(name, "environment.file", "a file name")
        if not name or Path(name).name != name or name in (".", ".."):
            fields.fail("environment.file", f"is {shown(name)}: expected a file name in the data set folder")
        uniform = None if "albedo" not in mesh else fields.rgb01(mesh["albedo"], "environment.albedo")
        return read_environment_mesh(folder / name, albedo=uniform)
    if kind != "cornell_box":
        fields.fail("environment.type", f"is {shown(kind)}: expected 'none', 'cornell_box' or 'mesh'")
    box = fields.mapping(value, "environment", required=_BOX_KEYS)
    x = fields.interval(box["x"], "environment.x")
    y = fields.interval(box["y"], "environment.y")
    z_top = fields.number(box["z_top"], "environment.z_top")
    if z_top <= floor_height:
        fields.fail("environment.z_top", f"({z_top:g}) must be above the floor height ({floor_height:g})")
    albedo = fields.mapping(box["albedo"], "environment.albedo", required=_WALLS)
    walls = {f"albedo_{wall}": fields.rgb01(albedo[wall], f"environment.albedo.{wall}") for wall in _WALLS}
    return CornellBox(x=x, y=y, z_top=z_top, **walls)


def _environment_to_dict(box: CornellBox | MeshEnvironment | None) -> dict:
    if box is None:
        return {"type": "none"}
    if isinstance(box, MeshEnvironment):
        uniform = {} if box.uniform_albedo is None else {"albedo": _floats(box.uniform_albedo)}
        return {"type": "mesh", "file": box.file} | uniform
    return {
        "type": "cornell_box",
        "x": _floats(box.x),
        "y": _floats(box.y),
        "z_top": float(box.z_top),
        "albedo": {wall: _floats(getattr(box, f"albedo_{wall}")) for wall in _WALLS},
    }


def _floats(values) -> list[float]:
    return [float(v) for v in values]


def _json_type(value: object) -> str:
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "a boolean"
    if isinstance(value, numbers.Number):
        return f"the number {value!r}"
    if isinstance(value, str):
        return f"the string {shown(value)}"
    if isinstance(value, (list, tuple)):
        return "an array"
    if isinstance(value, dict):
        return "an object"
    return type(value).__name__


class _Fields:
    """Typed access to parsed JSON; every error names the source and the field path."""

    def __init__(self, source: str) -> None:
        self.source = source

    def fail(self, field: str, problem: str) -> NoReturn:
        raise DatasetError(f"{self.source}: {field} {problem}")

    def expect(self, value: object, field: str, expected: str) -> NoReturn:
        self.fail(field, f"must be {expected}, got {_json_type(value)}")

    def mapping(self, value: object, field: str, required: tuple[str, ...], optional: tuple[str, ...] = ()) -> dict:
        """A JSON object with the ``required`` keys and no keys outside ``required + optional``."""
        where = field or "the top level"
        if not isinstance(value, dict):
            self.expect(value, where, "an object")
        for key in required:
            if key not in value:
                self.fail(_join(field, key), "is missing")
        for key in value:
            if key not in required and key not in optional:
                self.fail(where, f"has an unknown field {shown(key)}")
        return value

    def array(self, value: object, field: str) -> list:
        if not isinstance(value, (list, tuple)):
            self.expect(value, field, "an array")
        return list(value)

    def number(self, value: object, field: str) -> float:
        if not isinstance(value, numbers.Real) or isinstance(value, bool):
            self.expect(value, field, "a number")
        if not math.isfinite(value):
            self.fail(field, f"must be a finite number, got {value!r}")
        return float(value)

    def positive_number(self, value: object, field: str) -> float:
        number = self.number(value, field)
        if number <= 0.0:
            self.fail(field, f"must be positive, got {number:g}")
        return number

    def positive_int(self, value: object, field: str) -> int:
        if not isinstance(value, numbers.Integral) or isinstance(value, bool):
            self.expect(value, field, "a positive integer")
        if value <= 0:
            self.fail(field, f"must be a positive integer, got {value}")
        return int(value)

    def vector3(self, value: object, field: str) -> tuple[float, float, float]:
        items = self.array(value, field)
        if len(items) != 3:
            self.fail(field, f"must have 3 numbers, got {len(items)}")
        first, second, third = (self.number(item, f"{field}[{c}]") for c, item in enumerate(items))
        return first, second, third

    def rgb01(self, value: object, field: str) -> tuple[float, float, float]:
        rgb = self.vector3(value, field)
        if min(rgb) < 0.0 or max(rgb) > 1.0:
            self.fail(field, f"must be RGB values in [0, 1], got {list(rgb)}")
        return rgb

    def interval(self, value: object, field: str) -> tuple[float, float]:
        items = self.array(value, field)
        if len(items) != 2:
            self.fail(field, f"must be [low, high], got {len(items)} numbers")
        low, high = (self.number(item, f"{field}[{c}]") for c, item in enumerate(items))
        if not low < high:
            self.fail(field, f"must be [low, high] with low < high, got [{low:g}, {high:g}]")
        return low, high


def _join(field: str, key: str) -> str:
    return f"{field}.{key}" if field else key
