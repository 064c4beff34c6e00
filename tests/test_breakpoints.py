"""Coincident breakpoints (issue 48): a robot's own breakpoints at one arc length (a section end,
the anchors there, a point mass on it) are integrated as one (``Robot.merged``). The merged robot
must give the answers of the same robot with each breakpoint its own zero-length interval (built
here with ``merged`` None), to round-off, with fewer nodes; the shape files have one row per arc
length."""

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import tdct_jax as tdct
from tdct_jax.cli import main
from tdct_jax.description import ROBOTS
from tdct_jax.tree import unchecked

STEPS = 10
SOLVER = tdct.SolverOptions(steps=STEPS)
TENSIONS = jnp.asarray([1.5, 0.0, 0.4, 0.0, 0.8, 0.3])
MASSES = (tdct.PointMass(0.2, 0.005), tdct.PointMass(0.4, 0.002), tdct.PointMass(0.1, 0.003))
"""At the section end (with three anchors), at the tip, and alone."""


def apart(robot):
    """``robot`` with each breakpoint its own interval, as when its breakpoints are traced."""
    return unchecked(tdct.Robot, **vars(robot) | {"merged": None})


@pytest.fixture(scope="module")
def robots():
    robot = tdct.Robot.from_toml(ROBOTS / "two_segment.toml").replace(masses=MASSES)
    return robot, apart(robot)


def test_coincident_breakpoints_are_one(robots):
    merged, separate = robots
    # own breakpoints: base, section end, three anchors, three masses, length
    assert merged.merged == (0, 1, 1, 1, 1, 1, 8, 7, 8)
    distinct = {0.0, 0.1, 0.2, 0.4}
    sols = [tdct.solve(r, tdct.Actuation(TENSIONS), solver=SOLVER) for r in robots]
    assert [s.s.size for s in sols] == [(len(distinct) - 1) * (STEPS + 1), (9 - 1) * (STEPS + 1)]
    for sol in sols:
        assert sorted(set(np.asarray(sol.s)[sol.distinct()].tolist())) == np.asarray(sol.s)[sol.distinct()].tolist()
        assert set(np.round(np.asarray(sol.s), 15).tolist()) >= distinct
    np.testing.assert_allclose(sols[0].position[-1], sols[1].position[-1], rtol=0, atol=1e-15)
    np.testing.assert_allclose(sols[0].total_force[0], sols[1].total_force[0], rtol=0, atol=1e-15)
    # global balance: the base carries the weight of body and masses, whichever way they are integrated
    body = sum(
        float(sec.density) * np.pi / 4 * float(sec.outer_diameter) ** 2 * (float(sec.end) - start)
        for sec, start in zip(merged.sections, (0.0, 0.2), strict=True)
    )
    weight = 9.81 * (body + sum(float(m.mass) for m in MASSES))
    assert float(sols[0].total_force[0, 1]) == pytest.approx(-weight, rel=1e-12)


def test_compliance_and_derivatives_unchanged(robots):
    def tip(robot, tensions, E):
        robot = robot.replace({"sections[*].E": E}) if E is not None else robot
        return tdct.solve(robot, tdct.Actuation(tensions), solver=SOLVER).tip_position

    for what in (
        lambda r: tdct.compliance(r, tdct.Actuation(TENSIONS), solver=SOLVER),
        lambda r: jax.jacfwd(lambda t, E: tip(r, t, E), argnums=(0, 1))(TENSIONS, 54e9),
    ):
        a, b = (what(r) for r in robots)
        for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b), strict=True):
            np.testing.assert_allclose(x, y, rtol=1e-12, atol=1e-12 * float(jnp.max(jnp.abs(y))))


def test_a_traced_breakpoint_keeps_its_own_interval(robots):
    """Under a transformation the arc lengths are not known: nothing merges, and the derivative in
    an anchor's arc length is that of the robot whose anchor lies beyond the section end."""
    robot, _ = robots

    def tip(end):
        return tdct.solve(robot.replace({"tendons[0].end": end}), tdct.Actuation(TENSIONS), solver=SOLVER).tip_position

    seen = []
    jax.jit(lambda end: seen.append(robot.replace({"tendons[0].end": end}).merged) or end)(0.2)
    assert seen == [None]

    h = 1e-5
    ahead = (tip(0.2 + 2 * h) - tip(0.2 + h)) / h  # one-sided: the anchor moving into segment 2
    np.testing.assert_allclose(jax.jacfwd(tip)(0.2), ahead, rtol=1e-3, atol=1e-9)


@pytest.mark.parametrize("name", ["paper.toml", "two_segment.toml"])
def test_shape_files_have_no_repeated_arc_length(tmp_path, capsys, name):
    csv = tmp_path / "shape.csv"
    assert main(["solve", "--robot", str(ROBOTS / name), "--steps", str(STEPS), "--csv", str(csv), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    s = np.loadtxt(csv, delimiter=",", skiprows=1)[:, 0]
    assert np.all(np.diff(s) > 0) and np.all(np.diff(out["shape"]["s_mm"]) > 0)
    assert s[0] == 0.0 and s[-1] == pytest.approx(1e3 * float(tdct.Robot.from_toml(ROBOTS / name).length), rel=1e-12)
    np.testing.assert_allclose(out["shape"]["position_mm"][-1], out["tip_position_mm"], rtol=1e-12)
