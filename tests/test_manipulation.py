"""Load capacity and optimal insertion (Sec. V.A): defined by the solver's own tip height, checked there."""

import inspect

import jax
import numpy as np
import pytest

import tdct_jax as tdct


def tip_y(robot, act, mass):
    return float(tdct.solve(robot, act, tdct.Loads.from_mass(mass), throw=True).tip_position[1])


@pytest.fixture(scope="module")
def capacities(robot):
    grid = {"insertion": np.array([0.0, 0.07]), "tensions": np.array([[6.0, 0, 0, 0], [10.0, 0, 0, 0]])}
    return tdct.capacity(robot, grid=grid, progress=False)


def test_capacity_lifts_the_tip_exactly_to_the_base_height(robot, capacities):
    res = capacities
    assert res.shape == (2, 2) and res.converged.all() and res.reachable.all()
    for i, d in enumerate((0.0, 0.07)):
        for j, tau in enumerate((6.0, 10.0)):
            act, m = tdct.Actuation((tau, 0, 0, 0), d), float(res.mass[i, j])
            assert abs(tip_y(robot, act, m)) < 1e-9
            assert tip_y(robot, act, 1.01 * m) < 0 < tip_y(robot, act, 0.99 * m)
    # More tension lifts more; some tube lifts more than none (the paper's Fig. 14 trend).
    assert np.all(res.mass[:, 1] > res.mass[:, 0]) and np.all(res.mass[1] > res.mass[0])


def test_capacity_is_differentiable_in_robot_parameters(robot):
    act = tdct.Actuation((8.0, 0, 0, 0), 0.05)

    def mass(offset):
        return tdct.capacity(robot.replace({"tendons[*].offset": offset}), act).mass

    r = float(robot.tendons[0].offset)
    exact = jax.grad(mass)(r)  # called as the manipulation guide calls it: the same compiled programs
    h = 1e-6
    central = (mass(r + h) - mass(r - h)) / (2 * h)
    assert exact > 0
    assert abs(exact - central) < 1e-6 * abs(central)


def test_a_tip_that_cannot_reach_the_height_is_unreachable(robot, capacities):
    """3 N on tendon 1 cannot lift even the unloaded tip to y = 0 (the fixture's points beside it:
    four points with the fixture's inputs, so its compiled program serves)."""
    batch = {"insertion": [0.0, 0.0, 0.0, 0.07], "tensions": np.outer([3.0, 6.0, 10.0, 10.0], [1.0, 0, 0, 0])}
    res = tdct.capacity(robot, batch=batch, progress=False, throw=False)
    assert res.result.tolist() == [tdct.status.UNREACHABLE] + [tdct.status.SUCCESS] * 3
    assert res.reachable.tolist() == [False, True, True, True] and res.mass[0] == 0.0 and not res.converged[0]
    np.testing.assert_allclose(res.mass[1:], capacities.mass[[0, 0, 1], [0, 1, 1]], rtol=1e-12)
    with pytest.raises(
        tdct.ConvergenceError, match=r"target unreachable: even with no tip mass the tip stays below the height y = 0 m"
    ):
        tdct.capacity(robot, batch=batch, progress=False)


@pytest.mark.slow
def test_optimal_insertion_is_a_stationary_maximum(robot):
    act, load = tdct.Actuation((10.0, 0, 0, 0)), tdct.Loads.from_mass(0.05)
    res = tdct.optimal_insertion(robot, act, load, n_curve=9, progress=False)
    d = float(res.insertion)
    assert res.converged and res.interior and 0.0 < d < float(robot.length)
    J = tdct.kinematic_jacobian(robot, tdct.Actuation(act.tensions, d), load)
    assert abs(J[1, -1]) < 1e-8  # d y_tip / d insertion, independently of the optimiser's own slope
    y = lambda x: float(tdct.solve(robot, tdct.Actuation(act.tensions, x), load, throw=True).tip_position[1])  # noqa: E731
    assert y(d - 1e-3) < y(d) > y(d + 1e-3)
    assert y(d) >= res.curve_height.max()


def test_capacity_grid_saves_to_csv_and_npz(capacities, tmp_path):
    lines = capacities.save_csv(tmp_path / "c.csv").read_text().splitlines()
    header = lines[0].split(",")
    assert header[:3] == ["insertion_m", "tensions_1_N", "tensions_2_N"] and "mass_kg" in header and len(lines) == 5
    table = np.loadtxt(tmp_path / "c.csv", delimiter=",", skiprows=1)
    np.testing.assert_allclose(table[:, header.index("mass_kg")], capacities.mass.ravel(), rtol=1e-15)
    data = np.load(capacities.save_npz(tmp_path / "c.npz"))
    np.testing.assert_array_equal(data["mass"], capacities.mass)
    np.testing.assert_array_equal(data["axis_insertion"], [0.0, 0.07])


def test_the_entry_points_take_the_solver_by_name_and_refuse_batching_without_a_grid(robot):
    for f in (tdct.optimal_insertion, tdct.capacity):
        p = inspect.signature(f).parameters["solver"]
        assert p.kind is p.KEYWORD_ONLY and p.default is tdct.options.DEFAULT_SOLVER
    with pytest.raises(TypeError, match=r"\['chunk_size'\] apply over a grid or batch"):
        tdct.capacity(robot, tdct.Actuation((8.0, 0, 0, 0)), chunk_size=4)
    with pytest.raises(TypeError, match=r"unknown argument\(s\) \['hieght'\]"):
        tdct.capacity(robot, grid={"insertion": [0.0]}, hieght=0.01)
    with pytest.raises(TypeError, match="bracket= .* or grid=, not both"):
        tdct.optimal_insertion(robot, bracket=(0.0, 0.1), grid={"tip_mass": [0.01]})


def test_the_insertion_optimum_needs_a_tube(robot):
    bare = tdct.Robot(length=robot.length, sections=robot.sections, tendons=robot.tendons)
    with pytest.raises(ValueError, match="no tube"):
        tdct.optimal_insertion(bare, tdct.Actuation((10.0, 0, 0, 0)), progress=False)
