"""Inverse kinematics with an objective and its derivatives, against truths the IK code did not
produce: a 1 mm scan of the redundant input, the first-order optimality conditions from the public
Jacobians, central differences."""

import json

import jax
import numpy as np
import pytest
from conftest import HEIGHT, MASS

import tdct_jax as tdct
from tdct_jax.cli import main


def test_stiffest_solution_beats_every_solution_of_a_1_mm_insertion_scan(robot, stiffest):
    load, d = tdct.Loads.from_mass(MASS), np.array([0.0, -1.0, 0.0])
    best = d @ np.asarray(tdct.compliance(robot, stiffest.actuation, load)) @ d
    np.testing.assert_allclose(stiffest.objective, best, rtol=1e-9)  # the same compliance from two solves
    scan = []
    for depth in np.arange(0.0, 0.1605, 0.001):
        fixed = tdct.inverse_kinematics(
            robot, tdct.Target((0.0, HEIGHT, 0.0), axes="y"), load=load, tendons=(1,), insertion=depth, throw=False
        )
        if int(fixed.result) == tdct.status.SUCCESS:
            scan.append(d @ np.asarray(tdct.compliance(robot, fixed.actuation, load)) @ d)
    print(
        f"stiffest: {1e3 * best:.5f} mm/N at {1e3 * float(stiffest.actuation.insertion):.3f} mm; scan of {len(scan)}: {1e3 * min(scan):.5f}"
    )
    assert len(scan) > 50 and best <= min(scan) * (1 + 1e-6)


