"""Options: each declared once, validated once, named with its range, for every command.

The command line, the Python API and batch runs all go through `irtps.model.options`; a value out
of range is refused before anything runs, as one line naming the option and its range.
"""

import dataclasses
import pickle
import shutil
from pathlib import Path

import pytest

import irtps
from irtps.cli.main import main
from irtps.cli.parser import build_parser
from irtps.irt.interreflection import remove_interreflections
from irtps.model.options import (
    ClusterOptions,
    OptionError,
    ReconstructOptions,
    RenderOptions,
    SynthOptions,
    TableOptions,
)

DATA = Path(__file__).parent / "data"
BALL = DATA / "diligent_ball_small"
MITSUBA = DATA / "mitsuba_small" / "cap_cornell"

#: Values out of range for integer options (as typed on a command line).
ABSURD_INTEGERS = ["-1", str(2**64), str(2**70)]

#: (command, data fixture, the options that command takes, the rest of its arguments).
COMMANDS = {
    "reconstruct": ("ball", ["--seed", "--samples", "--bounces", "--iterations", "--stride"], ["--method", "irtps"]),
    "render": ("mitsuba", ["--seed", "--samples", "--bounces"], []),
    "synth": (None, ["--seed", "--samples", "--bounces", "--size", "--lights"], []),
    "table": ("ball", ["--seed", "--samples", "--bounces", "--iterations"], []),
    "demo": (None, ["--seed", "--samples", "--bounces", "--iterations"], []),
    "batch": ("ball", ["--seed", "--samples", "--bounces", "--iterations", "--workers", "--threads-per-worker"], []),
}


def _argv(command, data, option, value, out):
    fixture, _, rest = COMMANDS[command]
    head = {"synth": ["synth", "cap"], "demo": ["demo"]}.get(command, [command, str(data)])
    return [*head, "--out", str(out), option, value, *rest, "--quiet"]


def _snapshot(folder):
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


CASES = [
    (command, option, value)
    for command, (_, options, _) in COMMANDS.items()
    for option in options
    for value in ABSURD_INTEGERS
]


@pytest.mark.parametrize("command, option, value", CASES)
def test_an_integer_out_of_range_is_one_named_error_with_its_range(command, option, value, tmp_path, capsys):
    fixture = COMMANDS[command][0]
    data = tmp_path / "data"
    if fixture is not None:
        shutil.copytree({"ball": BALL, "mitsuba": MITSUBA}[fixture], data)
    before = _snapshot(tmp_path)
    assert main(_argv(command, data, option, value, tmp_path / "out")) == 2
    err = capsys.readouterr().err
    assert (
        err.startswith(f"irtps: error: {option}: {value} is out of range: expected an integer from ")
        and err.count("\n") == 1
    ), err
    assert "Traceback" not in err
    assert _snapshot(tmp_path) == before  # nothing written, the input as it was


