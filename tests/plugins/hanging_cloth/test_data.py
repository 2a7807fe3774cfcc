"""Tests of physinfer_hanging_cloth.data: the Bouman-format loader, its averaging and its errors.

The loader only lists video files, so the videos here are empty files with the right names.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from physinfer.errors import UserInputError
from physinfer_hanging_cloth.data import (
    find_table,
    load_dataset,
    load_ground_truth,
    parse_video_name,
)
from physinfer_hanging_cloth.units import LBF_IN2_IN_N_M2, OZ_PER_YD2_IN_G_PER_M2

HEADER = "fabric,area_weight_1 [oz/yd^2],area_weight_2 [oz/yd^2],stiffness_1 [lbf*in^2],stiffness_2 [lbf*in^2]"
ROWS = ["silk,2.0,2.2,0.01,0.03", "denim,12.0,12.0,0.08,0.1", "cotton,5.0,5.4,0.02,0.02"]


def make_dataset(root: Path, header: str = HEADER, rows: list[str] = ROWS, videos: list[str] | None = None) -> Path:
    root.mkdir(parents=True, exist_ok=True)
    (root / "ground_truth.csv").write_text("\n".join([header, *rows]) + "\n")
    (root / "videos").mkdir(exist_ok=True)
    names = videos if videos is not None else [
        f"{row.split(',')[0]}_W{k}.mp4" for row in rows for k in (1, 2, 3)
    ]
    for name in names:
        (root / "videos" / name).write_bytes(b"")
    return root


def test_measurements_are_averaged_in_canonical_units(tmp_path):
    truth = load_ground_truth(make_dataset(tmp_path / "d") / "ground_truth.csv")
    assert list(truth) == ["silk", "denim", "cotton"]
    assert truth["silk"].area_weight == pytest.approx(2.1)
    assert truth["silk"].stiffness == pytest.approx(0.02)
    assert truth["silk"].stiffness_measurements == pytest.approx((0.01, 0.03))
    assert truth["cotton"].area_weight == pytest.approx(5.2)


def test_other_units_are_converted(tmp_path):
    header = "Fabric,Area weight 1 (g/m²),area weight 2 (g/m2),bending stiffness warp [N·m^2],stiffness weft [mN*m^2]"
    rows = [f"silk,{2 * OZ_PER_YD2_IN_G_PER_M2},{2.2 * OZ_PER_YD2_IN_G_PER_M2},{0.01 * LBF_IN2_IN_N_M2},"
            f"{0.03 * LBF_IN2_IN_N_M2 * 1e3}"]
    truth = load_ground_truth(make_dataset(tmp_path / "d", header, rows) / "ground_truth.csv")
    assert truth["silk"].area_weight == pytest.approx(2.1)
    assert truth["silk"].stiffness == pytest.approx(0.02)


def test_a_single_measurement_column_and_empty_cells_are_fine(tmp_path):
    header = "fabric,note,area_weight [oz/yd^2],stiffness_1 [lbf*in^2],stiffness_2 [lbf*in^2]"
    truth = load_ground_truth(make_dataset(tmp_path / "d", header, ["silk,shiny,3,0.02,"]) / "ground_truth.csv")
    assert truth["silk"].area_weight == 3.0 and truth["silk"].stiffness == 0.02


def test_xlsx_table_reads_like_csv(tmp_path):
    import openpyxl

    root = make_dataset(tmp_path / "d")
    (root / "ground_truth.csv").unlink()
    book = openpyxl.Workbook()
    sheet = book.active
    sheet.append(HEADER.split(","))
    for row in ROWS:
        name, *values = row.split(",")
        sheet.append([name, *(float(v) for v in values)])
    book.save(root / "ground_truth.xlsx")
    dataset = load_dataset(root)
    assert dataset.table.name == "ground_truth.xlsx"
    assert dataset.fabrics["denim"].stiffness == pytest.approx(0.09)


def test_dataset_orders_videos_and_builds_log_targets(tmp_path):
    dataset = load_dataset(make_dataset(tmp_path / "d"))
    assert dataset.n_fabrics == 3 and len(dataset.videos) == 9
    assert [(v.fabric, v.fan_level) for v in dataset.videos[:4]] == [
        ("silk", "W1"), ("silk", "W2"), ("silk", "W3"), ("denim", "W1"),
    ]
    np.testing.assert_array_equal(dataset.groups(), [0, 0, 0, 1, 1, 1, 2, 2, 2])
    targets = dataset.targets()
    assert targets["stiffness"][0] == pytest.approx(np.log(0.02))
    assert targets["area_weight"][3] == pytest.approx(np.log(12.0))


def test_fabrics_may_miss_some_fan_levels_and_other_files_are_ignored(tmp_path):
    names = ["silk_W1.mp4", "denim_w2.avi", "cotton_W3.gif", "README.txt", ".hidden.mp4"]
    dataset = load_dataset(make_dataset(tmp_path / "d", videos=names))
    assert [(v.fabric, v.fan_level) for v in dataset.videos] == [("silk", "W1"), ("denim", "W2"), ("cotton", "W3")]


def test_video_names():
    assert parse_video_name(Path("my_fabric_W3.mp4")) == ("my_fabric", "W3")
    with pytest.raises(UserInputError, match="<fabric>_W1"):
        parse_video_name(Path("silk.mp4"))


# -- every bad input ends in a UserInputError that says what is wrong -----------------------------


def test_missing_directory(tmp_path):
    with pytest.raises(UserInputError, match="does not exist"):
        load_dataset(tmp_path / "nope")


def test_missing_ground_truth(tmp_path):
    (tmp_path / "videos").mkdir()
    with pytest.raises(UserInputError, match="no ground truth"):
        find_table(tmp_path)
    with pytest.raises(UserInputError, match="no ground truth"):
        load_dataset(tmp_path)
    with pytest.raises(UserInputError, match="does not exist"):
        load_ground_truth(tmp_path / "ground_truth.csv")


def test_missing_video_folder_and_no_videos(tmp_path):
    root = make_dataset(tmp_path / "d", videos=[])
    with pytest.raises(UserInputError, match="no videos"):
        load_dataset(root)
    (root / "videos").rmdir()
    with pytest.raises(UserInputError, match="no video folder"):
        load_dataset(root)


def test_missing_videos_of_a_fabric(tmp_path):
    root = make_dataset(tmp_path / "d", videos=["silk_W1.mp4", "denim_W1.mp4"])
    with pytest.raises(UserInputError, match=r"missing videos.*cotton"):
        load_dataset(root)


def test_unknown_fabric(tmp_path):
    names = [f"{f}_W1.mp4" for f in ("silk", "denim", "cotton", "velvet")]
    with pytest.raises(UserInputError, match=r"unknown fabrics \['velvet'\]"):
        load_dataset(make_dataset(tmp_path / "d", videos=names))


def test_misnamed_and_duplicate_videos(tmp_path):
    with pytest.raises(UserInputError, match="not named"):
        load_dataset(make_dataset(tmp_path / "a", videos=["silk_W1.mp4", "silk-fast.mp4"]))
    with pytest.raises(UserInputError, match="two videos"):
        load_dataset(make_dataset(tmp_path / "b", videos=["silk_W1.mp4", "silk_W1.avi"]))


def test_too_few_fabrics(tmp_path):
    with pytest.raises(UserInputError, match="at least 3"):
        load_dataset(make_dataset(tmp_path / "d", rows=ROWS[:2]))


@pytest.mark.parametrize(
    ("header", "row", "message"),
    [
        ("name,area_weight [oz/yd^2],stiffness [lbf*in^2]", "silk,2,0.02", "no 'fabric' column"),
        ("fabric,area_weight [oz/yd^2]", "silk,2", "no stiffness column"),
        ("fabric,stiffness [lbf*in^2]", "silk,0.02", "no area_weight column"),
        ("fabric,area_weight,stiffness [lbf*in^2]", "silk,2,0.02", "has no unit"),
        ("fabric,area_weight [furlong],stiffness [lbf*in^2]", "silk,2,0.02", "unknown area weight unit"),
        ("fabric,area_weight [oz/yd^2],stiffness [oz/yd^2]", "silk,2,0.02", "unknown stiffness unit"),
        ("fabric,area_weight [oz/yd^2],stiffness [lbf*in^2]", "silk,heavy,0.02", "not a number"),
        ("fabric,area_weight [oz/yd^2],stiffness [lbf*in^2]", "silk,2,-0.02", "positive"),
        ("fabric,area_weight [oz/yd^2],stiffness [lbf*in^2]", "silk,2,", "no stiffness measurement"),
        ("fabric,area_weight [oz/yd^2],stiffness [lbf*in^2]", ",2,0.02", "no fabric name"),
    ],
)
def test_bad_tables(tmp_path, header, row, message):
    root = make_dataset(tmp_path / "d", header, [row], videos=["silk_W1.mp4"])
    with pytest.raises(UserInputError, match=message):
        load_ground_truth(root / "ground_truth.csv")


def test_duplicate_fabric_and_header_only(tmp_path):
    root = make_dataset(tmp_path / "a", rows=[ROWS[0], ROWS[0]])
    with pytest.raises(UserInputError, match="appears twice"):
        load_ground_truth(root / "ground_truth.csv")
    root = make_dataset(tmp_path / "b", rows=[])
    with pytest.raises(UserInputError, match="at least one fabric"):
        load_ground_truth(root / "ground_truth.csv")


def test_unreadable_xlsx_and_other_suffix(tmp_path):
    (tmp_path / "ground_truth.xlsx").write_text("not a zip file")
    with pytest.raises(UserInputError, match="cannot read"):
        load_ground_truth(tmp_path / "ground_truth.xlsx")
    (tmp_path / "table.ods").write_text("")
    with pytest.raises(UserInputError, match=".csv or .xlsx"):
        load_ground_truth(tmp_path / "table.ods")
