"""The options of each stage, each one frozen, validated, picklable object.

An option is declared once, as a field of one of these dataclasses, with its default, help
text, choices or range; the Python API (`irtps.reconstruct`, `irtps.render`, ...), the
``irtps`` command's arguments, batch runs, the comparison table and ``run.json`` are all
built from the same declaration. A value out of range raises `OptionError` naming the option
and its range, when the object is made: nothing runs with a bad option.

- `ReconstructOptions`: photometric stereo, normal integration and placement, IRT-PS.
- `RenderOptions`: rendering a scene (``irtps render``, ``irtps synth``).
- `SynthOptions`: the synthetic scene of ``irtps synth``.
- `TableOptions`: the comparison table (``irtps table``, ``irtps demo``).
- `ClusterOptions`: the Dask cluster of ``irtps batch``.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
from dataclasses import dataclass
from typing import Any, ClassVar, TypeVar

import numpy as np

from irtps.errors import ArgumentError
from irtps._shared.guarded import parse_float, parse_int
from irtps.model.constants import INTEGRATION_METHODS, MAX_IMAGE_PIXELS, ROBUST_CHOICES, ROBUST_MODES

__all__ = [
    "ESTIMATORS",
    "METHODS",
    "ROBUST_CHOICES",
    "ROBUST_MODES",
    "UPDATES",
    "ClusterOptions",
    "OptionError",
    "ReconstructOptions",
    "RenderOptions",
    "SynthOptions",
    "TableOptions",
    "add_arguments",
    "from_arguments",
]

#: Reconstruction methods: classic photometric stereo, and IRT-PS.
METHODS = ("ps", "irtps")
#: IRT-PS's indirect-light estimators: the physically based renderer, or the paper's own
#: heuristic (`irtps.irt.paper_estimator`).
ESTIMATORS = ("physical", "paper")
#: Ways to form IRT-PS's corrected images: from the input (A₀ − E) or from the previous ones
#: (the paper's literal Aₜ₊₁ = Aₜ − Eₜ).
UPDATES = ("original", "previous")
#: Placements besides a number: estimated from the images, or contract §6's fallback (the
#: boundary's median on the floor).
PLACEMENTS = ("auto", "boundary")
#: Bounce counts the paper's estimator takes.
PAPER_BOUNCES = (1, 2, 3)
#: Largest seed: the Rust core's seeds are unsigned 64-bit integers, and IRT-PS's pass t
#: uses seed + t.
MAX_SEED = 2**63 - 1
#: Largest number of inter-reflection bounces rendered or estimated. Each bounce costs one
#: more ray a path; light that has bounced this often off surfaces of albedo below 1 is gone.
MAX_BOUNCES = 64
#: Largest number of camera paths per pixel (2^20): beyond it, Monte-Carlo noise is below
#: float32 rounding of the images.
MAX_SAMPLES = 2**20
#: Largest number of IRT-PS corrections.
MAX_ITERATIONS = 1000
#: Largest number of lights of a synthetic scene.
MAX_LIGHTS = 100_000
#: Largest side of a synthetic image: its square is the largest image irtps makes.
MAX_SYNTH_SIZE = math.isqrt(MAX_IMAGE_PIXELS)
#: Largest IRT-PS stride and number of cluster workers or threads: beyond any image or machine.
MAX_STRIDE = 4096
MAX_WORKERS = 4096

T = TypeVar("T", bound="_Options")


class OptionError(ArgumentError):
    """An option value out of its range or not among its choices: the `ArgumentError` of an
    option.

    Attributes
    ----------
    option : str
        The option's name as given (``"samples"``, or ``"--samples"`` from the command line).
    problem : str
        What is wrong, with the option's range or choices.
    """

    def __init__(self, option: str, problem: str) -> None:
        super().__init__(option, problem)
        self.option = option


@dataclass(frozen=True)
class _Spec:
    """What an option takes: its help text, its kind, and its range or choices."""

    help: str
    kind: type
    low: float | None = None
    high: float | None = None
    low_open: bool = False
    high_open: bool = False
    choices: tuple | None = None
    optional: bool = False
    many: bool = False
    group: str | None = None
    metavar: str | None = None
    words: tuple[str, ...] = ()

    def describe(self) -> str:
        """The values the option takes, e.g. ``"an integer from 1 to 64"``."""
        if self.choices is not None:
            text = f"one of {', '.join(map(str, self.choices))}"
        elif self.kind is bool:
            text = "true or false"
        else:
            noun = "an integer" if self.kind is int else "a finite number"
            low, high = _number_text(self.low), _number_text(self.high)
            if self.low is not None and self.high is not None:
                if self.low_open or self.high_open:
                    text = f"{noun} in {'(' if self.low_open else '['}{low}, {high}{')' if self.high_open else ']'}"
                else:
                    text = f"{noun} from {low} to {high}"
            elif self.low is not None:
                text = f"{noun} {'above' if self.low_open else 'at least'} {low}"
            elif self.high is not None:
                text = f"{noun} {'below' if self.high_open else 'at most'} {high}"
            else:
                text = noun
        if self.words:
            text = (
                f"{text}, {', '.join(self.words[:-1])} or {self.words[-1]}"
                if len(self.words) > 1
                else f"{text} or {self.words[0]}"
            )
        if self.many:
            text = f"one or more values, each {text}"
        return f"{text}, or none" if self.optional else text

    def check(self, name: str, value: Any) -> Any:
        """The value converted to its kind (tuple of them if `many`), or `OptionError`."""
        if value is None and self.optional:
            return None
        if self.many:
            items = (value,) if isinstance(value, (str, int, float)) else value
            try:
                items = tuple(items)
            except TypeError:
                raise OptionError(name, f"{value!r} is not {self.describe()}") from None
            if not items:
                raise OptionError(name, f"no value given; expected {self.describe()}")
            each = dataclasses.replace(self, many=False, optional=False)
            return tuple(each.check(name, item) for item in items)
        return self._one(name, value)

    def _one(self, name: str, value: Any) -> Any:
        number = self._converted(value)
        if number is None:
            raise OptionError(name, f"{_value_text(value)} is not {self.describe()}")
        if self.kind in (bool, str) or isinstance(number, str):
            return number
        below = self.low is not None and (number <= self.low if self.low_open else number < self.low)
        above = self.high is not None and (number >= self.high if self.high_open else number > self.high)
        if below or above:
            raise OptionError(name, f"{_value_text(value)} is out of range: expected {self.describe()}")
        return number

    def _converted(self, value: Any) -> Any:
        """`value` as the option's kind, or None if it is not one (range aside)."""
        if isinstance(value, str) and value in self.words:
            return value
        if self.kind is bool:
            return bool(value) if isinstance(value, (bool, np.bool_)) else None
        if self.kind is str:
            return value if isinstance(value, str) and (self.choices is None or value in self.choices) else None
        if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
            return None
        if isinstance(value, (float, np.floating)) and not math.isfinite(value):
            return None
        if self.kind is int:
            return int(value) if float(value).is_integer() else None
        return float(value)


