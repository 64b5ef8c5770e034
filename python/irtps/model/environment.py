"""Surroundings given as a triangle mesh (contract §3b): a rig's light box, backdrop,
turntable or reflector card, scanned or modelled.

The mesh is in world coordinates, its albedo given per vertex (interpolated across each
triangle); its surfaces are Lambertian and reflect on both sides. `read_environment_mesh`
reads it from a PLY or OBJ file (colours per vertex or per face, or one albedo for all),
`write_environment_mesh` writes a PLY file; `view_problem` says whether it hides the object
from the camera.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from irtps import _core
from irtps._shared.atomic import atomic_write_bytes
from irtps._shared.checks import check_path
from irtps._shared.paths import exists
from irtps.errors import ArgumentError, DatasetError

#: The name of the mesh file in a data set folder that `irtps synth` writes.
ENVIRONMENT_FILE = "environment.ply"

#: Largest number of triangles an environment mesh may have (a detailed scan has millions).
MAX_TRIANGLES = 50_000_000

#: Colour properties of a PLY vertex, as the contract names them: floats in [0, 1], or
#: 8-bit values.
_FLOAT_RGB, _BYTE_RGB = ("r", "g", "b"), ("red", "green", "blue")


@dataclass(frozen=True, eq=False)
class MeshEnvironment:
    """Surroundings given as a triangle mesh that reflects on both sides (contract §3b).

    Attributes
    ----------
    vertices : numpy.ndarray
        float64 (V, 3) world coordinates. Read-only.
    triangles : numpy.ndarray
        int64 (F, 3) vertex indices of each triangle. Read-only.
    albedo : numpy.ndarray
        float64 (V, 3) RGB albedo in [0, 1] at each vertex. Read-only.
    file : str
        The file name ``scene.json`` gives it, relative to the data set folder.
    uniform_albedo : tuple of 3 floats or None
        The one albedo ``scene.json`` gives the whole mesh (``environment.albedo``), which
        `albedo` then holds at every vertex; None where the file's colours are the albedo.

    Raises
    ------
    DatasetError
        If the arrays have the wrong shapes, a vertex is not finite, an index is out of
        range or an albedo lies outside [0, 1]; the message names the first one.
    """

    vertices: np.ndarray
    triangles: np.ndarray
    albedo: np.ndarray
    file: str = ENVIRONMENT_FILE
    uniform_albedo: tuple[float, float, float] | None = None

    def __post_init__(self) -> None:
        vertices = np.array(self.vertices, dtype=np.float64)
        albedo = np.array(self.albedo, dtype=np.float64)
        triangles = np.array(self.triangles)
        problem = mesh_problem(vertices, triangles, albedo)
        if problem is not None:
            raise DatasetError(f"MeshEnvironment: {problem}")
        triangles = triangles.astype(np.int64)
        for name, array in (("vertices", vertices), ("triangles", triangles), ("albedo", albedo)):
            array.flags.writeable = False
            object.__setattr__(self, name, array)
        if not isinstance(self.file, str) or not self.file or Path(self.file).name != self.file:
            raise DatasetError(f"MeshEnvironment.file must be a file name in the data set folder, got {self.file!r}")

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, MeshEnvironment):
            return NotImplemented
        return (
            self.file == other.file
            and self.uniform_albedo == other.uniform_albedo
            and all(
                np.array_equal(getattr(self, name), getattr(other, name))
                for name in ("vertices", "triangles", "albedo")
            )
        )

    __hash__ = None  # type: ignore[assignment]

    def __getstate__(self) -> dict:
        """Its fields, without what is built from them (`core_environment`, the view checks
        remembered): pickled to a batch's workers, they are built again there."""
        return {name: value for name, value in self.__dict__.items() if not name.startswith("_")}


