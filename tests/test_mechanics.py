"""Exact compliance and Jacobians against closed forms and central differences of the solve."""

import jax
import numpy as np
import pytest
from conftest import NO_GRAVITY, rel_err, section

import tdct_jax as tdct
from tdct_jax import shooting
from tdct_jax.inputs import gravity_vector

BENT = (tdct.Actuation(tensions=(8.0, 0.0, 0.0, 3.0), insertions=0.05), tdct.Loads(tip_force=(0.05, -0.3, 0.02)))


@pytest.mark.parametrize("insertion", [0.0, 0.16])
def test_straight_cantilever_compliance_is_timoshenkos(robot, insertion):
    CM = np.asarray(tdct.compliance(robot, tdct.Actuation(insertions=insertion), gravity=NO_GRAVITY))
    sec = section(robot)
    L, I_x, I_y = float(robot.length), sec.I_x, sec.I_y
    E, EA = sec.E, sec.E * sec.A
    if insertion == 0:
        shear = L / (sec.G * sec.A)
        bend = [L**3 / (3 * E * I_y) + shear, L**3 / (3 * E * I_x) + shear]
    else:  # the tube forbids shear
        EI_tube = sec.EI_tube
        bend = [L**3 / (3 * (E * I_y + EI_tube)), L**3 / (3 * (E * I_x + EI_tube))]
    assert rel_err(CM, np.diag([*bend, L / EA])) < 1e-6


def test_autodiff_compliance_matches_central_differences_when_bent(robot):
    act, load = BENT
    CM = tdct.compliance(robot, act, load)
    fd = tdct.finite_difference_compliance(robot, act, load, step=1e-5)
    assert rel_err(CM, fd) < 1e-6
    full = tdct.compliance(robot, act, load, full=True)
    np.testing.assert_array_equal(full[:3, :3], CM)
    # Rotation block: a small tip force rotates R(L) by the rotation vector full[3:, :3] @ dF.
    dF = np.array([0.0, 1e-5, 0.0])
    R0 = tdct.solve(robot, act, load).tip_rotation
    R1 = tdct.solve(robot, act, tdct.Loads(tip_force=load.tip_force + dF)).tip_rotation
    W = np.asarray(R1 @ R0.T)
    assert rel_err((W - W.T)[[2, 0, 1], [1, 2, 0]] / 2, np.asarray(full[3:, :3]) @ dF) < 1e-4


@pytest.mark.slow
def test_compliance_is_differentiable_in_the_insertion_and_a_tension(robot):
    """The compliance comes from Newton's Jacobians at the root; its own derivative must still be
    the derivative (not the zero tangent of a by-product): against central differences. In
    (tension 1, insertion), as tests/test_ik_optimality.py differentiates it: one program."""
    load = tdct.Loads.from_mass(0.02)

    def CM(w):  # w = (tension 1 [N], insertion [m])
        return tdct.compliance(robot, tdct.Actuation(jax.numpy.stack([w[0], 0.0, 0.0, 0.0]), w[1]), load, throw=False)

    w = np.array([8.0, 0.08])
    dCM = np.asarray(jax.jacfwd(CM)(w))
    for i, h in enumerate((1e-4, 1e-6)):
        step = h * np.eye(2)[i]
        fd = (np.asarray(CM(w + step)) - np.asarray(CM(w - step))) / (2 * h)
        assert rel_err(dCM[..., i], fd) < 1e-6
    assert np.abs(dCM[..., 1]).max() > 0.1  # m/N per m: the tube stiffens the robot