def _number_text(value: float | None) -> str:
    if value is None:
        return ""
    if value == MAX_SEED:
        return "2^63 - 1"
    if isinstance(value, float) and (abs(value) >= 1e6 or 0 < abs(value) < 1e-3):
        return f"{value:g}"
    return f"{value}" if isinstance(value, int) else f"{value:g}"


def _value_text(value: Any) -> str:
    text = repr(value) if isinstance(value, str) else str(value)
    return text if len(text) <= 40 else text[:37] + "..."


def _option(default: Any, help: str, kind: type, **spec: Any) -> Any:
    """A dataclass field declaring an option (see `_Spec` for `spec`)."""
    return dataclasses.field(default=default, metadata={"spec": _Spec(help=help, kind=kind, **spec)})


@dataclass(frozen=True)
class _Options:
    """Checks every field against its declaration when the object is made."""

    def __post_init__(self) -> None:
        for item in dataclasses.fields(self):
            object.__setattr__(self, item.name, item.metadata["spec"].check(item.name, getattr(self, item.name)))

    @classmethod
    def build(cls: type[T], options: T | None = None, **settings: Any) -> T:
        """`options` (default: all defaults) with some fields replaced, checked.

        Parameters
        ----------
        options : same class, optional
        **settings
            Field names and values; a name that is no field raises `OptionError`.
        """
        if options is not None and not isinstance(options, cls):
            raise OptionError("options", f"expected {cls.__name__}, got {type(options).__name__}")
        names = {item.name for item in dataclasses.fields(cls)}
        for name in settings:
            if name not in names:
                raise OptionError(name, f"no such option of {cls.__name__} (options: {', '.join(sorted(names))})")
        return dataclasses.replace(options if options is not None else cls(), **settings)

    def to_dict(self) -> dict:
        """The options as a JSON-ready dict (tuples as lists)."""
        return {
            key: list(value) if isinstance(value, tuple) else value for key, value in dataclasses.asdict(self).items()
        }


