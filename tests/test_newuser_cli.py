"""What a new user hits with their own robot (issue 48): tdct ik's step count and its step limit (a
non-convergence, not a bad input), calibrate and synth refusing an --out that names a file,
compliance --scene, the IK target drawn for a robot file's robot, the solved tensions in a
solve's figure title, synth on a robot without a tube, and docs/cli.md naming the verbs that take
robot files. Refusals come before any solve; the two IK runs share one compiled program (the
two-segment robot at few RK4 steps: --max-steps is a value, not a shape)."""

import argparse
import json
import re
from pathlib import Path

import matplotlib
import numpy as np
import pytest

import tdct_jax as tdct
from tdct_jax import cli, plotting
from tdct_jax.cli import main
from tdct_jax.description import ROBOTS
from tdct_jax.ik import MAX_STEPS
from tdct_jax.ik.starts import STARTS
from tdct_jax.scene import SCENES

matplotlib.use("Agg")

ROOT = Path(__file__).resolve().parents[1]
TWO = str(ROBOTS / "two_segment.toml")
TABLE = str(SCENES / "table.toml")
FEW_STEPS = ["--steps", "5"]
IK = ["ik", "--robot", TWO, *FEW_STEPS]
TARGET_MM = (30.0, 100.0, 380.0)
"""Reached by the two-segment robot (its tip, 400 mm long, raised and turned toward +x)."""
HELD_RTOL = 1e-8
"""|CM n| and |n^T CM| over |CM| for a tip held on a plane of normal n: zero but for round-off."""
ARC_RTOL = 1e-4
"""A tendon-bent arc against the closed form: the backbone's axial and shear strain (~1e-5 here)."""
STATUS = r"^status: +{} \((\d+) IK steps in all; --max-steps {} limits the steps from each start tried\)$"
"""The text output's status line: the status, the steps of every start tried, the limit of each."""


def _drawn(monkeypatch) -> list:
    """The figures ``plot_robot`` draws from now on (saved as asked, then kept for inspection)."""
    figures, real = [], plotting.plot_robot
    monkeypatch.setattr(plotting, "plot_robot", lambda *a, **k: figures.append(real(*a, **k)) or figures[-1])
    return figures


# ---- refused before any solve -----------------------------------------------------------------