def mesh_problem(vertices: np.ndarray, triangles: np.ndarray, albedo: np.ndarray) -> str | None:
    """What makes a mesh unusable as an environment, or None.

    Examples
    --------
    >>> mesh_problem(np.zeros((3, 3)), np.array([[0, 1, 2]]), np.full((3, 3), 0.5)) is None
    True
    >>> mesh_problem(np.zeros((3, 3)), np.array([[0, 1, 3]]), np.full((3, 3), 0.5))
    'triangle 0 names vertex 3, but there are 3 vertices'
    """
    if vertices.ndim != 2 or vertices.shape[1] != 3 or len(vertices) == 0:
        return f"vertices must be a non-empty (V, 3) array, got shape {vertices.shape}"
    if triangles.ndim != 2 or triangles.shape[1] != 3 or len(triangles) == 0:
        return f"triangles must be a non-empty (F, 3) array, got shape {triangles.shape}"
    if len(triangles) > MAX_TRIANGLES:
        return f"has {len(triangles)} triangles, more than the {MAX_TRIANGLES} supported"
    if albedo.shape != vertices.shape:
        return f"albedo must be one RGB value per vertex ({vertices.shape}), got shape {albedo.shape}"
    if not np.issubdtype(triangles.dtype, np.integer):
        return f"triangles must hold integer vertex indices, got {triangles.dtype}"
    finite = np.isfinite(vertices).all(axis=1)
    if not finite.all():
        bad = int(np.argmin(finite))
        return f"vertex {bad} is not finite: {vertices[bad].tolist()}"
    outside = (triangles < 0) | (triangles >= len(vertices))
    if outside.any():
        face, corner = np.argwhere(outside)[0]
        return f"triangle {face} names vertex {triangles[face, corner]}, but there are {len(vertices)} vertices"
    valid = np.isfinite(albedo).all(axis=1) & (albedo >= 0.0).all(axis=1) & (albedo <= 1.0).all(axis=1)
    if not valid.all():
        bad = int(np.argmin(valid))
        return f"vertex {bad} has albedo {albedo[bad].tolist()}: expected RGB values in [0, 1]"
    return None


#: The mesh files read, by suffix.
MESH_SUFFIXES = (".ply", ".obj")


def read_environment_mesh(path: str | Path, albedo=None) -> MeshEnvironment:
    """Read an environment mesh (contract §3b) from a PLY (binary or ASCII) or OBJ file.

    The albedo comes, in this order, from `albedo` (one RGB value for the whole mesh), from
    a colour per vertex (PLY: ``r, g, b`` floats in [0, 1] or ``red, green, blue`` integers
    over their type's largest value; OBJ: ``v x y z r g b``), or from a colour per face (PLY:
    the same properties on faces; OBJ: the ``Kd`` of each face's material, from the
    ``mtllib`` file beside it). Faces of more than three corners are split into triangles
    around their first corner.

    Parameters
    ----------
    path : str or pathlib.Path
        A ``.ply`` or ``.obj`` file.
    albedo : sequence of 3 floats, optional
        One RGB albedo in [0, 1] for the whole mesh, whatever colours the file holds.

    Returns
    -------
    MeshEnvironment
        With ``file`` the name of `path`, and `albedo` as its ``uniform_albedo``.

    Raises
    ------
    DatasetError
        Naming `path`: a file that is missing, of another kind, or not readable as its kind;
        vertices without a position, no faces, no colour and no `albedo`, a material without
        ``Kd``, or a mesh that `mesh_problem` refuses.
    ArgumentError
        An `albedo` that is not three numbers in [0, 1].
    """
    path = check_path("path", path)
    uniform = None if albedo is None else _checked_albedo(albedo)
    if not exists(path):
        raise DatasetError(f"{path}: file not found (the environment mesh of scene.json)")
    if not path.is_file():
        raise DatasetError(f"{path}: not a regular file (the environment mesh of scene.json)")
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise DatasetError(f"{path}: not a mesh file irtps reads: expected one of {', '.join(MESH_SUFFIXES)}")
    try:
        read = _read_obj if path.suffix.lower() == ".obj" else _read_ply_mesh
        vertices, triangles, vertex_albedo, face_albedo = read(path)
    except DatasetError as error:
        raise DatasetError(f"{path}: {error}") from None
    except (ValueError, TypeError, IndexError, EOFError, UnicodeDecodeError) as error:
        raise DatasetError(
            f"{path}: not a readable {path.suffix[1:].upper()} file: {type(error).__name__}: {error}"
        ) from None
    except OSError as error:
        raise DatasetError(f"{path}: cannot be read: {error.strerror or error}") from None
    if uniform is not None:
        vertex_albedo = np.tile(uniform, (len(vertices), 1))
    elif vertex_albedo is None and face_albedo is not None:
        vertices, triangles, vertex_albedo = _split_faces(vertices, triangles, face_albedo)
    elif vertex_albedo is None:
        raise DatasetError(
            f"{path}: has no colour for the albedo (per vertex or per face): give one albedo for the whole "
            "mesh (scene.json's environment.albedo)"
        )
    problem = mesh_problem(vertices, triangles, vertex_albedo)
    if problem is not None:
        raise DatasetError(f"{path}: {problem}")
    return MeshEnvironment(vertices, triangles, vertex_albedo, file=path.name, uniform_albedo=uniform)