@dataclass(frozen=True)
class ReconstructOptions(_Options):
    """How to reconstruct a data set: photometric stereo, integration, placement, IRT-PS.

    Every field is checked when the object is made (`OptionError` names the field and its
    range). The fields of the IRT-PS group matter only for ``method="irtps"``.

    Examples
    --------
    >>> ReconstructOptions(method="irtps", bounces=2).bounces
    2
    >>> ReconstructOptions(samples=0)
    Traceback (most recent call last):
    ...
    irtps.model.options.OptionError: samples: 0 is out of range: expected an integer from 1 to 1048576
    """

    method: str = _option("ps", "reconstruction method: classic photometric stereo or IRT-PS", str, choices=METHODS)
    robust: str = _option(
        "auto",
        "observations each pixel's fit uses: auto is lobe for objects most of whose pixels take a specular lobe (lobe_share, "
        "reported in run.json), else tukey; tukey re-weights them by their residuals (shadows and highlights set aside), lobe adds a "
        "specular lobe per pixel where the observations call for one (glossy and metallic objects; seconds, not milliseconds, on a DiLiGenT object), threshold drops "
        "those below the shadow fraction (the better choice on very rough matte surfaces such as plaster), trim keeps those between the darkest two fifths and the brightest fifth, none uses all; every mode but "
        "none drops saturated ones",
        str,
        choices=ROBUST_CHOICES,
    )
    shadow_fraction: float = _option(
        0.05,
        "shadow threshold relative to a pixel's brightest observation (threshold mode, and the start of tukey)",
        float,
        low=0.0,
        high=1.0,
        high_open=True,
    )
    saturation: float | None = _option(
        None,
        "raw value at or above which an observation is saturated (default: 1 for PNG images, none for EXR)",
        float,
        low=0.0,
        low_open=True,
        optional=True,
    )
    correct_brightness: bool = _option(
        False,
        "scale each light's irradiance by its image's brightness against a first fit (the summary's brightness line) and fit "
        "again: for a rig whose recorded irradiance is off in some images (it takes the fault out of the fit; data sets "
        "whose irradiance is right move by a fraction of a degree: docs/accuracy.md, Faulty images)",
        bool,
    )
    integration: str | None = _option(
        None,
        "normal integration (default ls for ps, footprint for irtps); bilateral keeps depth discontinuities "
        "(occluding contours) that the others join with a ramp",
        str,
        choices=INTEGRATION_METHODS,
        optional=True,
    )
    base_height: float | str = _option(
        "auto",
        "height of the object's boundary (the median of its mask's edge), world units; auto: estimated from the floor around the object, "
        "or the floor's height where nothing in the images fixes it; boundary: the floor's height",
        float,
        words=PLACEMENTS,
        metavar="H|auto|boundary",
    )
    bounces: int = _option(3, "inter-reflection bounces estimated", int, low=1, high=MAX_BOUNCES, group="IRT-PS")
    iterations: int = _option(8, "largest number of corrections", int, low=0, high=MAX_ITERATIONS, group="IRT-PS")
    samples: int = _option(64, "camera paths per pixel per estimate", int, low=1, high=MAX_SAMPLES, group="IRT-PS")
    seed: int = _option(
        0, "random seed of the first estimate (pass t uses seed + t)", int, low=0, high=MAX_SEED, group="IRT-PS"
    )
    albedo_scale: float | str = _option(
        "auto",
        "factor from the fitted albedo to reflectance, for rendering the inter-reflections; auto: estimated from the images when the "
        "irradiance is relative (DiLiGenT, or irradiance relative in scene.json), 1 when it is absolute",
        float,
        low=0.0,
        high=1e6,
        low_open=True,
        words=("auto",),
        metavar="F|auto",
        group="IRT-PS",
    )
    relaxation: float | str = _option(
        "auto",
        "step toward each new estimate: auto adapts it to how the estimates converge (over-relaxes a slow convergence, damps an oscillation); "
        "a number fixes it (1 takes each new estimate whole)",
        float,
        low=0.0,
        high=2.0,
        low_open=True,
        high_open=True,
        words=("auto",),
        group="IRT-PS",
    )
    early_stop: bool = _option(
        True,
        "stop when the residual has not fallen over the last two passes beyond its Monte-Carlo noise, or after pass 1 "
        "when its correction turned the normals by less than half their standard error (the result is then classic PS's)",
        bool,
        group="IRT-PS",
    )
    denoise: bool = _option(
        True,
        "filter each estimate along the surface (3x3, guided by heights, normals and albedo) before subtracting it",
        bool,
        group="IRT-PS",
    )
    update: str = _option(
        "original", "A0 - E (original) or the paper's A_t - E_t (previous)", str, choices=UPDATES, group="IRT-PS"
    )
    stride: int = _option(
        1,
        "estimate at one pixel in SxS and interpolate (faster; 1: every pixel)",
        int,
        low=1,
        high=MAX_STRIDE,
        group="IRT-PS",
    )
    estimator: str = _option(
        "physical", "indirect estimate: physical, or the paper's heuristic", str, choices=ESTIMATORS, group="IRT-PS"
    )

    #: Default normal integration of each method: IRT-PS renders the surface again, so it
    #: needs creases kept sharp.
    DEFAULT_INTEGRATION: ClassVar[dict[str, str]] = {"ps": "ls", "irtps": "footprint"}

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.estimator == "paper" and self.bounces not in PAPER_BOUNCES:
            raise OptionError("bounces", f"the paper's estimator takes 1, 2 or 3 reflections, not {self.bounces}")

    @property
    def integration_method(self) -> str:
        """`integration`, or the method's default."""
        return self.DEFAULT_INTEGRATION[self.method] if self.integration is None else self.integration

    def to_dict(self) -> dict:
        """The options as a JSON-ready dict; IRT-PS's only for ``method="irtps"``."""
        record = super().to_dict()
        if self.method != "irtps":
            for item in dataclasses.fields(self):
                if item.metadata["spec"].group == "IRT-PS":
                    del record[item.name]
        return record


