"""One way in: one SolverOptions object reaches every entry point; pytrees check user input when
built, never when JAX rebuilds them."""

import warnings

import jax
import numpy as np
import pytest

import tdct_jax as tdct

# 6 steps and the paper's printed transition: both change the answer, so each entry point's
# result shows whether it used these options.
OPTIONS = tdct.SolverOptions(steps=6, transition="paper")
NODES = 2 * (OPTIONS.steps + 1)  # two intervals, [0, d] and [d, L], steps + 1 nodes each
ACT = tdct.Actuation((8.0, 0.0, 0.0, 0.0), 0.05)
LOAD = tdct.Loads.from_mass(0.02)


@pytest.mark.slow
def test_one_options_object_reaches_solve_compliance_and_sweep(robot):
    sol = tdct.solve(robot, ACT, LOAD, solver=OPTIONS)
    default = tdct.solve(robot, ACT, LOAD)
    assert sol.s.shape == (NODES,) and sol.position.shape == (NODES, 3)
    assert np.linalg.norm(sol.tip_position - default.tip_position) > 1e-5  # the options change the tip

    CM = tdct.compliance(robot, ACT, LOAD, solver=OPTIONS)
    fd = tdct.finite_difference_compliance(robot, ACT, LOAD, step=1e-5, solver=OPTIONS)
    other = tdct.compliance(robot, ACT, LOAD)
    assert np.abs(CM - fd).max() < 1e-6 * np.abs(CM).max() < np.abs(CM - other).max()

    res = tdct.sweep(robot, ACT, LOAD, batch={"insertion": [0.05, 0.1]}, shapes=True, solver=OPTIONS, progress=False)
    assert res.position.shape == (2, NODES, 3)
    np.testing.assert_allclose(res.tip_position[0], sol.tip_position, rtol=0, atol=1e-9)  # the engine's own root


@pytest.mark.slow
def test_one_options_object_reaches_capacity_and_calibrate(robot):
    cap = tdct.capacity(robot, ACT, solver=OPTIONS)
    height = tdct.solve(robot, ACT, tdct.Loads.from_mass(cap.mass), solver=OPTIONS).tip_position[1]
    assert abs(float(height)) < 1e-9  # the capacity's own solves used the options
    assert abs(float(tdct.solve(robot, ACT, tdct.Loads.from_mass(cap.mass)).tip_position[1])) > 1e-6

    shapes = tdct.synthesize(robot, [ACT], noise=0.0, solver=OPTIONS)
    fit = tdct.calibrate(robot, shapes, max_steps=2, progress=False, solver=OPTIONS)
    assert fit.solutions.position.shape == (1, NODES, 3)
    assert fit.rmse_before[0] < 1e-12  # synthesized and fitted with the same options: no misfit


@pytest.mark.parametrize("make", [tdct.Robot.paper, tdct.Actuation, tdct.Loads, tdct.SolverOptions])
def test_unflatten_does_not_validate_but_building_does(make):
    built = make()
    leaves, tree = jax.tree.flatten(built)
    for fill in (0.0, -1.0, np.nan, object()):
        rebuilt = jax.tree.unflatten(tree, [fill] * len(leaves))  # zeros, bad values, placeholders: no checks
        assert all(x is fill for x in jax.tree.leaves(rebuilt, is_leaf=lambda x, fill=fill: x is fill))
    traced = jax.jit(lambda x: jax.tree.unflatten(tree, [x * 0 - 1] * len(leaves)))(1.0)  # tracers, negative values
    assert type(traced) is type(built)


def test_actuation_and_tip_load_take_a_leading_batch_axis(robot):
    act = tdct.Actuation(np.outer([2.0, 6.0, 9.0], [1.0, 0, 0, 0]), [0.0, 0.05, 0.1])
    load = tdct.Loads.from_mass(np.array([0.0, 0.01, 0.02]))
    assert load.tip_force.shape == load.tip_moment.shape == (3, 3)
    tips = jax.vmap(lambda a, f: tdct.solve(robot, a, tdct.Loads(tip_force=f), throw=False).tip_position)(act, load.tip_force)
    for k in range(3):
        single = tdct.solve(robot, tdct.Actuation(act.tensions[k], act.insertion[k]), tdct.Loads(tip_force=load.tip_force[k]))
        np.testing.assert_allclose(tips[k], single.tip_position, rtol=0, atol=1e-12)
    with pytest.raises(ValueError, match=r"leading \(batch\) axes \(3,\) and \(2,\)"):
        tdct.Actuation(np.zeros((3, 4)), [[0.0], [0.1]])
    with pytest.raises(ValueError, match="one configuration is expected here"):
        tdct.solve(robot, act)


def test_former_names_still_work_and_say_what_to_write(monkeypatch):
    """Scripts written against the two models run: each former name gives the merged type, with
    one FutureWarning naming what to write instead (CHANGELOG.md)."""
    monkeypatch.setattr(tdct.checks, "_DEPRECATED", set())
    with pytest.warns(FutureWarning, match=r"write tdct.Robot.paper\(\)"):
        robot = tdct.Robot(E_silicone=1e6)
    assert jax.tree.structure(robot) == jax.tree.structure(tdct.Robot.paper())
    assert float(robot.sections[0].E) == 1e6
    with pytest.warns(FutureWarning, match="write tdct.Loads"):
        load = tdct.TipLoad(force=(0.0, -0.1, 0.0))
    assert isinstance(load, tdct.Loads) and load.tip_force[1] == -0.1
    with pytest.warns(FutureWarning, match="write tdct.Robot"):
        assert tdct.GeneralRobot is tdct.Robot
    with pytest.warns(FutureWarning, match="insertions"):
        act = tdct.Actuation((1.0, 0.0, 0.0, 0.0), insertion=0.05)
    np.testing.assert_array_equal(act.insertions, [0.05])
    with pytest.warns(FutureWarning, match=r"'sections\[\*\]\.E'"):
        assert robot.E_silicone == 1e6
    with pytest.warns(FutureWarning, match=r"write tdct.capacity\(robot, act, grid=...\)"):
        with pytest.raises(ValueError, match="max_steps"):  # refused after the warning, before any solve
            tdct.load_capacity(robot, max_steps=0)
    with pytest.warns(FutureWarning, match=r"write tdct.calibrate\(rig, recording, params\)"):
        with pytest.raises(ValueError, match="at least one"):
            tdct.calibrate_rig(None, None, ())
    with pytest.warns(FutureWarning, match=r"bracket=\(lo, hi\)"):
        with pytest.raises(ValueError, match="no tube"):
            tdct.insertion_optimum(tdct.Robot(length=robot.length, sections=robot.sections), None, None, 0.0, 0.1)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # once each: the second use is silent
        tdct.Robot()
