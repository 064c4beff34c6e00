"""tdct simulate (issue 49): a bad input table or flag exits 2 naming the file, line, column and
value before anything is simulated; one short run of a small steel rod writes a CSV whose tip
equals tdct.simulate's through the API, an .npz of every trajectory array with its units, the tip
figure and a GIF of the frames asked; a step that did not converge exits 1 with its time and what
to do, the files still written. The CLI run and the API call share one compiled simulation."""

import dataclasses
import json

import numpy as np
import pytest
from PIL import Image

import tdct_jax as tdct
from tdct_jax import cli, status
from tdct_jax.cli import main
from tdct_jax.dynamics import default_solver
from tdct_jax.scene import SCENES

ROD = """length = 0.2

[[sections]]
end = 0.2
outer_diameter = 0.002
E = 200e9
nu = 0.3
density = 7800.0
damping = 0.001

[[tendons]]
offset = 0.005
angle_deg = 90
"""
"""A steel rod 0.2 m long and 2 mm across (first mode about 35 Hz), one tendon 5 mm off its axis."""
TABLE = "t_s,tension_1_N,tip_force_x_N\n0,0,0\n0.005,20,0\n0.02,20,0.01\n"
"""The tendon pulled to 20 N in 5 ms and held, a sideways tip force rising to 10 mN."""
DT_MS, STEPS, RK4 = 1.0, 20, 10
FRAMES = 5
TIP_ATOL = 1e-9
"""[m]: the CSV's tip (12 significant digits in mm) against the API's."""


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("simulate")
    (folder / "rod.toml").write_text(ROD)
    (folder / "inputs.csv").write_text(TABLE)
    return folder


@pytest.fixture(scope="module")
def api(files):
    """tdct.simulate of the table's inputs at the CLI's times, with the CLI's defaults."""
    t = np.arange(STEPS + 1) * DT_MS * 1e-3
    tension = np.interp(t, [0, 0.005, 0.02], [0, 20, 20])[:, None]
    force = np.zeros((STEPS + 1, 3))
    force[:, 0] = np.interp(t, [0, 0.005, 0.02], [0, 0, 0.01])
    robot = tdct.Robot.from_toml(files / "rod.toml")
    solver = default_solver(robot, tdct.Loads(), steps=RK4)
    return tdct.simulate(robot, DT_MS * 1e-3, tensions=tension, tip_force=force, solver=solver)


def _argv(files, *extra):
    return ["simulate", "--robot", str(files / "rod.toml"), "--inputs", str(files / "inputs.csv"), "--dt-ms", "1", *extra]


# ---- refused before anything is simulated ------------------------------------------------------

BAD_TABLES = [
    (
        "t,tension_1_N\n0,0\n",
        "inputs.csv:1: unknown column 't' (did you mean 't_s'?); the columns are t_s, tension_1_N, tip_force",
    ),
    ("t_s,displacment_1_mm\n0,0\n", "tip_force_z_N; displacement_i_mm in place of tension_i_N for a tendon driven by"),
    ("tension_1_N\n0\n", "inputs.csv:1: no time column 't_s' (the times in seconds, from 0); columns present: ['tension_1_N']"),
    ("t_s,tension_1_N\n0,0\n0.01,1\n0.01,2\n", "inputs.csv:4: t_s = 0.01 s is not after the row before's 0.01 s"),
    ("t_s,tension_1_N\n0.1,0\n0.2,1\n", "inputs.csv:2: t_s = 0.1 s: the table starts at t = 0"),
    ("t_s,tension_1_N,tip_torque_N\n0,0,0\n", "inputs.csv:1: unknown column 'tip_torque_N'"),
    ("t_s,tension_1_N\n0,0\n0.01,1\n0.02,-0.5\n", "inputs.csv:4: tension_1_N = -0.5 N is outside the allowed range [0, inf) N"),
    ("t_s,tension_1_N,tension_2_N\n0,0,0\n", "inputs.csv:1: column 'tension_2_N': the robot has 1 tendon, so the tension"),
    ("t_s,displacement_2_mm\n0,0\n", "column 'displacement_2_mm': the robot has 1 tendon, so the displacement columns are"),
    (
        "t_s,tension_1_N,insertion_1_mm\n0,0,0\n",
        "column 'insertion_1_mm': the robot has 0 tubes, so the insertion columns are none",
    ),
    (
        "t_s,tension_1_N,displacement_1_mm\n0,0,0\n",
        "inputs.csv:1: columns tension_1_N and displacement_1_mm: drive tendon 1 by its tension or its displacement",
    ),
    (
        "t_s,tip_force_y_N\n0,0\n0.01,1\n",
        "inputs.csv:1: no column(s) tension_1_N: the robot has 1 tendon, one tension column each",
    ),
    ("t_s,tension_1_N\n0,0\n0.01,abc\n", "inputs.csv:3: tension_1_N = 'abc' is not a number"),
    ("t_s,tension_1_N\n0,0\n0.01\n", "inputs.csv:3: row has 1 fields, the column line (line 1) has 2"),
    ("t_s;tension_1_N\n0;0\n", "unknown column 't_s;tension_1_N'"),
    ("t_s,tension_1_N\n", "inputs.csv:1: no samples"),
    ("t_s,tension_1_N,t_s\n0,0,0\n", "inputs.csv:1: duplicate column name(s) ['t_s']"),
    ("t_s,tension_1_N\n0,1\n", "inputs.csv: one row, at t = 0: give --duration-s"),
]
BAD_FLAGS = [
    (["--dt-ms", "0"], "--dt-ms 0 is outside the allowed range (0, inf] ms"),
    (["--duration-s", "0.0005"], "--duration-s 0.0005 is shorter than one time step, --dt-ms 1"),
    (["--duration-s", "200"], "200 s (--duration-s) in steps of --dt-ms 1 is 200000 time steps, more than 100000"),
    (["--alpha", "-0.6"], "--alpha -0.6 is outside the allowed range [-0.5, 0]"),
    (["--frames", "1"], "--frames 1 is outside the allowed range [2, inf]"),
    (["--gif", "robot.mp4"], "--gif robot.mp4: .mp4 is not a GIF; allowed: .gif"),
    (["--insertion-mm", "10"], "--insertion-mm 10: the robot has 0 tubes"),
    (["--set", "sections[0].damping=-1"], "--set: "),
    (["--scene", str(SCENES / "table.toml"), "--intervals", "2"], "--scene with --intervals 2: contact is solved by single"),
]


