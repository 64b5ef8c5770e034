"""Exception types of irtps."""


class IrtpsError(Exception):
    """Base class of every error that irtps raises on purpose."""


class DatasetError(IrtpsError, ValueError):
    """Input data (a data set, a scene file, an image) that irtps cannot accept.

    The message always names the file or field concerned and the problem, e.g.
    ``"scene.json: lights[3].direction is not a unit vector (norm 1.2)"``.
    """


class IrtpsWarning(UserWarning):
    """Input that irtps accepts but changes or leaves out, e.g. negative pixels clipped to 0.

    The message names the file concerned, like those of `DatasetError`; the ``irtps``
    command prints it as ``irtps: warning: ...``.
    """
