"""Recordings: the shipped ftdcr-v4 data set reads into SI units as its raw text and README say,
and every bad file or description gets an error naming the file, line and column."""

import csv
from pathlib import Path

import numpy as np
import pytest

from tdct_jax.calibrate_rig import equal_servo_pairs, pair_score
from tdct_jax.recording import check_tendons, read_dataset, read_recording

DATA = Path(__file__).resolve().parents[1] / "data" / "ftdcr-v4"
SERVOS = [f"servo_{i}_mm" for i in (4, 3, 9, 5, 2, 8, 6, 1, 7)]
TIP = ["tip_x", "tip_y", "tip_z"]
README_TOLERANCE = 0.05
"""mm: the data README quotes its baselines to 0.1 mm."""

# Lines: 1 columns, 2-4 samples.
BASE = """\
t_s,label,d1_mm,d2_mm,x_mm,y_mm,z_mm
0.0,rep1_a,1,2,10,20,30
0.5,rep1_a_hold,3,4,11,21,31
1.0,rep2_b,5,6,12,22,32
"""
ROLES = {"displacements": ["d1_mm", "d2_mm"], "tip": ["x_mm", "y_mm", "z_mm"], "label": "label", "time": "t_s"}


@pytest.fixture(scope="module")
def dataset():
    return read_dataset(DATA / "dataset.toml")


def write(tmp_path, text, name="rec.csv"):
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def bad(tmp_path, old, new, **roles):
    """The ValueError message of reading BASE with ``old`` replaced by ``new``."""
    assert old in BASE
    path = write(tmp_path, BASE.replace(old, new))
    with pytest.raises(ValueError) as e:
        read_recording(path, **{**ROLES, **roles})
    return path, str(e.value)


# ----------------------------------------------------------------------------- the shipped data


def test_dataset_reads_in_si(dataset):
    train, val = dataset.train, dataset.validation
    assert (len(train), len(val)) == (1620, 443)
    assert train.displacements.shape == (1620, 9) and val.tip.shape == (443, 3)
    assert train.tensions is None and train.insertions is None
    assert train.columns == val.columns and train.header == val.header
    assert [c[1] for c in train.columns if c[0] == "displacements"] == SERVOS
    assert dataset.robot == DATA / "robot.toml" and dataset.description == DATA / "dataset.toml"
    # line 5 of the raw text is the 4th sample; mm -> m, columns in the order named
    raw = (DATA / "train.csv").read_text().splitlines()
    names, row = raw[0].split(","), raw[4].split(",")
    assert train.lines[3] == 5
    assert train.labels[3] == row[names.index("pattern_label")]
    assert train.time[3] == float(row[names.index("timestamp")])
    assert np.array_equal(train.displacements[3], [float(row[names.index(c)]) / 1000 for c in SERVOS])
    assert np.array_equal(train.tip[3], [float(row[names.index(c)]) / 1000 for c in TIP])


def test_patterns_and_subset(dataset):
    val = dataset.validation
    held = val.labels == "rep1_all3_same_dir0_hold"
    assert held.sum() == 2 and set(val.patterns()[held]) == {"all3_same_dir0"}
    assert len(set(val.patterns())) == 18  # 3 kinds x 6 directions
    part = val.subset(held)
    assert len(part) == 2 and np.array_equal(part.tip, val.tip[held]) and np.array_equal(part.lines, val.lines[held])
    assert np.array_equal(val.subset(slice(10, 20)).time, val.time[10:20])
    assert np.array_equal(val.subset(np.array([5, 2])).displacements, val.displacements[[5, 2]])
    assert len(val.subset(7)) == 1 and val.subset(7).lines[0] == val.lines[7]
    assert val.subset(held).tensions is None


def test_tendon_order_and_sign(dataset):
    """Each 'tendon<i>_id<j>_pull' pattern drives column i, named servo_j_mm, positive (the rest slack)."""
    pulls = dataset.read("tendon_pull.csv")
    assert np.array_equal(pulls.displacements, dataset.train.displacements[: len(pulls)])
    names = [c[1] for c in pulls.columns if c[0] == "displacements"]
    for pattern in np.unique(pulls.patterns()):
        i, servo = (int(t) for t in pattern.removesuffix("_pull").replace("tendon", "").split("_id"))
        most = pulls.subset(pulls.patterns() == pattern).displacements.max(axis=0)
        assert int(np.argmax(most)) == i and names[i] == f"servo_{servo}_mm" and most[i] > 2e-3