@pytest.mark.parametrize(
    "argv",
    [
        ["calibrate", "--dataset", "no-such-dataset.toml", "--out"],
        ["synth", "--robot", TWO, "--tensions", "1,0,0,0,0,0", "--out"],
    ],
)
def test_out_naming_a_file_is_refused_first(argv, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    taken = tmp_path / "report.txt"
    taken.write_text("keep me")
    assert main([*argv, str(taken)]) == 2
    err = capsys.readouterr().err
    # before the data set is read (it does not exist) or anything is solved
    assert err == f"tdct: error: --out {taken}: is a file, expected a folder\n"
    assert taken.read_text() == "keep me"


def test_synth_refuses_an_insertion_for_a_robot_without_tubes(tmp_path, capsys):
    assert main(["synth", "--robot", TWO, "--tensions", "1,0,0,0,0,0", "--insertion-mm", "10", "--out", str(tmp_path)]) == 2
    assert "--insertion-mm 10: the robot has no tubes; leave it out" in capsys.readouterr().err


def _subcommands() -> dict:
    parser = cli._parser()
    return next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices


def test_cli_page_names_the_verbs_that_take_robot_files():
    """docs/cli.md's "The robot" lists exactly the verbs with --robot and --set, and documents
    compliance --scene, which the parser has."""
    page = (ROOT / "docs" / "cli.md").read_text()
    bullet = page.split("- **The robot**: ", 1)[1].split(" take `--robot", 1)[0]
    verbs = _subcommands()
    with_robot_files = {v for v, p in verbs.items() if {"--robot", "--set"} <= set(p._option_string_actions)}
    assert set(re.findall(r"`(\w+)`", bullet)) == with_robot_files
    assert "--scene" in verbs["compliance"]._option_string_actions
    assert "### tdct compliance\n\n`--scene scene.toml`" in page


# ---- inverse kinematics of a robot file (one compiled program) -------------------------------


def test_ik_step_limit_is_a_non_convergence_with_advice(capsys):
    """--max-steps 1: exit 1 with what to do, not a bad-input error; the steps printed count every
    start tried, each of which --max-steps limits."""
    assert main([*IK, "--target-mm", ",".join(map(str, TARGET_MM)), "--max-steps", "1"]) == 1
    out, err = capsys.readouterr()
    assert err.startswith("tdct: the inverse kinematics did not converge: ") and err.count("\n") == 1
    assert "error" not in err and "--max-steps 1" in err and "raise --max-steps" in err
    found = re.search(STATUS.format("outer iteration limit reached", 1), out, re.M)
    assert found, out
    assert 1 < int(found[1]) <= STARTS  # more than the limit, by the starts tried, never more


def test_ik_plot_of_a_robot_file_marks_the_target(tmp_path, capsys, monkeypatch):
    figures = _drawn(monkeypatch)
    png = tmp_path / "ik.png"
    assert main([*IK, "--target-mm", ",".join(map(str, TARGET_MM)), "--plot", str(png)]) == 0
    out = capsys.readouterr().out
    assert re.search(STATUS.format("converged", MAX_STEPS), out, re.M), out
    assert png.stat().st_size > 20_000
    (fig,) = figures
    side, top, ax3 = fig.axes
    x, y, z = TARGET_MM

    def crosses(ax, three=False):
        return [
            np.ravel(line.get_data_3d() if three else line.get_data())
            for line in ax.get_lines()
            if line.get_marker() == "x" and len(line.get_xdata())
        ]

    np.testing.assert_allclose(crosses(side), [[z, y]])  # side view: z across, y up
    np.testing.assert_allclose(crosses(top), [[z, x]])  # top view: z across, x up
    np.testing.assert_allclose(crosses(ax3, three=True), [[x, z, y]])  # 3D: drawn as (x, z, y)
    assert "target" in [t.get_text() for t in fig.legends[0].get_texts()]


# ---- solves ------------------------------------------------------------------------------------


def test_solve_plot_title_shows_the_solved_tensions(tmp_path, capsys, monkeypatch):
    """Tendon 1 driven by a 5 mm pull: the title shows the tension the pull makes (typed: 0)."""
    figures = _drawn(monkeypatch)
    png = tmp_path / "p.png"
    argv = ["solve", "--robot", TWO, *FEW_STEPS, "--displacements-mm", "1:5", "--plot", str(png), "--json"]
    assert main(argv) == 0
    tensions = json.loads(capsys.readouterr().out)["tensions_N"]
    title = figures[0].get_suptitle()
    shown = [float(t) for t in re.match(r"tensions ([^N]*) N, tendon 1 pulled 5 mm", title)[1].split(", ")]
    assert shown[0] > 0.1  # the pulled tendon holds tension
    np.testing.assert_allclose(shown, tensions, rtol=1e-3, atol=1e-12)
    assert png.stat().st_size > 20_000


def test_synth_of_a_robot_without_a_tube_draws_the_tendon_arc(tmp_path, capsys):
    """Tendon 1 (offset r at +y, anchored at 200 mm) at T, no gravity, no noise: segment 1 an arc
    of curvature T r / EI in the z-y plane, segment 2 straight along its tangent."""
    T = 2.0
    argv = ["synth", "--robot", TWO, *FEW_STEPS, "--no-gravity", "--noise-mm", "0", "--points", "5"]
    assert main([*argv, "--tensions", f"{T},0,0,0,0,0", "--out", str(tmp_path)]) == 0
    (path,) = capsys.readouterr().out.split()
    rows = [line for line in Path(path).read_text().splitlines() if not line.startswith("#")]
    assert rows[0] == "s_mm,x_mm,y_mm,z_mm"
    table = np.loadtxt(rows[1:], delimiter=",")
    s, p = table[:, 0] * 1e-3, table[:, 1:] * 1e-3
    robot = tdct.Robot.from_toml(TWO)
    section, tendon = robot.sections[0], robot.tendons[0]
    kappa = T * float(tendon.offset) / (float(section.E) * np.pi * float(section.outer_diameter) ** 4 / 64)
    arc = s <= 0.2
    expected = np.stack([0 * s[arc], (1 - np.cos(kappa * s[arc])) / kappa, np.sin(kappa * s[arc]) / kappa], 1)
    np.testing.assert_allclose(p[arc], expected, rtol=ARC_RTOL, atol=1e-12)
    turned = kappa * 0.2
    tangent = np.array([0.0, np.sin(turned), np.cos(turned)])
    straight = expected[-1] + np.outer(s[~arc] - 0.2, tangent)
    np.testing.assert_allclose(p[~arc], straight, rtol=ARC_RTOL, atol=1e-12)


def test_compliance_in_contact_holds_the_tip_on_the_table(capsys):
    """The paper's robot bent onto the shipped table (tip resting on it): the compliance in
    contact moves the tip neither along the table's normal nor under a force along it, and still
    sideways; the text output names the contacts."""
    argv = ["compliance", "--tensions", "0,0,10,0", "--insertion-mm", "60", "--scene", TABLE]
    assert main([*argv, "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    CM = np.asarray(out["compliance_mm_per_N"])
    (tip,) = [c for c in out["contacts"] if c["obstacle"] == "table"]
    assert tip["s_mm"] == pytest.approx(160.0) and tip["force_N"] > 0
    n = np.asarray(tip["normal"])
    big = np.abs(CM).max()
    assert np.abs(n @ CM).max() <= HELD_RTOL * big and np.abs(CM @ n).max() <= HELD_RTOL * big
    assert CM[0, 0] > 1e-3 * big  # sideways (x, along the table) the tip still gives
    assert [o["obstacle"] for o in out["obstacles"]] == ["table", "ball"]
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert text.startswith("compliance matrix CM [mm/N] (world x, y, z), in contact (the touching candidates held")
    assert "contacts:          " in text and "table at s = 160.0 mm" in text and "on ball:" in text
