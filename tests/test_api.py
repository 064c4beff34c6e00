"""One way in: one SolverOptions object reaches every entry point; pytrees check user input when
built, never when JAX rebuilds them."""

import warnings

import jax
import numpy as np
import pytest

import tdct_jax as tdct

# One Newton step per load stage: no solve converges, where the defaults converge every one. The
# limit is a leaf of the options (not static), so each entry point runs its default program: the
# test shows that the options object reaches it without compiling programs of its own.
OPTIONS = tdct.SolverOptions(max_iter=1)
ACT = tdct.Actuation((8.0, 0.0, 0.0, 0.0), 0.05)
LOAD = tdct.Loads.from_mass(0.02)


def test_one_options_object_reaches_solve_compliance_and_sweep(robot):
    sol = tdct.solve(robot, ACT, LOAD, solver=OPTIONS, throw=False)
    assert sol.result == tdct.status.NEWTON_LIMIT and tdct.solve(robot, ACT, LOAD).converged
    with pytest.raises(tdct.ConvergenceError, match="max_iter = 1"):
        tdct.solve(robot, ACT, LOAD, solver=OPTIONS)
    assert np.isnan(tdct.compliance(robot, ACT, LOAD, solver=OPTIONS, throw=False)).all()
    assert np.isfinite(tdct.compliance(robot, ACT, LOAD)).all()
    res = tdct.sweep(robot, ACT, LOAD, batch={"insertion": [0.05, 0.1]}, solver=OPTIONS, progress=False, throw=False)
    assert not res.converged.any()


@pytest.mark.slow
def test_one_options_object_reaches_capacity_and_calibrate(robot):
    cap = tdct.capacity(robot, ACT, solver=OPTIONS, throw=False)
    assert not cap.converged and tdct.capacity(robot, ACT).converged
    shapes = tdct.synthesize(robot, [ACT], noise=0.0)
    fit = tdct.calibrate(robot, shapes, max_steps=2, progress=False, solver=OPTIONS, throw=False)
    assert fit.message == "the model did not converge at the starting values" and fit.iterations == 0


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
