"""Surroundings given as a triangle mesh (contract §3b): a rig's light box, backdrop,
turntable or reflector card, scanned or modelled.

The mesh is in world coordinates, its albedo given per vertex (interpolated across each
triangle); its surfaces are Lambertian and reflect on both sides. `read_environment_mesh`
reads it from a PLY file, `write_environment_mesh` writes one; `view_problem` says whether
it hides the object from the camera.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from irtps._shared.atomic import atomic_write_bytes
from irtps._shared.checks import check_path
from irtps._shared.paths import exists
from irtps.errors import DatasetError

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
        return self.file == other.file and all(
            np.array_equal(getattr(self, name), getattr(other, name)) for name in ("vertices", "triangles", "albedo")
        )

    __hash__ = None  # type: ignore[assignment]


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


def read_environment_mesh(path: str | Path) -> MeshEnvironment:
    """Read an environment mesh from a PLY file (binary or ASCII), as contract §3b gives it.

    Each vertex has ``x, y, z`` and a colour, the albedo: ``r, g, b`` as floats in [0, 1], or
    ``red, green, blue`` as 8-bit (or 16-bit) values. Faces with more than three corners are
    split into triangles around their first corner.

    Parameters
    ----------
    path : str or pathlib.Path

    Returns
    -------
    MeshEnvironment
        With ``file`` the name of `path`.

    Raises
    ------
    DatasetError
        Naming `path`: a file that is missing or not a readable PLY file, a vertex without
        position or colour, no faces, or a mesh that `mesh_problem` refuses.
    """
    import plyfile

    path = check_path("path", path)
    if not exists(path):
        raise DatasetError(f"{path}: file not found (the environment mesh of scene.json)")
    if not path.is_file():
        raise DatasetError(f"{path}: not a regular file (the environment mesh of scene.json)")
    try:
        ply = _read_ply(plyfile, path)
        vertices, albedo = _vertex_data(ply)
        triangles = _triangles(ply)
    except DatasetError as error:
        raise DatasetError(f"{path}: {error}") from None
    except (plyfile.PlyParseError, plyfile.PlyElementParseError, plyfile.PlyHeaderParseError) as error:
        raise DatasetError(f"{path}: not a readable PLY file: {error}") from None
    except (ValueError, TypeError, IndexError, EOFError, UnicodeDecodeError) as error:
        raise DatasetError(f"{path}: not a readable PLY file: {type(error).__name__}: {error}") from None
    except OSError as error:
        raise DatasetError(f"{path}: cannot be read: {error.strerror or error}") from None
    problem = mesh_problem(vertices, triangles, albedo)
    if problem is not None:
        raise DatasetError(f"{path}: {problem}")
    return MeshEnvironment(vertices=vertices, triangles=triangles, albedo=albedo, file=path.name)


def _read_ply(plyfile, path: Path):
    """The parsed file: first as a mesh of triangles only (read as one array, fast), else as
    faces of any size."""
    try:
        return plyfile.PlyData.read(str(path), known_list_len={"face": {"vertex_indices": 3, "vertex_index": 3}})
    except (plyfile.PlyElementParseError, ValueError):
        return plyfile.PlyData.read(str(path))


def _vertex_data(ply) -> tuple[np.ndarray, np.ndarray]:
    if "vertex" not in ply:
        raise DatasetError("has no 'vertex' element")
    data = ply["vertex"].data
    names = data.dtype.names or ()
    missing = [name for name in ("x", "y", "z") if name not in names]
    if missing:
        raise DatasetError(f"its vertices have no {', '.join(missing)} (need x, y, z)")
    vertices = np.stack([np.asarray(data[name], dtype=np.float64) for name in ("x", "y", "z")], axis=1)
    if all(name in names for name in _FLOAT_RGB):
        albedo = np.stack([np.asarray(data[name], dtype=np.float64) for name in _FLOAT_RGB], axis=1)
    elif all(name in names for name in _BYTE_RGB):
        dtype = data.dtype[_BYTE_RGB[0]]
        scale = float(np.iinfo(dtype).max) if np.issubdtype(dtype, np.integer) else 1.0
        albedo = np.stack([np.asarray(data[name], dtype=np.float64) for name in _BYTE_RGB], axis=1) / scale
    else:
        raise DatasetError("its vertices have no colour, the albedo: expected properties r, g, b or red, green, blue")
    return vertices, albedo


def _triangles(ply) -> np.ndarray:
    if "face" not in ply or len(ply["face"].data) == 0:
        raise DatasetError("has no faces")
    data = ply["face"].data
    names = data.dtype.names or ()
    name = next((n for n in ("vertex_indices", "vertex_index") if n in names), None)
    if name is None:
        raise DatasetError("its faces have no vertex_indices list")
    faces = data[name]
    if faces.dtype != object:
        return np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    corners = np.array([len(face) for face in faces])
    if corners.min() < 3:
        bad = int(np.argmin(corners))
        raise DatasetError(f"face {bad} has {corners[bad]} corners, fewer than 3")
    fans = [np.asarray(face, dtype=np.int64) for face in faces]
    return np.concatenate([np.stack([np.full(len(f) - 2, f[0]), f[1:-1], f[2:]], axis=1) for f in fans])


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
    """`view_problem`, found by casting the rays."""
    corners = environment.vertices[environment.triangles]
    extent = float(np.ptp(environment.vertices, axis=0).max()) + abs(base_height) + 1.0
    low = base_height + 1e-6 * extent
    top = float(environment.vertices[:, 2].max()) + 1.0 if optical_center_z is None else optical_center_z
    if top > low:
        hit = _first_hit(corners, np.array([0.0, 0.0, top]), np.array([0.0, 0.0, -1.0]), top - low)
        if hit is not None:
            return (
                f"lies between the camera and the object: the camera's axis meets it at z = {top - hit:g}, "
                f"above the object's base ({base_height:g}); the camera would see the mesh, not the object"
            )
    if optical_center_z is not None:
        origin = np.array([0.0, 0.0, optical_center_z])
        axes = np.concatenate([np.eye(3), -np.eye(3)])
        if all(_first_hit(corners, origin, axis, np.inf) is not None for axis in axes):
            return (
                f"encloses the camera (the optical centre at z = {optical_center_z:g}): the camera must see "
                "the scene from outside the mesh (are the mesh's units the scene's?)"
            )
    return None


#: Triangles tested at once by `_first_hit` (bounds its temporaries to some hundred MB).
_CHUNK = 1 << 20


def _first_hit(corners: np.ndarray, origin: np.ndarray, direction: np.ndarray, t_max: float) -> float | None:
    """Distance along `direction` from `origin` to the nearest triangle of `corners`
    (F, 3, 3) in (0, t_max), or None (Möller–Trumbore, both sides)."""
    best = None
    for start in range(0, len(corners), _CHUNK):
        v0, v1, v2 = (corners[start : start + _CHUNK, c] for c in range(3))
        e1, e2 = v1 - v0, v2 - v0
        p = np.cross(direction, e2)
        det = np.einsum("ij,ij->i", e1, p)
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / det
            s = origin - v0
            u = np.einsum("ij,ij->i", s, p) * inv
            q = np.cross(s, e1)
            v = (q @ direction) * inv
            t = np.einsum("ij,ij->i", e2, q) * inv
            hit = (det != 0.0) & (u >= 0.0) & (v >= 0.0) & (u + v <= 1.0) & (t > 0.0) & (t < t_max)
        if hit.any():
            nearest = float(t[hit].min())
            best = nearest if best is None else min(best, nearest)
    return best
