"""Exception types of irtps."""


class IrtpsError(Exception):
    """Base class of every error that irtps raises on purpose."""


class ArgumentError(IrtpsError, ValueError):
    """An argument of a public function that irtps cannot accept.

    Every public function raises it for a bad argument, and the core's errors about its
    inputs arrive as it. The message starts with the argument's name, e.g.
    ``"mask: shape (3, 4), expected (2, 2) to match height"``.

    Attributes
    ----------
    argument : str
        The argument's name (or its field, e.g. ``"lights[2].irradiance"``).
    problem : str
        What is wrong with it.
    """

    def __init__(self, argument: str, problem: str) -> None:
        super().__init__(f"{argument}: {problem}")
        self.argument = argument
        self.problem = problem

    def __reduce__(self):
        return type(self), (self.argument, self.problem)


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
