"""Where the object stands: its base height (contract §6), and how it was found.

Normals fix a height field only up to a constant. `irtps.render.placement.estimate_placement`
finds that constant from the floor around the object in the images (it renders the floor);
`raised` stands a relief at a base height (through a pinhole, along the camera's rays);
where nothing in the data fixes it, `fallback_placement` gives contract §6's: the median
height of the mask boundary on the floor. `spread_lights` picks the few well-spread lights
that a rendering of the floor (or the albedo's scale) needs.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from irtps.model.scene import Scene

__all__ = ["Placement", "fallback_placement", "floor_height", "format_placement", "raised", "spread_lights"]


@dataclass(frozen=True)
class Placement:
    """The height at which the object's mask boundary stands (its median, contract §6).

    Attributes
    ----------
    base_height : float
        World units, the height the median of the mask boundary is placed at.
    source : str
        ``"images"`` (estimated from the floor around the object), ``"object"`` (estimated
        from the object's own pixels, which the light of the floor and walls reaches
        differently at each height: where no floor is in view), ``"falloff"`` (from how the
        light of point lights near the object falls off over it:
        `irtps.geometry.falloff_placement`), ``"boundary"`` (contract §6's fallback: the
        floor's height) or ``"given"`` (by the user).
    reason : str or None
        Why the fallback was used, when it was used without being asked for; why the floor
        did not place an object placed from its own pixels.
    floor_residual : float or None
        Estimated: relative mean absolute difference between the rendered and the observed
        floor at `base_height`.
    floor_pixels : int
        Floor pixels compared (0 when not estimated from the floor).
    object_residual : float or None
        Estimated from the object: the same difference over its pixels.
    object_pixels : int
        Object pixels compared (0 when not estimated from the object).
    """

    base_height: float
    source: str
    reason: str | None = None
    floor_residual: float | None = None
    floor_pixels: int = 0
    object_residual: float | None = None
    object_pixels: int = 0

    def to_dict(self) -> dict:
        """JSON-ready fields."""
        return asdict(self)


def format_placement(placement: Placement | dict) -> str:
    """One line saying where the object stands and why.

    Examples
    --------
    >>> format_placement(Placement(base_height=20.04, source="images", floor_residual=0.061, floor_pixels=6224))
    'boundary at height 20.04, estimated from the floor around the object (6224 floor pixels, residual 0.0610)'
    >>> format_placement(Placement(base_height=0.0, source="boundary", reason="the scene has no floor"))
    "boundary at height 0 (the floor's, 0 without one): the scene has no floor"
    >>> format_placement(Placement(base_height=38.2, source="object", reason="no floor is visible",
    ...                            object_residual=0.0712, object_pixels=6400))
    "boundary at height 38.2, estimated from the surroundings' light on the object (6400 object pixels, residual 0.0712): no floor is visible"
    """
    fields = placement.to_dict() if isinstance(placement, Placement) else placement
    height = f"boundary at height {fields['base_height']:.4g}"
    if fields["source"] == "images":
        return f"{height}, estimated from the floor around the object ({fields['floor_pixels']} floor pixels, residual {fields['floor_residual']:.4f})"
    if fields["source"] == "object":
        return (
            f"{height}, estimated from the surroundings' light on the object ({fields['object_pixels']} object pixels, "
            f"residual {fields['object_residual']:.4f})" + (f": {fields['reason']}" if fields.get("reason") else "")
        )
    if fields["source"] == "falloff":
        return (
            f"{height}, estimated from the point lights' fall-off over the object ({fields['object_pixels']} object pixels, "
            f"residual {fields['object_residual']:.4f})"
        )
    if fields["source"] == "given":
        return f"{height}, as given"
    return f"{height} (the floor's, 0 without one)" + (f": {fields['reason']}" if fields.get("reason") else "")


def raised(relief: np.ndarray, mask: np.ndarray, base_height: float, scene: Scene) -> np.ndarray:
    """`relief` stood with the median of its mask boundary at `base_height`: float32, 0
    outside `mask`.

    `relief` has its boundary median at 0. For an orthographic camera the object moves up
    rigidly: ``relief + base_height``. Seen through a pinhole (a perspective camera's
    orthographic stand-in, `irtps.model.camera.Camera.orthographic_stand_in`), the normals fix
    the depth map only up to a scale: `relief` is the shape at the stand-in's depth
    (``zc - scene.base_height``), and standing it higher moves it along the camera's rays
    toward the optical centre, which scales it by ``(zc - base_height) / (zc - scene.base_height)``.

    Examples
    --------
    >>> import numpy as np
    >>> from irtps import Camera, Scene
    >>> relief, mask = np.array([[0.0, 2.0]]), np.ones((1, 2), bool)
    >>> raised(relief, mask, 5.0, Scene(Camera(2, 1, 1.0), [])).tolist()
    [[5.0, 7.0]]
    >>> pinhole = Camera(2, 1, projection="perspective", fx=20.0, fy=20.0, cx=1.0, cy=0.5,
    ...                  optical_center=(0.0, 0.0, 20.0))
    >>> raised(relief, mask, 10.0, Scene(pinhole.orthographic_stand_in(20.0), [])).tolist()
    [[10.0, 11.0]]
    """
    pinhole = scene.camera.pinhole
    scale = 1.0
    if pinhole is not None:
        center = pinhole.center_z
        scale = (center - base_height) / (center - scene.base_height)
    return np.where(mask, relief * scale + base_height, 0).astype(np.float32)


def fallback_placement(scene: Scene, reason: str | None = None) -> Placement:
    """Contract §6's fallback: the boundary median on the floor (0 without a floor)."""
    return Placement(base_height=floor_height(scene), source="boundary", reason=reason)


def floor_height(scene: Scene) -> float:
    """The floor's height, 0 without a floor: the lowest the object's boundary stands."""
    return scene.floor.height if scene.floor is not None else 0.0


def spread_lights(directions: np.ndarray, count: int) -> np.ndarray:
    """Indices of at most `count` lights spread over the directions: the most oblique first
    (the longest shadows), then each time the one farthest in angle from those chosen.

    Examples
    --------
    >>> import numpy as np
    >>> directions = np.array([[0, 0, 1], [0.6, 0, 0.8], [0.59, 0.05, 0.806], [-0.6, 0, 0.8]])
    >>> spread_lights(directions, 2).tolist()
    [1, 3]
    """
    directions = np.asarray(directions, dtype=np.float64)
    if len(directions) <= count:
        return np.arange(len(directions))
    chosen = [int(np.argmin(directions[:, 2]))]
    nearest = directions @ directions[chosen[0]]
    while len(chosen) < count:
        following = int(np.argmin(nearest))
        chosen.append(following)
        nearest = np.maximum(nearest, directions @ directions[following])
    return np.sort(chosen)
