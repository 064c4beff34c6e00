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


@pytest.mark.slow
def test_highest_reach_is_the_maximum_of_the_tip_height(robot):
    """Sec. V.A: the highest reach with 50 g is where y_tip stops rising, not a point a chosen
    offset below it. At the reported insertion, central differences of forward solves give a zero
    slope (0.1 mm below the peak, the stiffest IK solution sits 5 mm deeper, where the slope is
    about -0.03), no depth of a 0.1 mm scan around it is higher, and the tension sits on its bound
    with the exact dy/dtau that differences give."""
    top = paper.highest_reach(robot, n_tensions=3, n_insertions=17, progress=False)
    assert top.converged and top.on_bound and top.tension == 10.0
    assert abs(top.slope_insertion) < 1e-9 and top.slope_tension > 0
    load = tdct.Loads.from_mass(paper.VA_MASS)

    def height(tension, depth):
        return float(tdct.solve(robot, tdct.Actuation((tension, 0, 0, 0), depth), load).tip_position[1])

    d, h = top.insertion, 1e-4
    assert height(10.0, d) == pytest.approx(top.height, abs=1e-12)
    assert abs(height(10.0, d + h) - height(10.0, d - h)) / (2 * h) < 1e-5
    assert abs(height(10.0, d + 5e-3) - height(10.0, d + 5e-3 - 2 * h)) / (2 * h) > 1e-2  # the old answer's slope
    dtau = 1e-4
    assert (height(10.0, d) - height(10.0 - dtau, d)) / dtau == pytest.approx(top.slope_tension, rel=1e-3)
    scan = np.linspace(d - 2e-3, d + 2e-3, 41)  # a grid of highest_reach's form: its compiled program serves
    res = tdct.sweep(robot, None, load, grid={"tensions": [[10.0, 0, 0, 0]], "insertion": scan}, progress=False)
    scan_height = res.tip_position[0, :, 1]
    assert scan_height.max() <= top.height + 1e-12
    assert abs(scan[np.argmax(scan_height)] - d) <= 0.05e-3 + 1e-12