@dataclass(frozen=True)
class RenderOptions(_Options):
    """How much to render: bounces, camera paths per pixel, seed.

    Examples
    --------
    >>> RenderOptions(bounces=2).samples
    256
    """

    bounces: int = _option(4, "inter-reflection bounces to render", int, low=0, high=MAX_BOUNCES)
    samples: int = _option(256, "camera paths per pixel", int, low=1, high=MAX_SAMPLES)
    seed: int = _option(0, "random seed", int, low=0, high=MAX_SEED)


@dataclass(frozen=True)
class SynthOptions(_Options):
    """The synthetic scene of `irtps.synthesize`: size, lights, albedo, surroundings."""

    size: int = _option(96, "image width and height in pixels", int, low=8, high=MAX_SYNTH_SIZE)
    lights: int = _option(12, "number of lights", int, low=3, high=MAX_LIGHTS)
    albedo: str = _option("uniform", "albedo pattern", str, choices=("uniform", "textured"))
    environment: str = _option(
        "cornell",
        "surroundings: a Cornell box, a light box given as a mesh (grey floor and walls, an orange side wall, "
        "open at the front and top; no floor besides) or none",
        str,
        choices=("cornell", "light-box", "none"),
    )
    floor: bool | None = _option(None, "a floor (default: only with the box)", bool, optional=True)
    fill: bool = _option(
        False,
        "the object fills the frame: the shape made twice as large and its middle seen, its edges leaving the image "
        "(no floor or wall in view)",
        bool,
    )
    camera: str = _option(
        "orthographic",
        "projection: orthographic (pixel size 1), or perspective (a pinhole about 45 degrees across: focal length 1.2 "
        "times the size in pixels, its optical centre where a pixel is 1 wide on the floor)",
        str,
        choices=("orthographic", "perspective"),
    )
    lights_near: float | None = _option(
        None,
        "point lights near the object instead of distant ones (a rig's LEDs): each this many image widths from the "
        "middle of the floor, in the distant lights' directions, its intensity giving irradiance pi there",
        float,
        low=0.3,
        high=100.0,
        optional=True,
    )
    base: float | None = _option(
        None,
        "height of the object's boundary above the floor, pixel sizes, with vertical sides down to the floor (default: the shape's own)",
        float,
        low=0.0,
        high=float(MAX_SYNTH_SIZE),
        optional=True,
    )


@dataclass(frozen=True)
class TableOptions(_Options):
    """The comparison table: IRT-PS variants and their settings."""

    bounces: tuple[int, ...] = _option(
        (1, 2, 3), "IRT-PS variants: bounces estimated", int, low=1, high=MAX_BOUNCES, many=True
    )
    iterations: int = _option(8, "IRT-PS corrections at most", int, low=0, high=MAX_ITERATIONS)
    samples: int = _option(64, "camera paths per pixel per estimate", int, low=1, high=MAX_SAMPLES)
    seed: int = _option(0, "random seed", int, low=0, high=MAX_SEED)
    paper: bool = _option(True, "also the paper's own estimator (columns Paper-rN)", bool)