@pytest.mark.parametrize(
    "argv, message",
    [
        (
            ["reconstruct", str(BALL), "--shadow-fraction", "1"],
            "--shadow-fraction: 1.0 is out of range: expected a finite number in [0, 1)",
        ),
        (
            ["reconstruct", str(BALL), "--relaxation", "0"],
            "--relaxation: 0.0 is out of range: expected a finite number in (0, 2) or auto",
        ),
        (
            ["reconstruct", str(BALL), "--base-height", "inf"],
            "--base-height: inf is not a finite number, auto or boundary",
        ),
        (
            ["reconstruct", str(BALL), "--base-height", "1e308"],
            "--base-height: 1e+308 is out of range for this data set",
        ),
        (
            ["reconstruct", str(BALL), "--base-height", "nan"],
            "--base-height: nan is not a finite number, auto or boundary",
        ),
        (
            ["reconstruct", str(BALL), "--estimator", "paper", "--bounces", "4"],
            "--bounces: the paper's estimator takes 1, 2 or 3 reflections, not 4",
        ),
        (["table", str(BALL), "--bounces", "1", "0"], "--bounces: 0 is out of range: expected an integer from 1 to 64"),
        (
            ["batch", str(BALL), "--workers", "2", "--scheduler", "tcp://nowhere:1"],
            "--scheduler: --workers and --threads-per-worker set up the local cluster",
        ),
    ],
)
def test_other_values_out_of_range_name_the_option(argv, message, tmp_path, capsys):
    assert main([*argv, "--out", str(tmp_path / "out"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("irtps: error: ") and message in err and err.count("\n") == 1, err
    assert list(tmp_path.iterdir()) == []


def test_the_api_raises_one_error_that_is_a_value_error_naming_the_option():
    data = irtps.load_dataset(BALL)
    for call in (
        lambda: irtps.reconstruct(data, seed=-1),
        lambda: irtps.reconstruct(data, "irtps", samples=2**70),
        lambda: remove_interreflections(data, bounces=0),
        lambda: irtps.render(data.scene, data.images[0, ..., 0], data.images[0], data.mask, seed=2**64),
    ):
        with pytest.raises(OptionError) as caught:
            call()
        assert isinstance(caught.value, ValueError) and isinstance(caught.value, irtps.IrtpsError)
        assert "out of range: expected an integer from" in str(caught.value)
    with pytest.raises(OptionError, match="samplez: no such option of ReconstructOptions"):
        irtps.reconstruct(data, samplez=3)


def test_reconstruct_records_the_options_it_used_with_defaults_resolved():
    data = irtps.load_dataset(BALL)
    result = irtps.reconstruct(data, options=ReconstructOptions(shadow_fraction=0.1))
    assert result.parameters == {
        "method": "ps",
        "robust": "auto",  # what was asked; the mode it chose is recorded beside
        "shadow_fraction": 0.1,
        "saturation": 1.0,  # PNG images saturate at their maximum
        "correct_brightness": False,
        "integration": "ls",
        "base_height": "auto",
    }
    assert result.robust_used == "tukey"  # a matte ball


@pytest.mark.parametrize("cls", [ReconstructOptions, RenderOptions, SynthOptions, TableOptions, ClusterOptions])
def test_options_pickle_and_every_field_is_on_the_command_line(cls):
    options = cls()
    assert pickle.loads(pickle.dumps(options)) == options
    commands = {
        ReconstructOptions: "reconstruct",
        RenderOptions: "render",
        SynthOptions: "synth",
        TableOptions: "table",
        ClusterOptions: "batch",
    }
    help_text = _help(commands[cls])
    for item in dataclasses.fields(cls):
        assert "--" + item.name.replace("_", "-") in help_text, item.name


def _help(command):
    parser = build_parser()
    subparsers = next(action for action in parser._actions if action.dest == "command")
    return subparsers.choices[command].format_help()


def test_the_command_line_reaches_every_reconstruction_option(tmp_path):
    args = build_parser().parse_args(
        [
            "reconstruct",
            str(BALL),
            "--out",
            str(tmp_path),
            "--relaxation",
            "0.5",
            "--base-height",
            "boundary",
            "--method",
            "irtps",
            "--robust",
            "trim",
        ]
    )
    options = irtps.model.options.from_arguments(ReconstructOptions, args)
    assert options == ReconstructOptions(method="irtps", relaxation=0.5, base_height="boundary", robust="trim")


@pytest.mark.parametrize(
    "argv, message",
    [
        (
            ["reconstruct", str(BALL), "--out", "o", "--samples", "1.5"],
            "argument --samples: '1.5' is not an integer from 1 to 1048576",
        ),
        (
            ["render", str(MITSUBA), "--out", "o", "--seed", "abc"],
            "argument --seed: 'abc' is not an integer from 0 to 2^63 - 1",
        ),
        (
            ["reconstruct", str(BALL), "--out", "o", "--iterations", "9" * 5000],
            "argument --iterations: '999999999999999999999999999999999999... is not an integer",
        ),
        (
            ["demo", "--size", "9" * 5000],
            "argument --size: '999999999999999999999999999999999999...: an integer with 5000 digits; at most 40 are accepted",
        ),
        (
            ["reconstruct", str(BALL), "--out", "o", "--base-height", "high"],
            "argument --base-height: 'high' is not a finite number, auto or boundary",
        ),
        # Python's float() reads these as 10 and 0.5; a number on the command line is ASCII decimal
        (
            ["reconstruct", str(BALL), "--out", "o", "--saturation", "1_0"],
            "argument --saturation: '1_0' is not a finite number above 0",
        ),
        (
            ["reconstruct", str(BALL), "--out", "o", "--saturation", "\u0660.\u0665"],
            "argument --saturation: '\u0660.\u0665' is not a finite number above 0",
        ),
        (
            ["reconstruct", str(BALL), "--out", "o", "--method", "mitsuba"],
            "argument --method: invalid choice: 'mitsuba'",
        ),
        (["table", str(BALL), "--bounces"], "argument --bounces: expected at least one argument"),
    ],
)
def test_a_value_of_the_wrong_kind_is_one_line_too(argv, message, capsys):
    with pytest.raises(SystemExit) as exit_:
        main(argv)
    assert exit_.value.code == 2
    err = capsys.readouterr().err
    assert err.startswith(f"irtps: error: {message}") and err.endswith("--help')\n") and err.count("\n") == 1, err
