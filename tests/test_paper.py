"""The paper's stiffness studies: the batched Fig. 11 grid equals single solves; headline arithmetic."""

import numpy as np
import pytest

import tdct_jax as tdct
from tdct_jax import paper


def test_fig11_grid_equals_single_compliances(robot):
    tensions, insertions = (0.0, 8.0), (0.0, 0.15)
    lam = paper.fig11_eigenvalues(robot, tensions, insertions)
    assert lam.shape == (2, 2, 3)
    for i, tau in enumerate(tensions):
        for j, d in enumerate(insertions):
            CM = tdct.compliance(robot, tdct.Actuation((tau, 0, 0, 0), d))
            np.testing.assert_allclose(lam[i, j], tdct.compliance_ellipsoid(CM).eigenvalues, rtol=1e-10)
    # The tube stiffens the robot: both bending compliances fall as it goes in.
    assert np.all(lam[:, 1, 1:] < 0.6 * lam[:, 0, 1:])


def test_headline_reports_the_reduction_beside_the_paper():
    lam = np.zeros((1, 3, 3))
    lam[0, :, 1] = [0.2, 0.15, 0.08]
    (row,) = paper.compliance_headline([6.0], [0.0, 0.07, 0.15], lam)
    assert row["lambda2_mm_per_N"] == pytest.approx((200.0, 80.0), rel=1e-14)
    assert row["reduction_percent"] == pytest.approx(60.0, rel=1e-14)
    assert row["insertion_mm"] == (0.0, 150.0)
    assert abs(row["paper_reduction_percent"] - 57.7) < 0.01
