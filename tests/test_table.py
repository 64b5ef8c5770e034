"""The paper's comparison table and the demo, run as a user would."""

import json

import pytest

import irtps
from irtps.cli.main import main
from irtps.evaluate.table import ROWS, comparison_table, format_table


@pytest.fixture(scope="module")
def two_scenes(tmp_path_factory):
    root = tmp_path_factory.mktemp("scenes")
    folders = []
    for shape, seed in (("cap", 1), ("relief", 2)):
        data, _ = irtps.synthesize(shape, size=24, lights=8, environment="cornell", bounces=3, samples=32, seed=seed)
        irtps.save_dataset(data, root / shape)
        folders.append(root / shape)
    return folders


def test_table_has_the_papers_layout_and_marks_the_best(two_scenes, tmp_path, capsys):
    out = tmp_path / "table"
    assert (
        main(
            [
                "table",
                *map(str, two_scenes),
                "--out",
                str(out),
                "--bounces",
                "1",
                "3",
                "--iterations",
                "2",
                "--samples",
                "32",
                "--quiet",
            ]
        )
        == 0
    )
    printed = capsys.readouterr().out
    assert "| **cap** | PS | IRTPSr1 | IRTPSr3 | Paper-r1 | Paper-r3 |" in printed
    assert "| **Overall** | PS | IRTPSr1 | IRTPSr3 | Paper-r1 | Paper-r3 |" in printed
    assert (out / "table.md").read_text() in printed
    table = json.loads((out / "table.json").read_text())
    assert table["methods"] == ["PS", "IRTPSr1", "IRTPSr3", "Paper-r1", "Paper-r3"]
    assert set(table["datasets"]) == {"cap", "relief"}
    for key in table["rows"]:
        values = [table["datasets"][name]["PS"][key] for name in ("cap", "relief")]
        if None not in values:
            assert table["overall"]["PS"][key] == pytest.approx(sum(values) / 2)
    for label, _ in ROWS:
        row = next(line for line in printed.splitlines() if line.startswith(f"| {label} |"))
        assert row.count("**") == 2  # exactly one best value per row


def test_irtps_beats_classic_ps_in_a_cornell_box(two_scenes):
    data = irtps.load_dataset(two_scenes[0])
    table = comparison_table([("cap", data)], bounces=(3,), iterations=3, samples=64, paper=False)
    ps, irt = table["datasets"]["cap"]["PS"], table["datasets"]["cap"]["IRTPSr3"]
    assert irt["normal_mean_angular_deg"] < 0.7 * ps["normal_mean_angular_deg"]
    assert irt["height_error_aligned"] < ps["height_error_aligned"]
    assert format_table(table).count("| **cap** |") == 1


def test_demo_writes_everything_it_announces(tmp_path, capsys):
    out = tmp_path / "demo"
    assert main(["demo", "--out", str(out), "--size", "24", "--samples", "32", "--iterations", "2", "--quiet"]) == 0
    printed = capsys.readouterr().out
    assert "| **cap_cornell** | PS | IRTPSr1 | IRTPSr2 | IRTPSr3 | Paper-r1 | Paper-r2 | Paper-r3 |" in printed
    assert str(out) in printed
    assert irtps.load_dataset(out / "data").gt is not None
    for method in ("PS", "IRTPSr1", "IRTPSr2", "IRTPSr3"):
        assert (out / "cap_cornell" / method / "mesh.ply").is_file()
    assert (out / "table.md").is_file() and (out / "table.json").is_file()
    # The reconstructions name the data set they came from, so a report finds its ground truth.
    assert f"irtps report {out / 'cap_cornell' / 'IRTPSr3'}" in printed
    assert json.loads((out / "cap_cornell" / "IRTPSr3" / "run.json").read_text())["source"] == str(
        (out / "data").resolve()
    )


def test_table_needs_ground_truth(tmp_path, capsys):
    data, _ = irtps.synthesize("cap", size=16, lights=4, bounces=0, environment="none")
    data.gt = None
    irtps.save_dataset(data, tmp_path / "nogt")
    assert main(["table", str(tmp_path / "nogt"), "--quiet"]) == 2
    assert "ground truth" in capsys.readouterr().err


def test_two_data_sets_of_one_name_both_get_a_block(two_scenes, tmp_path, capsys):
    twin = tmp_path / "elsewhere" / "cap"
    twin.parent.mkdir()
    twin.symlink_to(two_scenes[0])  # the same folder name in another place
    out = tmp_path / "table"
    argv = [
        "table",
        str(two_scenes[0]),
        str(twin),
        "--out",
        str(out),
        "--bounces",
        "1",
        "--iterations",
        "0",
        "--no-paper",
        "--quiet",
    ]
    assert main(argv) == 0
    printed = capsys.readouterr().out
    assert "| **cap** |" in printed and "| **cap-2** |" in printed
    table = json.loads((out / "table.json").read_text())
    assert list(table["datasets"]) == ["cap", "cap-2"]
    assert table["datasets"]["cap"] == table["datasets"]["cap-2"]  # the same data set twice


def test_the_api_refuses_two_data_sets_under_one_name(two_scenes):
    data = irtps.load_dataset(two_scenes[0])
    with pytest.raises(irtps.IrtpsError, match="datasets: the name 'cap' is given to more than one data set"):
        comparison_table([("cap", data), ("cap", data)], bounces=(1,), iterations=0, paper=False)
