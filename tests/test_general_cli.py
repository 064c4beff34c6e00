"""tdct solve and compliance on any robot (issue 23): a robot file with tensions of any length,
displacements and point loads equal the API's solve of the same inputs; --set takes fields.py
names; every bad input exits 2 naming the flag, the value and the range, before any solve; --plot
draws the robot. One solve configuration (one compile) serves most tests."""

import dataclasses
import json
from types import SimpleNamespace

import matplotlib
import numpy as np
import pytest

import tdct_jax as tdct
from tdct_jax import cli, fields, plotting, rod
from tdct_jax.cli import main
from tdct_jax.description import ROBOTS
from tdct_jax.options import DEFAULT_SOLVER

matplotlib.use("Agg")

TWO = str(ROBOTS / "two_segment.toml")
TENSIONS = (1.5, 0.0, 0.4, 0.0, 0.8, 0.0)
SOLVE = ["solve", "--robot", TWO, "--tensions", ",".join(map(str, TENSIONS))]


@pytest.fixture(scope="module")
def two_segment():
    return tdct.Robot.from_toml(TWO)


def test_tensions_of_any_length_give_the_api_tip(capsys, two_segment):
    assert main([*SOLVE, "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    sol = tdct.solve(two_segment, tdct.Actuation(TENSIONS))
    np.testing.assert_allclose(out["tip_position_mm"], np.asarray(sol.tip_position) * 1e3, rtol=1e-12)
    np.testing.assert_allclose(out["tensions_N"], TENSIONS, rtol=0)
    np.testing.assert_allclose(out["displacements_mm"], np.asarray(sol.displacements) * 1e3, rtol=1e-12)
    assert out["slack"] == [False] * 6 and out["shape"]["s_mm"] == sorted(set(out["shape"]["s_mm"]))


def test_set_changes_a_general_field(capsys, two_segment):
    """Angles typed in degrees, under the robot file's key name."""
    argv = [*SOLVE, "--set", "sections[*].E=60e9", "--set", "tendons[0].offset=0.012", "--set", "tendons[2].angle_deg=200"]
    assert main(argv) == 0
    text = capsys.readouterr().out
    robot = fields.replace(two_segment, {"sections[*].E": 60e9, "tendons[0].offset": 0.012, "tendons[2].angle": np.pi * 10 / 9})
    tip = 1e3 * np.asarray(tdct.solve(robot, tdct.Actuation(TENSIONS)).tip_position)
    assert f"tip position [mm]: x = {tip[0]:.3f}, y = {tip[1]:.3f}, z = {tip[2]:.3f}" in text
    assert "tensions [N]:      1.5000, 0.0000, 0.4000" in text and "slack tendons:     none" in text


@pytest.mark.slow
def test_displacements_and_point_loads_equal_the_api(capsys, two_segment):
    argv = [*SOLVE, "--displacements-mm", "4:0.5,6:-20", "--point-load", "300:0,-0.05,0.02", "--json"]
    assert main(argv) == 0
    out = json.loads(capsys.readouterr().out)
    act = tdct.Actuation(TENSIONS, (), (0.5e-3, -20e-3), (3, 5))
    load = tdct.Loads(point_s=(0.3,), point_force=((0.0, -0.05, 0.02),))
    sol = tdct.solve(two_segment, act, load)
    np.testing.assert_allclose(out["tip_position_mm"], np.asarray(sol.tip_position) * 1e3, rtol=1e-12)
    np.testing.assert_allclose(out["tensions_N"], np.asarray(sol.tensions), rtol=1e-12, atol=1e-15)
    assert out["tensions_N"][3] > 0 and out["slack"] == [False] * 5 + [True]  # tendon 6 let out: slack
    assert out["displacements_mm"][3] == pytest.approx(0.5, rel=1e-12)


def test_plot_of_a_general_robot(tmp_path, capsys):
    png = tmp_path / "robot.png"
    assert main([*SOLVE, "--plot", str(png)]) == 0
    assert png.stat().st_size > 20_000


def test_plot_robot_draws_sections_tendons_masses_and_loads(two_segment):
    """A straight shape, drawn without a solve: every part of the robot appears in each view."""
    robot = dataclasses.replace(two_segment, masses=(tdct.PointMass(0.1, 0.01), tdct.PointMass(0.3, 0.01)))
    s = np.linspace(0.0, 0.4, 41)
    sol = SimpleNamespace(
        s=s, position=np.outer(s, [0.0, 0.0, 1.0]), rotation=np.broadcast_to(np.eye(3), (41, 3, 3)), tip_angle=0.0
    )
    load = tdct.Loads(tip_force=(0.0, -0.1, 0.0), point_s=(0.2,), point_force=((0.0, 0.05, 0.0),))
    fig = plotting.plot_robot(sol, robot, None, load)
    side, top, ax3 = fig.axes
    # per view: 2 sections, 6 tendons and their 6 anchors, 2 disks
    assert len(side.get_lines()) == len(top.get_lines()) + 3 == 2 + 12 + 2 + 3  # + legend proxies in the side view
    assert len([a for a in side.texts if a.arrow_patch is not None]) == 2  # tip force and point load
    tendon_ends = [line.get_xydata()[-1] for line in top.get_lines()[2:14:2]]
    np.testing.assert_allclose(sorted(z for z, _ in tendon_ends), [200.0] * 3 + [400.0] * 3)
    assert (side.get_xlabel(), side.get_ylabel(), top.get_ylabel()) == ("z [mm]", "y [mm]", "x [mm]")
    assert ax3.get_zlabel() == "y [mm]" and len(ax3.texts) == 6  # tendon numbers
    matplotlib.pyplot.close(fig)


@pytest.mark.parametrize(
    ("argv", "words"),
    [
        ([*SOLVE[:3], "--tensions", "1,0,0,0"], "--tensions 1,0,0,0 has 4 values: the robot has 6 tendons"),
        (
            [*SOLVE, "--point-load", "500:0,0,1"],
            "--point-load 500:0,0,1: arc length 500 is outside the allowed range [0, 400] mm",
        ),
        ([*SOLVE, "--set", "sections[*].G=1"], "--set: 'sections[*].G' is not a scalar robot field; allowed: length"),
        (
            [*SOLVE, "--set", "tendons[6].offset=0.01"],
            "--set: 'tendons[6].offset': the robot has 6 tendons (indices 0 to 5, or a range a-b with a <= b)",
        ),
        (
            [*SOLVE, "--set", "tendons[0].angle=90"],
            "--set: tendons[0].angle = 90: angles are typed in degrees here; write tendons[0].angle_deg=90",
        ),
        ([*SOLVE, "--displacements-mm", "1:200"], "tendon 1's 200 mm is outside the allowed range (-inf, 200) mm"),
        ([*SOLVE, "--displacements-mm", "7:1"], "--displacements-mm 7:1: tendon numbers, each once, 1 to 6"),
        ([*SOLVE, "--displacements-mm", "1"], "argument --displacements-mm: expected TENDON:MM pairs"),
        ([*SOLVE, "--insertion-mm", "10"], "--insertion-mm 10: the robot has 0 tubes; give --insertions-mm"),
        ([*SOLVE, "--insertions-mm", "10"], "--insertions-mm 10 has 1 values: the robot has 0 tubes"),
        (["compliance", "--insertions-mm", "10,20"], "--insertions-mm 10,20 has 2 values: the robot has 1 tubes"),
        (
            ["compliance", "--point-load", "-1:0,0,1"],
            "--point-load -1:0,0,1: arc length -1 is outside the allowed range [0, 160] mm",
        ),
        (["calibrate", "shapes.csv", "--robot", TWO, "--params", "tubes[0].E"], "--params: 'tubes[0].E': the robot has 0 tubes"),
    ],
)
def test_bad_input_exits_2_before_any_solve(argv, words, capsys, monkeypatch):
    def no_solve(*args, **kwargs):
        raise AssertionError("a solve started")

    monkeypatch.setattr(cli, "solve", no_solve)
    monkeypatch.setattr(cli, "compliance_and_solution", no_solve)
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert words in err and "Traceback" not in err


def test_robot_without_tendons_refuses_tensions(tmp_path, capsys):
    path = tmp_path / "rod.toml"
    path.write_text("length = 0.3\n[[sections]]\nend = 0.3\nouter_diameter = 0.002\nE = 2e11\nnu = 0.3\ndensity = 7800.0\n")
    assert main(["solve", "--robot", str(path), "--tensions", "1"]) == 2
    assert "--tensions 1: the robot has no tendons" in capsys.readouterr().err


def test_displacement_beyond_the_rest_length_is_refused(two_segment):
    """A tendon cannot be pulled by its whole length inside the straight robot (longer when helical);
    letting it out (negative) is allowed. Checked before any compile."""

    def check(robot, d):
        act = tdct.Actuation((0.0,) * 6, (), (d,), (4,))
        rod.check_arguments(robot, act, tdct.Loads(), DEFAULT_SOLVER)

    check(two_segment, -0.5)
    check(two_segment, 0.3999)
    with pytest.raises(
        ValueError, match=r"displacements\[0\] \(tendons\[4\]\) = 0\.4 is outside the allowed range \(-inf, 0\.4\) m"
    ):
        check(two_segment, 0.4)
    helical = fields.replace(two_segment, {"tendons[4].twist": 10.0})  # rest length 0.4 sqrt(1 + 0.1^2)
    check(helical, 0.4015)
    with pytest.raises(ValueError, match=r"= 0\.4021 is outside the allowed range \(-inf, 0\.401995\) m"):
        check(helical, 0.4021)
    with pytest.raises(ValueError, match=r"displacements\[0\] \(tendons\[4\]\)"):
        tdct.solve(two_segment, tdct.Actuation((0.0,) * 6, (), (0.5,), (4,)))
