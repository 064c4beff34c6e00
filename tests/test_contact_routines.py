"""The routines built on solve take the same scene= (issue 26): Jacobians with the contact set
held, sweeps, the force estimate beside known obstacles; inverse kinematics refuses a scene."""

import numpy as np
import pytest

import tdct_jax as tdct

TABLE = tdct.Scene((tdct.Plane(point=(0.0, -0.04, 0.0), normal=(0.0, 1.0, 0.0), name="table"),))
ACT = tdct.Actuation(tensions=(0.0, 0.0, 6.0, 0.0), insertions=0.05)


def test_kinematic_jacobian_in_contact_against_central_differences():
    """Tendon 3 presses the tip on the table: the tip cannot move along the table's normal, and
    its slide along the table follows the tension as central differences of the contact solve say."""
    J = tdct.kinematic_jacobian(tdct.Robot.paper(), ACT, scene=TABLE)
    h = 1e-4
    tips = [
        np.asarray(tdct.solve(tdct.Robot.paper(), tdct.Actuation((0.0, 0.0, 6.0 + d, 0.0), 0.05), scene=TABLE).tip_position)
        for d in (h, -h)
    ]
    np.testing.assert_allclose(J[:3, 2], (tips[0] - tips[1]) / (2 * h), rtol=1e-6, atol=1e-10)
    assert np.max(np.abs(J[1])) < 1e-9  # held on the table: no column moves the tip along y


def test_sweep_with_a_scene_equals_single_solves():
    depths = np.array([[0.0], [0.08], [0.16]])
    res = tdct.sweep(tdct.Robot.paper(), ACT, scene=TABLE, grid={"insertions": depths}, progress=False)
    for k, d in enumerate(depths[:, 0]):
        sol = tdct.solve(tdct.Robot.paper(), tdct.Actuation(ACT.tensions, d), scene=TABLE)
        np.testing.assert_allclose(res.tip_position[k], sol.tip_position, atol=1e-10)


def test_inverse_kinematics_refuses_a_scene():
    with pytest.raises(ValueError, match="scene"):
        tdct.inverse_kinematics(tdct.Robot.paper(), tdct.Target((0.0, -0.03, 0.14)), load=tdct.Loads().with_scene(TABLE))
