"""The choice lists and bounds that the options and the scene declare and the algorithms
use: the model owns them, `irtps.ps.fit`, `irtps.geometry.integrate` and `irtps.io.imageio`
import them from here (and keep them importable under their names there)."""

from irtps import _core

__all__ = ["INTEGRATION_METHODS", "MAX_IMAGE_PIXELS", "ROBUST_CHOICES", "ROBUST_MODES"]

#: Robust modes of a fit, the default first.
ROBUST_MODES = ("tukey", "lobe", "threshold", "trim", "none")
#: What `irtps.ps.fit.photometric_stereo` takes for `robust`: a mode of `ROBUST_MODES`, or
#: ``"auto"``, the mode `irtps.ps.fit.choose_robust` picks for the object.
ROBUST_CHOICES = ("auto", *ROBUST_MODES)

#: Methods of normal integration (`irtps.geometry.integrate.integrate_normals`).
INTEGRATION_METHODS = ("ls", "mestimator", "footprint", "bilateral", "dct", "fc")

MAX_IMAGE_PIXELS = _core.MAX_IMAGE_PIXELS
"""The largest image irtps reads or makes, in pixels (width x height): 2^27."""