@pytest.fixture
def nothing_simulated(monkeypatch):
    def no_simulation(*args, **kwargs):
        raise AssertionError("a simulation started")

    monkeypatch.setattr(cli, "simulate", no_simulation)


@pytest.mark.parametrize("table, words", BAD_TABLES)
def test_bad_table_exits_2_naming_file_line_column_and_value(table, words, files, tmp_path, capsys, nothing_simulated):
    inputs = tmp_path / "inputs.csv"
    inputs.write_text(table)
    assert main([*_argv(files)[:4], str(inputs), "--dt-ms", "1"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"tdct: error: {tmp_path}") and words in err and err.count("\n") == 1, err


@pytest.mark.parametrize("flags, words", BAD_FLAGS)
def test_bad_flag_exits_2_before_anything_is_simulated(flags, words, files, tmp_path, capsys, monkeypatch, nothing_simulated):
    monkeypatch.chdir(tmp_path)
    argv = _argv(files)
    if "--dt-ms" in flags:
        argv = argv[:-2]
    assert main([*argv, *flags]) == 2
    err = capsys.readouterr().err
    assert err.startswith("tdct: error: ") and words in err and "Traceback" not in err, err


def test_unreadable_table_and_friction_with_multiple_shooting_are_refused(files, tmp_path, capsys, nothing_simulated):
    missing = tmp_path / "none.csv"
    assert main(["simulate", "--robot", str(files / "rod.toml"), "--inputs", str(missing), "--dt-ms", "1"]) == 2
    assert f"tdct: error: {missing}: cannot read input table: " in capsys.readouterr().err
    rubbing = tmp_path / "friction.toml"
    rubbing.write_text(ROD.replace("damping = 0.001", "damping = 0.001\nfriction = 0.1"))
    argv = ["simulate", "--robot", str(rubbing), "--inputs", str(files / "inputs.csv"), "--dt-ms", "1", "--intervals", "4"]
    assert main(argv) == 2
    assert f"tdct: error: --robot {rubbing}: solver intervals = 4 with tendon friction" in capsys.readouterr().err


def test_displacement_columns_drive_their_tendons_in_metres(tmp_path):
    """A displacement_i_mm column makes tendon i displacement-driven: its values in metres,
    interpolated like the tensions; the other tendons keep their tension columns."""
    path = tmp_path / "pulls.csv"
    path.write_text("t_s,displacement_1_mm,tension_2_N,tension_3_N\n0,0,0,0\n0.1,2,0,1.5\n")
    table = cli.read_input_table(path, 3)
    assert table.driven == (0,)
    tensions, displacements, force, depths = table.at(np.array([0.0, 0.05, 0.2]))
    assert depths is None
    np.testing.assert_allclose(displacements[:, 0], [0.0, 1e-3, 2e-3], rtol=1e-12)
    np.testing.assert_allclose(tensions, [[0, 0, 0], [0, 0, 0.75], [0, 0, 1.5]], rtol=1e-12)
    assert not force.any()


def test_insertion_columns_move_every_tube_in_metres(tmp_path, capsys, nothing_simulated):
    """insertion_i_mm columns give every tube's depth along time, in metres, interpolated like the
    tensions; one tube's column without the other's, or the columns beside --insertion-mm, is
    refused."""
    path = tmp_path / "tubes.csv"
    path.write_text("t_s,tension_1_N,insertion_1_mm,insertion_2_mm\n0,0,10,0\n0.1,1,30,5\n")
    table = cli.read_input_table(path, 1, 2)
    np.testing.assert_allclose(table.insertions, [[0.01, 0.0], [0.03, 5e-3]], rtol=1e-12)
    depths = table.at(np.array([0.0, 0.05, 0.2]))[3]
    np.testing.assert_allclose(depths, [[0.01, 0.0], [0.02, 2.5e-3], [0.03, 5e-3]], rtol=1e-12)
    path.write_text("t_s,tension_1_N,insertion_2_mm\n0,0,0\n")
    with pytest.raises(ValueError, match="columns insertion_2_mm: give every tube's depth"):
        cli.read_input_table(path, 1, 2)
    paper = tmp_path / "paper.csv"
    paper.write_text("t_s,tension_1_N,tension_2_N,tension_3_N,tension_4_N,insertion_1_mm\n0,0,0,0,0,10\n0.01,1,0,0,0,20\n")
    assert main(["simulate", "--inputs", str(paper), "--dt-ms", "1", "--insertion-mm", "10"]) == 2
    assert (
        "--insertion-mm and the input table's insertion columns: give the tube depths in one of them" in capsys.readouterr().err
    )


# ---- one short simulation ---------------------------------------------------------------------


def test_simulation_writes_the_api_trajectory_a_figure_and_a_gif(files, api, tmp_path, capsys):
    out, png, gif = tmp_path / "run", tmp_path / "tip.png", tmp_path / "robot.gif"
    argv = _argv(files, "--steps", str(RK4), "--out", str(out), "--plot", str(png), "--gif", str(gif))
    assert main([*argv, "--frames", str(FRAMES)]) == 0
    stdout, err = capsys.readouterr()
    assert f"simulating {STEPS} steps of 1 ms to t = 0.02 s" in err
    assert f"simulated {STEPS} steps of 1 ms to t = 0.02 s" in stdout and "every step converged" in stdout
    assert bool(api.converged)

    header, *rows = (out / "trajectory.csv").read_text().splitlines()
    names = "t_s,tip_x_mm,tip_y_mm,tip_z_mm,tension_1_N,displacement_1_mm,tip_force_x_N,tip_force_y_N,tip_force_z_N,result"
    assert header == names and len(rows) == STEPS + 1
    table = np.array([[float(v) for v in row.split(",")] for row in rows])
    np.testing.assert_allclose(table[:, 0], np.asarray(api.t), atol=1e-15)
    np.testing.assert_allclose(table[-1, 1:4] * 1e-3, np.asarray(api.tip_position[-1]), rtol=0, atol=TIP_ATOL)
    np.testing.assert_allclose(table[:, 1:4] * 1e-3, np.asarray(api.tip_position), rtol=0, atol=TIP_ATOL)
    assert table[-1, 4] == 20 and table[-1, 6] == pytest.approx(0.01) and not table[:, -1].any()
    np.testing.assert_allclose(table[:, 5] * 1e-3, np.asarray(api.displacements[:, 0]), rtol=0, atol=1e-15)
    assert abs(table[-1, 1]) > 0.1  # the tip force moved the tip sideways [mm]

    saved = np.load(out / "trajectory.npz")
    for name in (
        "t",
        "s",
        "position",
        "rotation",
        "force",
        "moment",
        "velocity",
        "angular_velocity",
        "tensions",
        "displacements",
    ):
        np.testing.assert_array_equal(saved[name], np.asarray(getattr(api, name)), err_msg=name)
    meta = json.loads(str(saved["metadata"]))
    assert meta["units"]["position"] == "m" and meta["units"]["t"] == "s" and meta["dt_s"] == 1e-3

    assert png.stat().st_size > 20_000
    with Image.open(gif) as frames:
        assert frames.n_frames == FRAMES


def test_a_step_that_does_not_converge_exits_1_with_its_time(files, api, tmp_path, capsys, monkeypatch):
    """The first failed step's time and what to do; the files are written, the GIF stops before it."""
    failed = 7
    result = api.result.at[failed:].set(status.NEWTON_LIMIT)
    broken = dataclasses.replace(api, result=result, residual_norm=api.residual_norm.at[failed].set(1e-3))
    monkeypatch.setattr(cli, "simulate", lambda *a, **k: broken)
    out, gif = tmp_path / "run", tmp_path / "robot.gif"
    assert main([*_argv(files, "--steps", str(RK4), "--out", str(out), "--gif", str(gif), "--quiet")]) == 1
    stdout, err = capsys.readouterr()
    assert err.startswith(f"tdct: time step {failed} (t = 0.007 s) did not converge: Newton used its --max-iter 50 steps")
    assert "(0.001) below 1e-10" in err and "Raise --intervals (now " in err and "error" not in err
    assert f"{STEPS + 1 - failed} of {STEPS + 1} steps did NOT converge" in stdout
    result = [int(row.rsplit(",", 1)[1]) for row in (out / "trajectory.csv").read_text().splitlines()[1:]]
    assert result == [0] * failed + [status.NEWTON_LIMIT] * (STEPS + 1 - failed)
    with Image.open(gif) as frames:
        assert frames.n_frames == failed  # 60 frames asked, the rows before the failure drawn
