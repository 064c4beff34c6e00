"""Multiple shooting (SolverOptions.intervals, issue 24) against single shooting, the established
and independently validated solver: the same root, so the same tips, paths, implicit derivatives
and compliance to the solver's tolerance."""

import dataclasses
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import rel_err

import tdct_jax as tdct
from tdct_jax import fields, status
from tdct_jax.mechanics import compliance_and_solution

ROBOTS = Path(tdct.__file__).parent / "robots"

TIP_TOL = 1e-10
"""Tips and paths [m]: both roots within the Newton tolerance of the same exact root."""
DERIVATIVE_TOL = 1e-8
"""Implicit derivatives and compliance, relative."""
K = 4

CASES = {
    "Fig. 6": ((6.0, 0, 0, 0), 0.080, 0.020),
    "large bending, no tube": ((0, 0, 10.0, 0), 0.0, 0.0),
    "two tendons, tube deep": ((3.0, 0, 0, 5.0), 0.120, 0.0),
}


@pytest.fixture(scope="module")
def solutions(robot):
    """Single (K = 1) and multiple (K) shooting solutions of every case."""
    out = {}
    for name, (t, d, m) in CASES.items():
        act, load = tdct.Actuation(t, d), tdct.Loads.from_mass(m)
        out[name] = [tdct.solve(robot, act, load, solver=tdct.SolverOptions(intervals=k)) for k in (1, K)]
    return out


@pytest.mark.parametrize("name", CASES)
def test_same_tip_and_path_as_single_shooting(solutions, name):
    single, multi = solutions[name]
    assert multi.converged
    assert multi.position.shape == single.position.shape
    np.testing.assert_allclose(multi.tip_position, single.tip_position, rtol=0, atol=TIP_TOL)
    np.testing.assert_allclose(multi.position, single.position, rtol=0, atol=TIP_TOL)
    np.testing.assert_allclose(multi.rotation, single.rotation, rtol=0, atol=TIP_TOL)
    np.testing.assert_allclose(multi.s, single.s, rtol=0, atol=1e-15)
    assert rel_err(multi.total_force, single.total_force) < DERIVATIVE_TOL
    assert rel_err(multi.moment, single.moment) < DERIVATIVE_TOL


def test_large_bending(solutions):
    single, multi = solutions["large bending, no tube"]
    assert float(single.tip_rotation[2, 2]) < 0  # the tip tangent bent past 90 degrees
    np.testing.assert_allclose(multi.tip_angle, single.tip_angle, rtol=0, atol=1e-9)


@pytest.mark.slow
@pytest.mark.parametrize("k", [2, 8])
def test_other_interval_counts(robot, k):
    t, d, m = CASES["large bending, no tube"]
    act, load = tdct.Actuation(t, d), tdct.Loads.from_mass(m)
    single = tdct.solve(robot, act, load)
    multi = tdct.solve(robot, act, load, solver=tdct.SolverOptions(intervals=k))
    np.testing.assert_allclose(multi.position, single.position, rtol=0, atol=TIP_TOL)


def _tip_derivatives(robot, act, load, solver):
    """d tip / d(tensions, insertion, silicone modulus) by implicit differentiation, (3, 6)."""

    def tip(v):
        r = robot.replace({"sections[*].E": v[5]})
        return tdct.solve(r, tdct.Actuation(v[:4], v[4]), load, solver=solver, throw=False).tip_position

    v = jnp.concatenate([jnp.asarray(act.tensions, float), jnp.array([act.insertion, robot.sections[0].E])])
    return jax.jacfwd(tip)(v)


@pytest.mark.slow
def test_implicit_derivatives_and_compliance(robot):
    t, d, m = CASES["Fig. 6"]
    act, load = tdct.Actuation(t, d), tdct.Loads.from_mass(m)
    single, multi = tdct.SolverOptions(), tdct.SolverOptions(intervals=K)
    D1, DK = (_tip_derivatives(robot, act, load, s) for s in (single, multi))
    for j in range(D1.shape[1]):  # each input's column on its own scale
        assert rel_err(DK[:, j], D1[:, j]) < DERIVATIVE_TOL
    C1, CK = (tdct.compliance(robot, act, load, solver=s, full=True) for s in (single, multi))
    assert rel_err(CK, C1) < DERIVATIVE_TOL


def test_non_convergence_is_reported(robot):
    t, d, m = CASES["large bending, no tube"]
    act, load = tdct.Actuation(t, d), tdct.Loads.from_mass(m)
    solver = tdct.SolverOptions(intervals=K, max_iter=1)  # a leaf: the same compiled program
    sol = tdct.solve(robot, act, load, solver=solver, throw=False)
    assert not sol.converged
    assert int(sol.result) in (status.NEWTON_LIMIT, status.CONTINUATION_EXHAUSTED)
    with pytest.raises(tdct.ConvergenceError):
        tdct.solve(robot, act, load, solver=solver)


@pytest.mark.parametrize("value, words", [(0, ["intervals = 0", ">= 1"]), (2.0, ["intervals = 2.0", "integer"])])
def test_bad_intervals(value, words):
    with pytest.raises(ValueError) as e:
        tdct.SolverOptions(intervals=value)
    for w in words:
        assert w in str(e.value)