#: What a mesh reader gives: vertices (V, 3), triangles (F, 3), and a colour per vertex
#: (V, 3) or per triangle (F, 3), or neither (None).
_MeshData = tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray | None]


def _checked_albedo(albedo) -> tuple[float, float, float]:
    values = np.asarray(albedo, dtype=np.float64) if not isinstance(albedo, str) else np.array([])
    if values.shape != (3,) or not np.isfinite(values).all() or values.min() < 0 or values.max() > 1:
        raise ArgumentError("albedo", f"must be three numbers in [0, 1], got {albedo!r}")
    return (float(values[0]), float(values[1]), float(values[2]))


def _split_faces(vertices: np.ndarray, triangles: np.ndarray, face_albedo: np.ndarray):
    """A mesh coloured per face as one coloured per vertex: each triangle its own corners."""
    corners = vertices[triangles].reshape(-1, 3)
    return corners, np.arange(len(corners)).reshape(-1, 3), np.repeat(face_albedo, 3, axis=0)


def _read_ply_mesh(path: Path) -> _MeshData:
    import plyfile

    try:
        ply = _read_ply(plyfile, path)
    except (plyfile.PlyParseError, plyfile.PlyElementParseError, plyfile.PlyHeaderParseError) as error:
        raise DatasetError(f"not a readable PLY file: {error}") from None
    if "vertex" not in ply:
        raise DatasetError("has no 'vertex' element")
    data = ply["vertex"].data
    names = data.dtype.names or ()
    missing = [name for name in ("x", "y", "z") if name not in names]
    if missing:
        raise DatasetError(f"its vertices have no {', '.join(missing)} (need x, y, z)")
    vertices = np.stack([np.asarray(data[name], dtype=np.float64) for name in ("x", "y", "z")], axis=1)
    triangles, face_of = _triangles(ply)
    face_albedo = _ply_colours(ply["face"].data)
    return vertices, triangles, _ply_colours(data), None if face_albedo is None else face_albedo[face_of]


def _ply_colours(data: np.ndarray) -> np.ndarray | None:
    """The RGB colours in [0, 1] of a PLY element's records, or None where it has none."""
    names = data.dtype.names or ()
    for channels in (_FLOAT_RGB, _BYTE_RGB):
        if all(name in names for name in channels):
            dtype = data.dtype[channels[0]]
            scale = float(np.iinfo(dtype).max) if np.issubdtype(dtype, np.integer) else 1.0
            return np.stack([np.asarray(data[name], dtype=np.float64) for name in channels], axis=1) / scale
    return None


def _read_ply(plyfile, path: Path):
    """The parsed file: first as a mesh of triangles only (read as one array, fast), else as
    faces of any size."""
    try:
        return plyfile.PlyData.read(str(path), known_list_len={"face": {"vertex_indices": 3, "vertex_index": 3}})
    except (plyfile.PlyElementParseError, ValueError):
        return plyfile.PlyData.read(str(path))


def _triangles(ply) -> tuple[np.ndarray, np.ndarray]:
    """The triangles of a PLY mesh's faces (fans of larger ones), and the face of each."""
    if "face" not in ply or len(ply["face"].data) == 0:
        raise DatasetError("has no faces")
    data = ply["face"].data
    names = data.dtype.names or ()
    name = next((n for n in ("vertex_indices", "vertex_index") if n in names), None)
    if name is None:
        raise DatasetError("its faces have no vertex_indices list")
    faces = data[name]
    if faces.dtype != object:
        triangles = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
        return triangles, np.arange(len(triangles))
    return _fans([np.asarray(face, dtype=np.int64) for face in faces])