def test_compliance_from_newtons_jacobians_at_a_root_is_differentiable(robot):
    """``shooting.jacobians_at_root`` (how an IK answer's stiffness objective gets its value): the
    compliance from Newton's Jacobians at a root is tdct.compliance, and its derivative in (tension
    1, insertion) equals central differences of tdct.compliance (the points and steps above)."""
    load, g, solver = tdct.Loads.from_mass(0.02), gravity_vector(tdct.STANDARD_GRAVITY), tdct.SolverOptions()

    def actuation(w):  # w = (tension 1 [N], insertion [m])
        return tdct.Actuation(jax.numpy.stack([w[0], 0.0, 0.0, 0.0]), w[1])

    def CM(w):
        act = actuation(w)
        x, info = shooting.root(robot, act, load, g, jax.numpy.full(6, jax.numpy.nan), solver)
        J_res, (J_p, J_R) = shooting.jacobians_at_root(robot, act, load, g, solver, x, info.jacobians)
        # the positional rows: the tip rotation enters only the rotation rows
        return shooting.tip_compliance(robot, jax.numpy.eye(3), J_res, J_p, J_R, shooting.force_scale(robot, act, load, g))[
            :3, :3
        ]

    def reference(w):
        return np.asarray(tdct.compliance(robot, actuation(w), load, throw=False))

    w = np.array([8.0, 0.08])
    np.testing.assert_allclose(jax.jit(CM)(w), reference(w), rtol=1e-12, atol=0)
    dCM = np.asarray(jax.jit(jax.jacfwd(CM))(w))
    for i, h in enumerate((1e-4, 1e-6)):
        step = h * np.eye(2)[i]
        assert rel_err(dCM[..., i], (reference(w + step) - reference(w - step)) / (2 * h)) < 1e-6


@pytest.mark.parametrize("d", [1e-4, 0.08, 0.16 - 1e-4])
def test_insertion_column_of_kinematic_jacobian_matches_differences(robot, d):
    act = tdct.Actuation(tensions=(10.0, 0.0, 0.0, 0.0), insertions=d)
    load = tdct.Loads.from_mass(0.05)
    J = np.asarray(tdct.kinematic_jacobian(robot, act, load))
    assert J.shape == (6, 5)
    # Fourth-order central differences: the tip curves sharply in d near d = L.
    h = 2e-5
    tip = {k: np.asarray(tdct.solve(robot, tdct.Actuation(act.tensions, d + k * h), load).tip_position) for k in (-2, -1, 1, 2)}
    fd = (8 * (tip[1] - tip[-1]) - (tip[2] - tip[-2])) / (12 * h)
    assert rel_err(J[:3, -1], fd) < 1e-6


def test_parameter_jacobian_matches_differences(paper_case):
    robot, act, load, _ = paper_case
    J = np.asarray(tdct.parameter_jacobian(robot, act, load, params=("sections[*].E", "tendons[*].offset")))
    for k, (name, h) in enumerate([("sections[*].E", 1e2), ("tendons[*].offset", 1e-7)]):
        value = tdct.fields.value(robot, name)
        tips = [tdct.solve(robot.replace({name: value + s * h}), act, load).tip_position for s in (1, -1)]
        assert rel_err(J[:3, k], (tips[0] - tips[1]) / (2 * h)) < 1e-6
    with pytest.raises(ValueError, match="'stiffness' is not a scalar robot field"):
        tdct.parameter_jacobian(robot, act, load, params=("stiffness",))


def test_ellipsoid_of_a_symmetric_matrix_has_eigenvalues_as_semi_axes():
    rng = np.random.default_rng(1)
    Q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    CM = Q @ np.diag([0.001, 0.08, 0.2]) @ Q.T
    e = tdct.compliance_ellipsoid(CM)
    np.testing.assert_allclose(e.eigenvalues, [0.001, 0.08, 0.2], rtol=1e-12)
    np.testing.assert_allclose(e.semi_axes, [0.2, 0.08, 0.001], rtol=1e-12)
    np.testing.assert_allclose(np.abs(e.axes[:, 0] @ e.eigenvectors[:, 2]), 1.0, rtol=1e-12)
    with pytest.raises(ValueError, match="shape"):
        tdct.compliance_ellipsoid(np.eye(2))


def test_bad_input_and_non_convergence_fail_loudly(robot):
    with pytest.raises(ValueError, match=r"insertions = \[0.3\] is outside"):
        tdct.compliance(robot, tdct.Actuation(insertions=0.3))
    act, load = BENT
    with pytest.raises(tdct.ConvergenceError):
        tdct.compliance(robot, act, load, solver=tdct.SolverOptions(max_iter=1))
    assert np.all(np.isnan(tdct.compliance(robot, act, load, solver=tdct.SolverOptions(max_iter=1), throw=False)))