def test_baselines_of_the_data_readme(dataset):
    """The data README's two model-free baselines, recomputed from the files."""
    for rec, rmse_mm in ((dataset.train, 70.9), (dataset.validation, 78.0)):
        off = rec.tip - rec.tip.mean(axis=0)
        assert abs(1000 * np.sqrt(np.mean(np.sum(off**2, axis=1))) - rmse_mm) < README_TOLERANCE
    servo = np.vstack([dataset.train.displacements, dataset.validation.displacements])
    tip = np.vstack([dataset.train.tip, dataset.validation.tip])
    close = np.abs(servo[:, None] - servo[None]).max(axis=-1) < 0.1e-3
    i, j = np.nonzero(np.triu(close, 1))
    gap_mm = 1000 * np.linalg.norm(tip[i] - tip[j], axis=1)
    assert len(i) == 147
    assert abs(np.median(gap_mm) - 5.0) < README_TOLERANCE and abs(np.sqrt(np.mean(gap_mm**2)) - 6.2) < README_TOLERANCE
    # the library's own pairs and score: the same pairs; the measured tips score 1, a model that
    # predicts one tip for both samples of every pair (here: one tip for all) 0
    pairs = equal_servo_pairs(dataset.train, dataset.validation)
    assert pairs.tolist() == np.column_stack([i, j]).tolist()
    assert pair_score(tip, tip, pairs) == 1.0 and pair_score(np.zeros_like(tip), tip, pairs) == 0.0


def test_check_tendons(dataset):
    check_tendons(dataset.train, 9)
    with pytest.raises(ValueError, match=r"train\.csv: 9 displacements column\(s\).*robot has 4 tendons"):
        check_tendons(dataset.train, 4)


# ----------------------------------------------------------------------------- a small file


def test_small_file_reads(tmp_path):
    path = write(tmp_path, "# a comment line\n\n" + BASE)
    rec = read_recording(path, **ROLES, units={})
    assert rec.name == "rec" and list(rec.lines) == [4, 5, 6]
    assert np.array_equal(rec.displacements, [[1e-3, 2e-3], [3e-3, 4e-3], [5e-3, 6e-3]])
    assert list(rec.patterns()) == ["a", "a", "b"]
    assert rec.columns[0] == ("label", "label", "") and ("time", "t_s", "s") in rec.columns
    other = read_recording(write(tmp_path, BASE.replace("d1_mm", "d1")), displacements=["d1"], units={"d1": "um"})
    assert np.array_equal(other.displacements[:, 0], [1e-6, 3e-6, 5e-6]) and list(other.labels) == ["", "", ""]
    assert other.tip is None and other.time is None


# ----------------------------------------------------------------------------- bad input


def test_missing_or_unreadable_file(tmp_path):
    with pytest.raises(ValueError, match=r"nothing\.csv: cannot read recording"):
        read_recording(tmp_path / "nothing.csv", **ROLES)
    path = tmp_path / "latin1.csv"
    path.write_bytes(BASE.replace("label", "l\xe4bel").encode("latin-1"))
    with pytest.raises(ValueError, match=r"latin1\.csv: cannot read recording: not UTF-8"):
        read_recording(path, **ROLES)


@pytest.mark.parametrize("text", ["", "\n\n", "# only a comment\n"])
def test_empty_file(tmp_path, text):
    path = write(tmp_path, text)
    with pytest.raises(ValueError, match=rf"{path}: empty file: no column line"):
        read_recording(path, **ROLES)


def test_no_samples(tmp_path):
    path = write(tmp_path, BASE.splitlines()[0] + "\n")
    with pytest.raises(ValueError, match=rf"{path}:1: no samples"):
        read_recording(path, **ROLES)


def test_missing_column(tmp_path):
    path, message = bad(tmp_path, "d2_mm", "d3_mm")
    assert message.startswith(f"{path}:1: missing column(s) ['d2_mm']; columns present: ['t_s', 'label', 'd1_mm', 'd3_mm'")


def test_units_not_stated(tmp_path):
    path, message = bad(tmp_path, "x_mm", "x", tip=["x", "y_mm", "z_mm"])
    assert message.startswith(f"{path}:1: column 'x' (tip): units not stated") and "allowed for tip: m, mm, um" in message


def test_unknown_unit_and_unit_of_another_role(tmp_path):
    path, message = bad(tmp_path, "x_mm", "x", tip=["x", "y_mm", "z_mm"], units={"x": "cm"})
    assert message.startswith(f"{path}: unknown unit 'cm' for column 'x'; known units: m, mm, um, N, s, deg, rad")
    path, message = bad(tmp_path, "d2_mm", "d2_N", displacements=["d1_mm", "d2_N"])
    assert message.startswith(f"{path}:1: column 'd2_N' is in N, which does not fit displacements; allowed")
    path, message = bad(tmp_path, "x_mm", "x_mm", units={"x_mm": "m"})
    assert message.startswith(f"{path}:1: column 'x_mm' (tip) is in mm by its name but units gives 'm'")
    path, message = bad(tmp_path, "x_mm", "x_mm", units={"w": "m"})
    assert message.startswith(f"{path}: units given for column(s) ['w'] that are not read")


@pytest.mark.parametrize(
    ("cell", "says"),
    [("abc", "'abc' is not a number"), ("nan", "nan is not finite"), ("-inf", "-inf is not finite"), ("", "'' is not a number")],
)
def test_bad_cell(tmp_path, cell, says):
    path, message = bad(tmp_path, "3,4,11", f"3,{cell},11")
    assert message.startswith(f"{path}:3: d2_mm = {says}")


def test_row_with_other_field_count(tmp_path):
    path, message = bad(tmp_path, "5,6,12", "5,6,7,12")
    assert message.startswith(f"{path}:4: row has 8 fields, the column line (line 1) has 7")


