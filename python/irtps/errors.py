"""Exception types of irtps."""


class IrtpsError(Exception):
    """Base class of every error that irtps raises on purpose."""


class DatasetError(IrtpsError, ValueError):
    """Input data (a data set, a scene file, an image) that irtps cannot accept.

    The message always names the file or field concerned and the problem, e.g.
    ``"scene.json: lights[3].direction is not a unit vector (norm 1.2)"``.
    """
