"""Plausibility notes (issue 48): one table of ranges by kind of quantity for every robot field,
robot file, scene and recording; refusals of empty robot files, files without [[sections]] and
tendon channels too large for the body; a converged shape whose tendon path folds gets a note.
Everything but the last two tests stops before any solve."""

import contextlib
import dataclasses
import re
import shutil
import warnings
from pathlib import Path

import jax
import numpy as np
import pytest

import tdct_jax as tdct
from tdct_jax.checks import KINDS
from tdct_jax.cli import main
from tdct_jax.description import PAPER, ROBOTS
from tdct_jax.options import DEFAULT_SOLVER
from tdct_jax.recording import read_dataset
from tdct_jax.scene import SCENES, read_scene
from tdct_jax.solve import problem

TWO = ROBOTS / "two_segment.toml"
FTDCR = Path(__file__).resolve().parents[1] / "data" / "ftdcr-v4"


@contextlib.contextmanager
def _no_notes():
    """A UnitWarning inside fails the test."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", tdct.UnitWarning)
        yield


def _mm_file(tmp_path):
    """two_segment.toml written in millimetres."""
    text = TWO.read_text()
    for old, new in (("length = 0.4", "length = 400"), ("end = 0.2", "end = 200"), ("end = 0.4", "end = 400")):
        text = text.replace(old, new)
    path = tmp_path / "mm.toml"
    path.write_text(text.replace("0.0014", "1.4").replace("offset = 0.010", "offset = 10"))
    return path


def test_every_field_and_paper_name_has_a_kind():
    for cls in (tdct.Section, tdct.Tendon, tdct.Tube, tdct.PointMass):
        assert set(KINDS[cls.__name__]) == {f.name for f in dataclasses.fields(cls)}, cls.__name__
    assert set(KINDS["paper"]) == set(PAPER) and KINDS["Robot"] == {"length": "length"}


SECTION = dict(end=0.2, outer_diameter=0.001, E=2e11, nu=0.3, density=7800.0)


@pytest.mark.parametrize(
    "make, words",
    [
        (
            lambda: tdct.Section(**SECTION | dict(E=200.0)),
            "Section.E = 200 Pa is far outside the plausible range [1000, 1e+12] Pa: "
            "did you mean 200 MPa (2e+08 Pa), 200 kPa (200000 Pa) or 200 GPa (2e+11 Pa)?",
        ),
        (lambda: tdct.Section(**SECTION | dict(outer_diameter=4.0)), "did you mean 4 millimetres (0.004 m)?"),
        (lambda: tdct.Section(**SECTION | dict(density=7.8)), "did you mean 7.8 g/cm^3 (7800 kg/m^3)?"),
        (
            lambda: tdct.Tendon(offset=5.0, angle=0.0),
            "Tendon.offset = 5 m is far outside the plausible range [0, 0.5] m: did you mean 5 millimetres (0.005 m)?",
        ),
        (
            lambda: tdct.Tendon(offset=0.005, angle=90.0),
            "Tendon.angle = 90 rad is far outside the plausible range [0, 6.28319] rad",
        ),
        (lambda: tdct.Tube(4.0, 1.1e-3, 83e9, 0.33, 6450.0), "Tube.outer_diameter = 4 m"),
        (
            lambda: tdct.Tube(1.4e-3, 1.1e-3, 83.0, 0.33, 6450.0),
            "Tube.E = 83 Pa is far outside the plausible range [1e+07, 1e+12] Pa: did you mean 83 GPa (8.3e+10 Pa)?",
        ),
        (
            lambda: tdct.PointMass(0.1, 20.0),
            "PointMass.mass = 20 kg is far outside the plausible range [0, 10] kg: did you mean 20 grams (0.02 kg)?",
        ),
        (
            lambda: tdct.Robot.paper(E_silicone=0.85),
            "E_silicone = 0.85 Pa is far outside the plausible range [1000, 1e+09] Pa: did you mean 0.85 MPa (850000 Pa)?",
        ),
        (lambda: tdct.Robot.paper(tendon_angles=(90.0, 180.0, 270.0, 0.0)), "tendon_angles[0] = 90 rad"),
    ],
)
def test_constructors_get_notes_from_the_one_table(make, words):
    with pytest.warns(tdct.UnitWarning) as caught:
        make()
    assert [str(w.message) for w in caught if words in str(w.message)], [str(w.message) for w in caught]
    assert len(caught) == 1 and caught[0].filename == __file__


def test_robot_level_notes_length_and_a_diameter_larger_than_it():
    sec = tdct.Section(**SECTION | dict(end=400.0))
    with pytest.warns(tdct.UnitWarning, match=r"^length = 400 m is far outside .* did you mean 400 millimetres \(0.4 m\)\?$"):
        tdct.Robot(400.0, (sec,))
    sec = tdct.Section(**SECTION | dict(end=0.01, outer_diameter=0.02))
    with pytest.warns(tdct.UnitWarning) as caught:
        tdct.Robot(0.01, (sec,), (tdct.Tendon(0.03, 0.0),))
    assert [str(w.message) for w in caught] == [
        "tendons[0].offset = 0.03 m is larger than the robot's length = 0.01 m: is one of them in another unit (SI: metres)?"
    ]


def test_real_robots_zero_and_traced_values_get_no_note():
    with _no_notes():
        for path in (ROBOTS / "paper.toml", TWO, FTDCR / "robot.toml"):
            tdct.Robot.from_toml(path)
        tdct.Robot.paper()
        for L, D, E, offset, rho in ((0.005, 0.004, 1e5, 0.0015, 1100.0), (5.0, 0.5, 2.1e11, 0.5, 0.0)):
            tdct.Robot(L, (tdct.Section(L, D, E, 0.3, rho),), (tdct.Tendon(offset, -np.pi), tdct.Tendon(0.0, 0.0)))
        robot = tdct.Robot.from_toml(TWO)
        jax.jit(lambda e: robot.replace({"sections[0].E": e}).sections[0].E)(200.0)


def test_a_robot_file_in_millimetres_gets_merged_notes_naming_the_file(tmp_path, capsys):
    path = _mm_file(tmp_path)
    assert main(["solve", "--robot", str(path), "--tip-mass-g", "-1"]) == 2  # a bad flag stops it before solving
    notes = [line for line in capsys.readouterr().err.splitlines() if line.startswith("tdct: note:")]
    assert notes == [
        f"tdct: note: robot file {path}: sections[0-1].outer_diameter = 1.4 m is far outside the plausible range [0, 0.5] m: "
        "did you mean 1.4 millimetres (0.0014 m)?",
        f"tdct: note: robot file {path}: tendons[0-5].offset = 10 m is far outside the plausible range [0, 0.5] m: "
        "did you mean 10 millimetres (0.01 m)?",
        f"tdct: note: robot file {path}: length = 400 m is far outside the plausible range [0.005, 5] m: "
        "did you mean 400 millimetres (0.4 m)?",
    ]


def test_replace_and_set_catch_a_tendon_angle_in_degrees(capsys):
    robot = tdct.Robot.from_toml(TWO)
    with pytest.warns(
        tdct.UnitWarning, match=r"^tendons\[0\]\.angle = 90 rad .* did you mean 90 degrees \(1.5708 rad\)\?$"
    ) as caught:
        robot.replace({"tendons[0].angle": 90.0})
    assert len(caught) == 1 and caught[0].filename == __file__
    with pytest.warns(tdct.UnitWarning, match=r"^sections\[0-1\]\.E = 200 Pa .* or 200 GPa \(2e\+11 Pa\)\?$"):
        robot.replace({"sections[*].E": 200.0})
    assert main(["solve", "--robot", str(TWO), "--set", "tendons[0].angle=90"]) == 2
    assert "write tendons[0].angle_deg=90" in capsys.readouterr().err


def test_empty_robot_files_and_files_without_sections_are_refused(tmp_path):
    empty = tmp_path / "empty.toml"
    empty.write_text("# nothing yet\n")
    with pytest.raises(ValueError) as e:
        tdct.Robot.from_toml(empty)
    assert str(e.value) == (
        f"robot file {empty} is empty: describe the robot by length and [[sections]] (docs/robot-file.md), "
        "or give the paper robot's Table II names"
    )
    with pytest.raises(ValueError, match=r"^the robot's table is empty: describe the robot by length and \[\[sections\]\]"):
        tdct.Robot.from_dict({})
    general = tmp_path / "general.toml"
    general.write_text("length = 0.2\n\n[[tendons]]\noffset = 0.01\nangle_deg = 0\n")
    with pytest.raises(
        ValueError, match=r"general.toml: no \[\[sections\]\]: a robot file with \[\[tendons\]\] describes its body"
    ):
        tdct.Robot.from_toml(general)
    with pytest.raises(ValueError, match=r"unknown field\(s\) \['E_silicon'\]"):  # a misspelt Table II name
        tdct.Robot.from_dict({"E_silicon": 1e6})


def test_tendon_channels_too_large_for_the_body_name_their_diameter(tmp_path):
    text = (
        "length = 0.2\n\n[[sections]]\nend = 0.2\nouter_diameter = 0.01\ninner_diameter = 0.002\n"
        "tendon_channel_diameter = 0.005\nE = 1e6\nnu = 0.5\ndensity = 1100\n\n[[tendons]]\noffset = 0.003\nangle_deg = 0\n"
    )
    path = tmp_path / "wide.toml"
    path.write_text(text)
    with pytest.raises(ValueError) as e:
        tdct.Robot.from_toml(path)
    assert str(e.value) == (
        f"robot file {path}: sections[0].tendon_channel_diameter = 0.005 m leaves no room for a tendon channel between the "
        "central channel (inner_diameter 0.002 m) and the surface (outer_diameter 0.01 m): it must be at most "
        "(sections[0].outer_diameter - sections[0].inner_diameter) / 2 = 0.004 m"
    )
    path.write_text(text.replace("0.005", "0.004"))
    tdct.Robot.from_toml(path)  # the largest that leaves room
    with pytest.raises(ValueError, match=r"^tendon_channel_diameter = 0.01 m leaves no room .* = 0.00925 m$"):
        tdct.Robot.paper(tendon_channel_diameter=0.01)


def _mm_scene(tmp_path):
    text = (SCENES / "table.toml").read_text()
    for old, new in (("-0.045", "-45"), ("-0.03, 0.09", "-30, 90"), ("0.015", "15")):
        text = text.replace(old, new)
    path = tmp_path / "table_mm.toml"
    path.write_text(text)
    return read_scene(path)


def test_a_scene_in_millimetres_gets_a_note_when_solved_with_a_robot(tmp_path):
    robot = tdct.Robot.paper()
    with pytest.warns(tdct.UnitWarning) as caught:
        problem(robot, None, None, DEFAULT_SOLVER, _mm_scene(tmp_path))  # the solve's checks, before any solve
    assert [str(w.message) for w in caught] == [
        "obstacles[0] (plane 'table') surface: 45 m from the base is 281 robot lengths away, where no tip reaches: "
        "positions are in metres; did you mean millimetres (0.045 m)?",
        "obstacles[1] (sphere 'ball') center: 94.8683 m from the base is 593 robot lengths away, where no tip reaches: "
        "positions are in metres; did you mean millimetres (0.0948683 m)?",
    ]
    with _no_notes():
        problem(robot, None, None, DEFAULT_SOLVER, read_scene(SCENES / "table.toml"))


def test_a_scene_of_a_robot_is_refused_in_one_short_line():
    with pytest.raises(TypeError) as e:
        tdct.Scene((tdct.Robot.paper(),))
    assert str(e.value) == "Scene obstacles[0] must be a tdct.Plane, Sphere, Capsule or Distance, got Robot"


def _dataset(tmp_path, scale: float, unit: str):
    """A copy of ftdcr-v4's data set, its first 20 training rows' tips times ``scale`` and labelled ``unit``."""
    shutil.copy(FTDCR / "robot.toml", tmp_path / "robot.toml")
    lines = (FTDCR / "train.csv").read_text().splitlines()[:21]
    rows = [line.split(",") for line in lines[1:]]
    rows = [row[:-3] + [f"{float(x) * scale:.9g}" for x in row[-3:]] for row in rows]
    (tmp_path / "train.csv").write_text("\n".join([lines[0], *(",".join(r) for r in rows)]) + "\n")
    spec = (FTDCR / "dataset.toml").read_text()
    spec = re.sub(r"\nvalidation = .*|\npulls = .*", "", spec).replace('tip_x = "mm"', f'tip_x = "{unit}"')
    spec = spec.replace('tip_y = "mm"', f'tip_y = "{unit}"').replace('tip_z = "mm"', f'tip_z = "{unit}"')
    (tmp_path / "dataset.toml").write_text(spec)
    return tmp_path / "dataset.toml"


def test_recorded_tips_in_the_wrong_unit_get_a_note(tmp_path):
    with _no_notes():
        read_dataset(FTDCR / "dataset.toml")
        read_dataset(_dataset(tmp_path, 1.0, "mm"))
    with pytest.warns(
        tdct.UnitWarning,
        match=r"train.csv: the tips \(tip_x, tip_y, tip_z in mm\) on average: 0.18\d* mm from "
        r"the base is 0.001 robot lengths away: did you type metres \(18\d\.?\d* mm\)\?",
    ):
        read_dataset(_dataset(tmp_path, 1e-3, "mm"))  # metres labelled mm
    with pytest.warns(
        tdct.UnitWarning,
        match=r"train.csv: the tips \(tip_x, tip_y, tip_z in m\) on average: 18\d\.?\d* m from "
        r"the base is 1e\+03 robot lengths away.* did you mean millimetres \(0.18\d* m\)\?",
    ):
        read_dataset(_dataset(tmp_path, 1.0, "m"))  # millimetres labelled m


# One small solve configuration for the last two tests: a 30 mm steel rod, tendons 10 mm off its axis.
STEEL = "length = 0.03\n\n[[sections]]\nend = 0.03\nouter_diameter = 0.001\nE = 2e11\nnu = 0.3\ndensity = 7800\n" + "".join(
    f"\n[[tendons]]\noffset = 0.01\nangle_deg = {a}\n" for a in (90, 270)
)


def test_a_folding_tendon_path_is_noted_on_a_converged_shape(tmp_path, capsys):
    path = tmp_path / "steel.toml"
    path.write_text(STEEL)
    robot = tdct.Robot.from_toml(path)
    sol = tdct.solve(robot, tdct.Actuation((300.0, 0.0)), solver=tdct.SolverOptions(steps=10))
    value, s, tendon = sol.fold(robot)
    assert value == pytest.approx(300.0 * 0.01**2 / (2e11 * np.pi / 64 * 1e-12), rel=0.02) and tendon == 0  # T r^2 / EI
    assert sol.notes(robot) == [
        f"tendon 1's path folds at s = {1e3 * s:.1f} mm: curvature x offset = {value:.3g}, at least 1 (the bend's radius is "
        "below the tendon's offset): the shape solves the equations but is not physical; lower the tension or load"
    ]
    assert main(["solve", "--robot", str(path), "--tensions", "300,0", "--steps", "10"]) == 0
    out = capsys.readouterr()
    assert "converged:         yes" in out.out and "tdct: note: tendon 1's path folds at s = " in out.err


def test_a_mild_bend_gets_no_fold_note(tmp_path, capsys):
    path = tmp_path / "steel.toml"
    path.write_text(STEEL)
    robot = tdct.Robot.from_toml(path)
    sol = tdct.solve(robot, tdct.Actuation((5.0, 0.0)), solver=tdct.SolverOptions(steps=10))
    assert 0 < sol.fold(robot)[0] < 0.1 and sol.notes(robot) == []
    assert main(["solve", "--robot", str(path), "--tensions", "5,0", "--steps", "10"]) == 0
    assert "tdct: note:" not in capsys.readouterr().err