def _fans(faces: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Triangles of polygons split around their first corner, and the polygon of each."""
    corners = np.array([len(face) for face in faces])
    if corners.min() < 3:
        bad = int(np.argmin(corners))
        raise DatasetError(f"face {bad} has {corners[bad]} corners, fewer than 3")
    triangles = np.concatenate([np.stack([np.full(len(f) - 2, f[0]), f[1:-1], f[2:]], axis=1) for f in faces])
    return triangles, np.repeat(np.arange(len(faces)), corners - 2)


def _read_obj(path: Path) -> _MeshData:
    """Vertices (with ``v x y z r g b`` colours), faces and the ``Kd`` of their materials."""
    vertices: list[list[float]] = []
    colours: list[list[float]] = []
    faces: list[np.ndarray] = []
    face_material: list[str | None] = []
    materials: dict[str, tuple[float, float, float] | None] = {}
    material = None
    with path.open(encoding="utf-8") as lines:
        for number, line in enumerate(lines, start=1):
            fields = line.split("#", 1)[0].split()
            if not fields:
                continue
            keyword, values = fields[0], fields[1:]
            if keyword == "v":
                if len(values) not in (3, 4, 6, 7):
                    raise DatasetError(f"line {number}: a vertex needs x y z (and r g b), got {len(values)} numbers")
                numbers = [float(value) for value in values]
                vertices.append(numbers[:3])
                if len(values) >= 6:
                    colours.append(numbers[-3:])
            elif keyword == "f":
                faces.append(_obj_face(values, len(vertices), number))
                face_material.append(material)
            elif keyword == "mtllib":
                materials.update(_read_mtl(path, " ".join(values)))
            elif keyword == "usemtl":
                material = " ".join(values)
    if not vertices:
        raise DatasetError("has no vertices")
    if not faces:
        raise DatasetError("has no faces")
    triangles, face_of = _fans(faces)
    vertex_albedo = np.array(colours, dtype=np.float64) if len(colours) == len(vertices) else None
    face_albedo = None
    if vertex_albedo is None and any(name is not None for name in face_material):
        face_albedo = np.array([_material_kd(materials, name) for name in face_material], dtype=np.float64)[face_of]
    return np.array(vertices, dtype=np.float64), triangles, vertex_albedo, face_albedo


def _obj_face(values: list[str], count: int, number: int) -> np.ndarray:
    """The 0-based vertex indices of an OBJ face (``i``, ``i/t``, ``i//n``, ``i/t/n``; a
    negative index counts back from the last vertex read)."""
    indices = []
    for value in values:
        index = int(value.split("/", 1)[0])
        if index == 0:
            raise DatasetError(f"line {number}: vertex index 0 (OBJ counts from 1)")
        indices.append(index - 1 if index > 0 else count + index)
    return np.array(indices, dtype=np.int64)


def _read_mtl(obj: Path, name: str) -> dict[str, tuple[float, float, float] | None]:
    """The diffuse colour ``Kd`` of each material of the ``mtllib`` file `name` (beside `obj`)."""
    path = obj.parent / name
    if Path(name).is_absolute() or ".." in Path(name).parts:
        raise DatasetError(f"mtllib {name!r} lies outside the mesh's folder")
    if not path.is_file():
        raise DatasetError(f"mtllib {name!r}: file not found beside the mesh")
    kd: dict[str, tuple[float, float, float] | None] = {}
    current = None
    with path.open(encoding="utf-8") as lines:
        for line in lines:
            fields = line.split("#", 1)[0].split()
            if fields[:1] == ["newmtl"]:
                current = " ".join(fields[1:])
                kd[current] = None
            elif fields[:1] == ["Kd"] and current is not None and len(fields) >= 4:
                kd[current] = (float(fields[1]), float(fields[2]), float(fields[3]))
    return kd


def _material_kd(
    materials: dict[str, tuple[float, float, float] | None], name: str | None
) -> tuple[float, float, float]:
    colour = None if name is None else materials.get(name)
    if colour is None:
        raise DatasetError(
            f"a face's material {name!r} has no Kd colour"
            if name is not None
            else "some faces have a material and others none: every face needs a colour"
        )
    return colour


def write_environment_mesh(environment: MeshEnvironment, path: str | Path) -> None:
    """Write an environment mesh atomically as a binary PLY file with ``r, g, b`` albedo
    (contract §3b), every value a double, which `read_environment_mesh` reads back exactly.

    Parameters
    ----------
    environment : MeshEnvironment
    path : str or pathlib.Path
    """
    vertex = np.empty(len(environment.vertices), dtype=[(name, "<f8") for name in ("x", "y", "z", *_FLOAT_RGB)])
    for axis, name in enumerate(("x", "y", "z")):
        vertex[name] = environment.vertices[:, axis]
    for channel, name in enumerate(_FLOAT_RGB):
        vertex[name] = environment.albedo[:, channel]
    header = "\n".join(
        [
            "ply",
            "format binary_little_endian 1.0",
            f"element vertex {len(vertex)}",
            *(f"property double {name}" for name in vertex.dtype.names or ()),
            f"element face {len(environment.triangles)}",
            "property list uchar uint vertex_indices",
            "end_header",
            "",
        ]
    ).encode("ascii")
    face = np.empty(len(environment.triangles), dtype=[("n", "u1"), ("v", "<u4", (3,))])
    face["n"] = 3
    face["v"] = environment.triangles
    atomic_write_bytes(path, header + vertex.tobytes() + face.tobytes())


def view_problem(environment: MeshEnvironment, optical_center_z: float | None, base_height: float) -> str | None:
    """Why the mesh hides the object from the camera, or None.

    The camera's axis (the vertical line through the image centre) from the camera (the
    optical centre, or above the whole mesh for an orthographic camera) down to the object's
    base must not cross the mesh (a roof, or a mesh in other units that swallows the
    scene); and a perspective camera's optical centre must not be enclosed by it (the rays
    along ±x, ±y and ±z from it all meeting the mesh).

    Parameters
    ----------
    environment : MeshEnvironment
    optical_center_z : float or None
        Height of a perspective camera's optical centre (on the z axis); None for an
        orthographic camera.
    base_height : float
        The height the object stands on (the floor's, or 0).

    Notes
    -----
    A mesh found to leave a camera's view open is remembered (the mesh is immutable): the
    scenes made from one another in a run ask again and again.
    """
    views_open: set = environment.__dict__.setdefault("_views_open", set())
    if (optical_center_z, base_height) in views_open:
        return None
    problem = _view_problem(environment, optical_center_z, base_height)
    if problem is None:
        views_open.add((optical_center_z, base_height))
    return problem


def _view_problem(environment: MeshEnvironment, optical_center_z: float | None, base_height: float) -> str | None:
    """`view_problem`, found by casting the rays through the mesh's BVH (`core_environment`).
    Each ray leaves a hair (a millionth of the scene's size, in no special direction) off the
    axis, so that it does not run along the shared edge of a mesh laid out around the axis."""
    accel = core_environment(environment)
    extent = float(np.ptp(environment.vertices, axis=0).max()) + abs(base_height) + 1.0
    hair = 1e-6 * extent
    low = base_height + hair
    top = float(environment.vertices[:, 2].max()) + 1.0 if optical_center_z is None else optical_center_z
    if top > low:
        hit = accel.first_hit((hair, 0.618 * hair, top), (0.0, 0.0, -1.0), top - low)
        if hit is not None:
            return (
                f"lies between the camera and the object: the camera's axis meets it at z = {top - hit:g}, "
                f"above the object's base ({base_height:g}); the camera would see the mesh, not the object"
            )
    if optical_center_z is not None:
        origin = (hair, 0.618 * hair, optical_center_z + 0.382 * hair)
        axes = [(1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0), (-1.0, 0.0, 0.0), (0.0, -1.0, 0.0), (0.0, 0.0, -1.0)]
        if all(accel.first_hit(origin, axis, np.inf) is not None for axis in axes):
            return (
                f"encloses the camera (the optical centre at z = {optical_center_z:g}): the camera must see "
                "the scene from outside the mesh (are the mesh's units the scene's?)"
            )
    return None


def core_environment(mesh: MeshEnvironment) -> _core.Environment:
    """The mesh made ready for ray queries (its BVH, in world units), built once per mesh and
    kept with it: its view check and every renderer of the scene (IRT-PS's passes, the
    placement's renderings) share it."""
    built = mesh.__dict__.get("_core_environment")
    if built is None:
        built = _core.Environment(
            np.ascontiguousarray(mesh.vertices, dtype=np.float32),
            np.ascontiguousarray(mesh.triangles, dtype=np.uint32),
            np.ascontiguousarray(mesh.albedo, dtype=np.float32),
        )
        mesh.__dict__["_core_environment"] = built
    return built