def test_ik_options_are_leaves_a_new_tol_or_max_steps_compiles_nothing(robot, stiffest):
    """IKOptions' tol and max_steps, and the objective's direction, are leaves: the stiffest
    solution's program answers other values of them without compiling again, and answers the
    original values as it did."""
    from tdct_jax.ik.driver import _solve_ik

    load, target = tdct.Loads.from_mass(MASS), tdct.Target((0.0, HEIGHT, 0.0), axes="y")

    def again(ik, direction=(0.0, -1.0, 0.0)):
        objective = tdct.Stiffness(direction=direction)
        return tdct.inverse_kinematics(robot, target, load=load, tendons=(1,), objective=objective, ik=ik, throw=False)

    # compiled here if the process dropped its programs (conftest, MAX_MAPS) since ``stiffest`` ran
    same = again(tdct.IKOptions())
    compiled = _solve_ik._cache_size()
    tight = again(tdct.IKOptions(tol=1e-12, max_steps=80))
    short = again(tdct.IKOptions(max_steps=1))
    tilted = again(tdct.IKOptions(), direction=(0.0, -1.0, 0.1))
    assert _solve_ik._cache_size() == compiled
    assert int(short.result) == tdct.status.OUTER_LIMIT and int(short.iterations) < int(
        stiffest.iterations
    )  # the limit took effect
    assert int(tight.result) == tdct.status.SUCCESS and float(tight.position_error) <= 1e-12 * float(robot.length)
    assert float(tilted.objective) != float(stiffest.objective)  # the new direction took effect
    for a, b in zip(jax.tree.leaves(same), jax.tree.leaves(stiffest), strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


def test_stiffest_solution_is_first_order_optimal(robot, stiffest):
    """KKT from the public Jacobians: the objective's gradient is balanced by the task on the free
    inputs (multiplier lam), and pushes against every input held at a bound."""
    load, d = tdct.Loads.from_mass(MASS), np.array([0.0, -1.0, 0.0])
    act = stiffest.actuation

    def compliance_along(w):  # w = (tension 1 [N], insertion [m])
        a = tdct.Actuation(jax.numpy.stack([w[0], 0.0, 0.0, 0.0]), w[1])
        return d @ tdct.compliance(robot, a, load) @ d

    w = np.array([float(act.tensions[0]), float(act.insertion)])
    grad = np.asarray(jax.jacfwd(compliance_along)(w))
    G = np.asarray(tdct.kinematic_jacobian(robot, act, load))[1, [0, 4]]  # d tip y / d (tension 1, insertion)
    scale = np.array([10.0, 0.16])  # the inputs' ranges
    grad, G = grad * scale, G * scale
    at_upper = w >= np.array([10.0, 0.16]) - 1e-12
    at_lower = w <= 1e-12
    free = ~(at_upper | at_lower)
    lam = -np.linalg.lstsq(G[free, None], grad[free], rcond=None)[0][0]
    reduced = grad + G * lam
    assert np.abs(reduced[free]).max() <= 1e-8 * np.abs(grad).max()
    assert np.all(reduced[at_upper] <= 1e-8 * np.abs(grad).max()) and np.all(reduced[at_lower] >= -1e-8 * np.abs(grad).max())


def test_actuation_derivative_in_the_target_matches_central_differences(robot):
    def tension_and_insertion(position):
        result = tdct.inverse_kinematics(robot, tdct.Target(position, axes="yz"), tendons=(1,), throw=False)
        return jax.numpy.stack([result.actuation.tensions[0], result.actuation.insertion, *result.tip_position[1:]])

    p = np.asarray(tdct.solve(robot, tdct.Actuation((6.0, 0, 0, 0), 0.06)).tip_position)  # reachable: a forward tip
    exact = np.asarray(jax.jacfwd(tension_and_insertion)(p))[:, 1:]
    h = 1e-6
    fd = np.column_stack(
        [
            (np.asarray(tension_and_insertion(p + h * e)) - np.asarray(tension_and_insertion(p - h * e))) / (2 * h)
            for e in np.eye(3)[1:]
        ]
    )
    assert np.abs(exact[:2] - fd[:2]).max() <= 1e-6 * np.abs(fd[:2]).max()
    # the tip follows the target it reaches: through the answer's forward solve, whose Jacobian the
    # derivative takes itself (phase 1 reached: no closing solve took one)
    np.testing.assert_allclose(exact[2:], np.eye(2), rtol=0, atol=1e-8)


@pytest.mark.parametrize(
    "made_by", [((2.0, 0.0, 1.0, 0.0), 0.10), ((3.0, 0.0, 1.0, 0.0), 0.08)], ids=["2 N, 100 mm", "3 N, 80 mm"]
)
def test_least_tension_with_two_opposed_tendons_is_reached_and_first_order_optimal(robot, made_by):
    """An in-plane target made by tendon 1 against 1 N on tendon 3 (reachable by construction), re-solved
    with tendons 1 and 3 and the tube free (two task rows, three inputs) for the least total squared
    tension: reached, and the objective's gradient 2 tau has no component along the task's null space,
    computed from the public kinematic Jacobian. (Phase 2 once ran out of steps on such targets.)"""
    tip = np.asarray(tdct.solve(robot, tdct.Actuation(*made_by)).tip_position)
    result = tdct.inverse_kinematics(robot, tdct.Target(tip, axes="yz"), tendons=(1, 3), objective="tension", throw=False)
    assert int(result.result) == tdct.status.SUCCESS and float(result.position_error) < 1e-9
    tau, depth = np.asarray(result.actuation.tensions), float(result.actuation.insertion)
    assert 0 < tau[0] < 10 and 0 < tau[2] < 10 and 0 < depth < 0.16  # no bound active: the plain Lagrange condition
    scale = np.array([10.0, 10.0, 0.16])  # the inputs' ranges
    G = np.asarray(tdct.kinematic_jacobian(robot, result.actuation))[1:3][:, [0, 2, 4]] * scale  # d tip (y, z) / d inputs
    grad = np.array([2 * tau[0], 2 * tau[2], 0.0]) * scale
    null = np.linalg.svd(G)[2][-1]
    assert abs(grad @ null) <= 1e-6 * np.linalg.norm(grad)
    assert sum(tau**2) <= sum(np.square(made_by[0])) * (1 + 1e-9)  # no worse than the actuation that made it


def test_cli_ik_with_a_partial_target_is_the_apis_stiffest_reach(robot, stiffest, capsys):
    """``tdct ik --axes y``: the redundancy example (a tip height, tendon 1 and the tube) from the
    command line, the same answer as the API's (conftest's ``stiffest``)."""
    argv = ["ik", "--target-mm", f"0,{1e3 * HEIGHT:g},0", "--axes", "y", "--tip-mass-g", f"{1e3 * MASS:g}", "--tendons", "1"]
    assert main([*argv, "--objective", "stiffness", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["status"] == "converged" and abs(out["tip_position_mm"][1] - 1e3 * HEIGHT) < 1e-6
    np.testing.assert_allclose(out["tensions_N"], np.asarray(stiffest.actuation.tensions), rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(out["insertion_mm"], 1e3 * float(stiffest.actuation.insertion), rtol=1e-9)