def test_wrong_tip_count(tmp_path):
    path, message = bad(tmp_path, "x_mm", "x_mm", tip=["x_mm", "y_mm"])
    assert message.startswith(f"{path}: tip needs 3 columns (x, y, z of the measured tip), got 2: ['x_mm', 'y_mm']")


def test_duplicate_or_reused_columns(tmp_path):
    path, message = bad(tmp_path, "d2_mm", "d1_mm", displacements=["d1_mm"])
    assert message.startswith(f"{path}:1: duplicate column name(s) ['d1_mm']")
    path, message = bad(tmp_path, "x_mm", "x_mm", displacements=["d1_mm", "x_mm"])
    assert message.startswith(f"{path}: column(s) ['x_mm'] given for more than one role")


def test_nothing_to_read(tmp_path):
    path = write(tmp_path, BASE)
    with pytest.raises(ValueError, match=rf"{path}: no columns to read"):
        read_recording(path, time="t_s")


def test_tendon_count_names_the_file(tmp_path):
    rec = read_recording(write(tmp_path, BASE), **ROLES)
    with pytest.raises(
        ValueError, match=rf"{tmp_path / 'rec.csv'}: 2 displacements column\(s\) \['d1_mm', 'd2_mm'\], but the robot has 9"
    ):
        check_tendons(rec, 9)


# ----------------------------------------------------------------------------- data set descriptions

DESCRIPTION = """\
train = "train.csv"
validation = "val.csv"
label = "label"
time = "t"
displacements = ["d1_mm", "d2_mm"]
tip = ["x_mm", "y_mm", "z_mm"]

[units]
t = "s"
"""


def description(tmp_path, text=DESCRIPTION, validation=BASE):
    write(tmp_path, BASE.replace("t_s", "t"), "train.csv")
    write(tmp_path, validation.replace("t_s", "t"), "val.csv")
    return write(tmp_path, text, "dataset.toml")


def test_small_dataset(tmp_path):
    data = read_dataset(description(tmp_path))
    assert data.robot is None and np.array_equal(data.validation.time, [0, 0.5, 1.0])
    assert data.train.path == tmp_path / "train.csv" and data.validation.name == "val"


def test_validation_with_other_columns(tmp_path):
    """Columns the description reads are checked in each file, the file that lacks one named;
    the files must then agree on the rest."""
    path = description(tmp_path, validation=BASE.replace("d2_mm", "d2_m"))
    with pytest.raises(ValueError, match=rf"^{tmp_path / 'val.csv'}:1: missing column\(s\) \['d2_mm'\]"):
        read_dataset(path)
    write(tmp_path, BASE.replace("t_s", "t").replace("d2_mm", "d2_m"), "train.csv")
    write(tmp_path, BASE.replace("t_s", "t"), "val.csv")
    with pytest.raises(ValueError, match=rf"^{tmp_path / 'train.csv'}:1: missing column\(s\) \['d2_mm'\]"):
        read_dataset(path)
    write(tmp_path, BASE.replace("t_s", "t"), "train.csv")
    write(tmp_path, BASE.replace("t_s", "t").replace("label,", "pattern,"), "val.csv")
    path = write(tmp_path, DESCRIPTION.replace('label = "label"\n', ""), "dataset.toml")
    with pytest.raises(ValueError) as e:
        read_dataset(path)
    message = str(e.value)
    assert message.startswith(
        f"{tmp_path / 'val.csv'}:1: the validation file's columns differ from the training file {tmp_path / 'train.csv'}'s"
    )
    assert "only in train.csv: ['label']; only in val.csv: ['pattern']" in message


@pytest.mark.parametrize(
    ("old", "new", "says"),
    [
        ('train = "train.csv"', "", "missing key train"),
        ('time = "t"', 'tyme = "t"', "unknown key 'tyme' (did you mean 'time'?)"),
        ('["x_mm", "y_mm", "z_mm"]', '"x_mm"', "tip = 'x_mm' must be a list of column names"),
        ('t = "s"', 't = "s"\nw = "m"', "[units] names column(s) ['w'] that the description does not read"),
        ('t = "s"', 't = "h"', "unknown unit 'h' for column 't'"),
        ("[units]", "[units", "cannot read dataset description"),
    ],
)
def test_bad_description(tmp_path, old, new, says):
    path = description(tmp_path, DESCRIPTION.replace(old, new))
    with pytest.raises(ValueError) as e:
        read_dataset(path)
    assert str(path) in str(e.value) and says in str(e.value)


def test_raw_reader_agrees(dataset):
    """The csv module's reading of val.csv, column by column, is what the Recording holds (mm / 1000)."""
    with open(DATA / "val.csv", newline="", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    assert np.array_equal(dataset.validation.tip, np.array([[float(r[c]) for c in TIP] for r in rows]) / 1000)
    assert np.array_equal(dataset.validation.displacements, np.array([[float(r[c]) for c in SERVOS] for r in rows]) / 1000)
    assert list(dataset.validation.labels) == [r["pattern_label"] for r in rows]