def test_interval_count_must_divide_the_steps(robot):
    """Checked against the robot (its step count is its breakpoint intervals x 20: the paper
    robot's 2 x 20) before anything compiles."""
    act = tdct.Actuation((1.0, 0, 0, 0), 0.05)
    with pytest.raises(
        ValueError, match=r"intervals = 3: a robot with 2 breakpoint intervals .*2 x 20 = 40: one of \[1, 2, 4, 5, 8"
    ):
        tdct.solve(robot, act, solver=tdct.SolverOptions(intervals=3))
    general, loads = _general_robot()
    with pytest.raises(ValueError) as e:
        tdct.solve(general, tdct.Actuation(GENERAL_TENSIONS), loads, solver=tdct.SolverOptions(intervals=3))
    for w in ["intervals = 3", "4 breakpoint intervals", "4 x 20 = 80", "[1, 2, 4, 5, 8, 10, 16, 20, 40, 80]"]:
        assert w in str(e.value)


def test_unsupported_combinations(robot):
    act = tdct.Actuation((1.0, 0, 0, 0), 0.05)
    with pytest.raises(ValueError, match="intervals = 2 with transition = 'paper'"):
        tdct.solve(robot, act, solver=tdct.SolverOptions(intervals=2, transition="paper"))


# ---- a GeneralRobot: intervals between its breakpoints ------------------------------------------

GENERAL_TENSIONS = (1.5, 0.0, 0.4, 0.0, 0.8, 0.3)
DRIVEN = (0, 2, 4, 5)
DISPLACEMENTS = (2e-3, 1e-3, 1e-3, 5e-4)
G = (0.0, 0.0, -9.81)
K_GENERAL = 8
"""Twice the 4 breakpoint intervals of ``_general_robot``: every breakpoint a boundary, each
breakpoint interval cut in two."""


def _general_robot():
    """The shipped two-segment robot (three tendons anchored at 0.2 m, three at the tip) with a
    point mass at 0.3 m, a point force and moment at 0.1 m and a tip load: 0, 0.1, 0.2 (section end
    and three anchors, one breakpoint), 0.3 and L, 4 breakpoint intervals."""
    robot = tdct.Robot.from_toml(ROBOTS / "two_segment.toml")
    robot = dataclasses.replace(robot, masses=(tdct.PointMass(0.3, 0.005),))
    loads = tdct.Loads(
        tip_force=[0.02, 0.0, 0.0],
        tip_moment=[0.0, 0.0, 2e-3],
        point_s=[0.1],
        point_force=[[0.0, 0.05, -0.02]],
        point_moment=[[1e-3, 0.0, 5e-4]],
    )
    return robot, loads


GENERAL_CASES = {
    "tensions": tdct.Actuation(GENERAL_TENSIONS),
    "displacements": tdct.Actuation(np.zeros(6), displacements=DISPLACEMENTS, driven=DRIVEN),
}


@pytest.fixture(scope="module")
def general_solutions():
    """(compliance, Solution) of single and multiple shooting, per actuation."""
    robot, loads = _general_robot()
    return {
        name: [
            compliance_and_solution(robot, act, loads, gravity=G, solver=tdct.SolverOptions(intervals=k)) for k in (1, K_GENERAL)
        ]
        for name, act in GENERAL_CASES.items()
    }


@pytest.mark.slow
@pytest.mark.parametrize("name", GENERAL_CASES)
def test_general_robot_same_solution_as_single_shooting(general_solutions, name):
    (C1, single), (CK, multi) = general_solutions[name]
    assert multi.converged
    assert multi.position.shape == single.position.shape
    np.testing.assert_allclose(multi.position, single.position, rtol=0, atol=TIP_TOL)
    np.testing.assert_allclose(multi.rotation, single.rotation, rtol=0, atol=TIP_TOL)
    np.testing.assert_allclose(multi.s, single.s, rtol=0, atol=1e-15)
    # both sides of each breakpoint: the jumps at the point load and mass land where single shooting has them
    assert rel_err(multi.total_force, single.total_force) < DERIVATIVE_TOL
    assert rel_err(multi.total_moment, single.total_moment) < DERIVATIVE_TOL
    assert rel_err(multi.tensions, single.tensions) < DERIVATIVE_TOL
    np.testing.assert_allclose(multi.displacements, single.displacements, rtol=0, atol=TIP_TOL)
    assert list(np.asarray(multi.slack)) == list(np.asarray(single.slack))
    assert rel_err(CK, C1) < DERIVATIVE_TOL  # with driven tendons: displacements held


@pytest.mark.slow
def test_general_robot_implicit_derivatives():
    """d tip / d(tensions, E of every section) by implicit differentiation."""
    robot, loads = _general_robot()

    def derivatives(solver):
        def tip(v):
            r = fields.replace(robot, {"sections[*].E": v[6]})
            return tdct.solve(r, tdct.Actuation(v[:6]), loads, gravity=G, solver=solver, throw=False).tip_position

        return jax.jacfwd(tip)(jnp.array([*GENERAL_TENSIONS, float(robot.sections[0].E)]))

    D1, DK = derivatives(tdct.SolverOptions()), derivatives(tdct.SolverOptions(intervals=K_GENERAL))
    for j in range(D1.shape[1]):  # each input's column on its own scale
        assert rel_err(DK[:, j], D1[:, j]) < DERIVATIVE_TOL