@dataclass(frozen=True)
class ClusterOptions(_Options):
    """The Dask cluster of a batch: a running one, or a local one of worker processes."""

    scheduler: str | None = _option(
        None,
        "run on the Dask cluster of this scheduler (e.g. tcp://head-node:8786) instead of a local one",
        str,
        optional=True,
        metavar="ADDRESS",
    )
    workers: int | None = _option(
        None,
        "local cluster: worker processes (default: cores / threads per worker)",
        int,
        low=1,
        high=MAX_WORKERS,
        optional=True,
        metavar="N",
    )
    threads_per_worker: int | None = _option(
        None,
        "local cluster: data sets per worker at once, and its Rust threads (default 1)",
        int,
        low=1,
        high=MAX_WORKERS,
        optional=True,
        metavar="T",
    )

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.scheduler is not None and (self.workers is not None or self.threads_per_worker is not None):
            raise OptionError(
                "scheduler",
                "--workers and --threads-per-worker set up the local cluster; with --scheduler, give them to 'dask worker' (--nworkers, --nthreads)",
            )


def add_arguments(
    parser: argparse.ArgumentParser | argparse._ArgumentGroup,
    cls: type[_Options],
    *,
    defaults: dict | None = None,
    groups: dict[str, str] | None = None,
) -> None:
    """Add one command-line option per field of `cls` (``--shadow-fraction`` for
    ``shadow_fraction``), with its help, default and choices.

    Parameters
    ----------
    parser : argparse.ArgumentParser
    cls : options class
    defaults : dict, optional
        Defaults that differ from the class's for this command.
    groups : dict, optional
        Titles of argument groups by the fields' group name (e.g. ``{"IRT-PS": "IRT-PS
        (--method irtps)"}``).
    """
    defaults = defaults or {}
    sections: dict[str, Any] = {}
    for item in dataclasses.fields(cls):
        spec: _Spec = item.metadata["spec"]
        target = parser
        if spec.group is not None:
            title = (groups or {}).get(spec.group, spec.group)
            target = sections.setdefault(title, parser.add_argument_group(title))
        default = defaults.get(item.name, item.default)
        flag = "--" + item.name.replace("_", "-")
        text = _help(spec, default)
        if spec.kind is bool:
            target.add_argument(flag, dest=item.name, action=argparse.BooleanOptionalAction, default=default, help=text)
            continue
        target.add_argument(
            flag,
            dest=item.name,
            type=spec.kind if spec.kind is str else _converter(spec),
            default=default,
            choices=spec.choices,
            nargs="+" if spec.many else None,
            metavar=spec.metavar,
            help=text,
        )


def _converter(spec: _Spec):
    """The command-line converter of a number option: one of its words, or its kind (an
    integer read by `irtps._shared.guarded.parse_int`, a float by `irtps._shared.guarded.parse_float`: ASCII
    decimal digits, bounded)."""

    def convert(text: str) -> Any:
        if text in spec.words:
            return text
        try:
            return int_argument(text) if spec.kind is int else parse_float(text, "value")
        except (ArgumentError, argparse.ArgumentTypeError):
            raise argparse.ArgumentTypeError(
                f"{_value_text(text)} is not {dataclasses.replace(spec, optional=False).describe()}"
            ) from None

    return convert


def int_argument(text: str) -> int:
    """An integer given on the command line (argparse's ``type``), bounded in digits.

    Raises
    ------
    argparse.ArgumentTypeError
        For anything but an integer of at most `irtps._shared.guarded.MAX_DIGITS` digits.

    Examples
    --------
    >>> int_argument("64")
    64
    """
    try:
        return parse_int(text, "value")
    except ArgumentError as error:
        raise argparse.ArgumentTypeError(f"{_value_text(text)}: {error.problem}") from None


def _help(spec: _Spec, default: Any) -> str:
    """The option's help with its range (when it is not a list of choices) and default."""
    notes = []
    if spec.choices is None and spec.kind in (int, float):
        notes.append(dataclasses.replace(spec, optional=False, many=False).describe())
    if spec.kind is bool and default is not None:
        notes.append(f"default {'on' if default else 'off'}")
    elif default is not None and "default" not in spec.help:
        notes.append(f"default {' '.join(map(str, default)) if isinstance(default, tuple) else default}")
    return f"{spec.help} ({'; '.join(notes)})" if notes else spec.help


def from_arguments(cls: type[T], args: argparse.Namespace) -> T:
    """The options given on the command line.

    Parameters
    ----------
    cls : options class
    args : argparse.Namespace
        Parsed by a parser that `add_arguments` set up for `cls` (fields it lacks take
        their defaults).
    """
    return cls(**{item.name: getattr(args, item.name) for item in dataclasses.fields(cls) if hasattr(args, item.name)})
