"""Compliance at any arc length, Jacobians in every input and calibration of any field of a
GeneralRobot (issue 23), against truths the code under test does not produce: central
differences of forward solves, the Timoshenko cantilever, and synthetic shapes of known fields.

Compiled configurations: the two-segment robot's tip compliance, its compliance at an arc length
(also the cantilever's: its tendons slack, gravity off), its solve with one point load (every
finite difference of it), its synthesize and its calibration; the paper robot as a GeneralRobot
with tendon 0 displacement-driven: its actuation Jacobian and its solve.
"""

import json

import numpy as np
import pytest

import tdct_jax as tdct
from tdct_jax import fields
from tdct_jax.description import ROBOTS

G = (0.0, -9.81, 0.0)
TENSIONS = [1.5, 0.0, 0.4, 0.0, 0.8, 0.3]  # N
D, E, NU = 1.4e-3, 54e9, 0.3  # the two-segment robot's backbone (two_segment.toml)
STEPS = np.array([2e-5] * 3 + [2e-6] * 3)  # N, N m: central differences of the solve
FD_RTOL = 1e-6
CLOSED_FORM_RTOL = 1e-9
RECOVERY_RTOL = 1e-6


def rel(a, b):
    a, b = np.asarray(a, float), np.asarray(b, float)
    return float(np.max(np.abs(a - b)) / np.max(np.abs(b)))


def vee_log(W):
    """The rotation vector of a rotation matrix near the identity, to second order."""
    A = (W - W.T) / 2
    return np.array([A[2, 1], A[0, 2], A[1, 0]])


@pytest.fixture(scope="module")
def two_segment():
    return tdct.Robot.from_toml(ROBOTS / "two_segment.toml")


def pose_by_differences(robot, act, at, moved):
    """The 6x6 central-difference compliance at ``at`` (d(position, rotation vector) at ``at`` /
    d(force, moment)), of solves with one point load at s = 0.3 m; ``moved(w)`` gives the Loads for
    the force and moment w (6,). Every solve has the same structure: one compiled program."""

    def pose(w):
        sol = tdct.solve(robot, act, moved(w), gravity=G)
        i = np.flatnonzero(np.asarray(sol.s) == at)[0]
        return np.asarray(sol.position[i]), np.asarray(sol.rotation[i])

    columns = []
    for k in range(6):
        w = np.zeros(6)
        w[k] = STEPS[k]
        (p1, R1), (p0, R0) = pose(w), pose(-w)
        columns.append(np.concatenate([(p1 - p0), vee_log(R1 @ R0.T)]) / (2 * STEPS[k]))
    return np.stack(columns, axis=1)


@pytest.fixture(scope="module")
def tip_compliance(two_segment):
    return np.asarray(tdct.compliance(two_segment, tdct.Actuation(TENSIONS), gravity=G, full=True))


@pytest.mark.slow
def test_tip_compliance_matches_central_differences(two_segment, tip_compliance):
    def at_tip(w):
        return tdct.Loads(tip_force=w[:3], tip_moment=w[3:], point_s=[0.3], point_force=[[0.0, 0.0, 0.0]])

    fd = pose_by_differences(two_segment, tdct.Actuation(TENSIONS), 0.4, at_tip)
    assert rel(tip_compliance, fd) < FD_RTOL, [rel(tip_compliance[:, k], fd[:, k]) for k in range(6)]


@pytest.mark.slow
@pytest.mark.parametrize("s", [0.2, 0.3])  # the segment boundary (and segment 1's anchors), inside segment 2
def test_compliance_at_an_arc_length_matches_central_differences(two_segment, tip_compliance, s):
    act = tdct.Actuation(TENSIONS)
    C = np.asarray(tdct.compliance(two_segment, act, at=s, gravity=G, full=True))

    def at_s(w):
        return tdct.Loads(point_s=[s], point_force=[w[:3]], point_moment=[w[3:]])

    assert rel(C, pose_by_differences(two_segment, act, s, at_s)) < FD_RTOL
    np.testing.assert_array_equal(tdct.compliance(two_segment, act, at=s, gravity=G), C[:3, :3])
    assert np.abs(C).max() < np.abs(tip_compliance).max()  # nearer the base, stiffer


def test_compliance_at_the_length_is_the_tip_compliance(two_segment, tip_compliance):
    C = tdct.compliance(two_segment, tdct.Actuation(TENSIONS), at=0.4, gravity=G, full=True)
    assert rel(C, tip_compliance) < 1e-12


@pytest.mark.parametrize("a", [0.1, 0.25])
def test_compliance_of_a_straight_cantilever_is_timoshenkos(two_segment, a):
    """No tension and no gravity: a straight uniform rod, whose compliance at s = a to a load at a is
    the clamped beam's of length a, with the model's shear stiffness G A (no shear coefficient)."""
    C = np.asarray(tdct.compliance(two_segment, tdct.Actuation(np.zeros(6)), at=a, gravity=None, full=True))
    A, I = np.pi / 4 * D**2, np.pi / 64 * D**4
    Gm = E / (2 * (1 + NU))
    EI, bend, tilt = E * I, a**3 / (3 * E * I) + a / (Gm * A), a**2 / (2 * E * I)
    expected = np.diag([bend, bend, a / (E * A), a / EI, a / EI, a / (Gm * 2 * I)])
    expected[4, 0] = expected[0, 4] = tilt  # F_x bends towards +x: a rotation about +y
    expected[3, 1] = expected[1, 3] = -tilt
    assert rel(C, expected) < CLOSED_FORM_RTOL


# ---- calibration -------------------------------------------------------------------------------

CONDITIONS = [TENSIONS, [0.0, 1.0, 0.0, 0.5, 0.0, 0.0], [0.0, 0.0, 1.2, 0.0, 0.0, 0.9]]
PARAMS = ("sections[*].E", "tendons[0].offset")


@pytest.fixture(scope="module")
def fitted(two_segment):
    measured = tdct.synthesize(two_segment, [tdct.Actuation(t) for t in CONDITIONS], noise=0.0, gravity=G, n_points=17)
    start = fields.replace(two_segment, {"sections[*].E": 1.2 * E, "tendons[0].offset": 0.011})
    return measured, tdct.calibrate(start, measured, PARAMS, gravity=G, progress=False)


@pytest.mark.slow
def test_calibration_recovers_the_modulus_and_a_tendon_offset(two_segment, fitted):
    measured, fit = fitted
    assert [e.name for e in measured] == ["t1.5-0-0.4-0-0.8-0.3N_m0g", "t0-1-0-0.5-0-0N_m0g", "t0-0-1.2-0-0-0.9N_m0g"]
    assert fit.converged, fit.message
    assert fit.initial == {"sections[*].E": pytest.approx(1.2 * E), "tendons[0].offset": 0.011}
    assert fit.values["sections[*].E"] == pytest.approx(E, rel=RECOVERY_RTOL)
    assert fit.values["tendons[0].offset"] == pytest.approx(0.010, rel=RECOVERY_RTOL)
    # the fitted robot: every section's modulus and only tendon 0's offset changed
    assert isinstance(fit.robot, tdct.Robot)
    assert [float(s.E) for s in fit.robot.sections] == [fit.values["sections[*].E"]] * 2
    assert float(fit.robot.tendons[0].offset) == fit.values["tendons[0].offset"]
    assert [float(t.offset) for t in fit.robot.tendons[1:]] == [0.010] * 5
    assert np.all(fit.rmse_before > 1e-3) and np.all(fit.rmse_after < 1e-8)
    assert "sections[*].E" in fit.summary() and json.loads(json.dumps(fit.to_dict()))["params"] == list(PARAMS)


# ---- the actuation Jacobian: tensions, displacements, insertions -------------------------------

DISPLACEMENT = 2e-3  # m, tendon 0 of the paper robot; tendon 3 at 1 N, the tube at 80 mm


def paper_act(tension=1.0, displacement=DISPLACEMENT, insertion=0.08):
    return tdct.Actuation([0.0, 0.0, 0.0, tension], [insertion], [displacement], driven=(0,))


@pytest.mark.slow
def test_actuation_jacobian_covers_tensions_displacements_and_insertions():
    robot, load = tdct.Robot.paper(), tdct.Loads.from_mass(0.02)
    J = np.asarray(tdct.kinematic_jacobian(robot, paper_act(), load, gravity=G))
    assert J.shape == (6, 4 + 1 + 1)  # tensions, the driven tendon's displacement, the insertion
    np.testing.assert_array_equal(J[:, 0], 0.0)  # tendon 0's tension follows from its displacement

    def derivative(name, x, h):
        """Fourth-order central differences of the tip (it curves sharply in the insertion)."""
        tips = {}
        for k in (-2, -1, 1, 2):
            sol = tdct.solve(robot, paper_act(**{name: x + k * h}), load, gravity=G)
            assert float(sol.tensions[0]) > 0 and not np.any(sol.slack)
            tips[k] = np.asarray(sol.tip_position)
        return (8 * (tips[1] - tips[-1]) - (tips[2] - tips[-2])) / (12 * h)

    assert rel(J[:3, 3], derivative("tension", 1.0, 1e-3)) < FD_RTOL
    assert rel(J[:3, 4], derivative("displacement", DISPLACEMENT, 1e-6)) < FD_RTOL
    assert rel(J[:3, 5], derivative("insertion", 0.08, 2e-5)) < FD_RTOL


# ---- bad input ----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "params, words",
    [
        (("sections[*].G",), ["params: 'sections[*].G' is not a scalar robot field", "sections[i, * or a-b]"]),
        (("tendons[6].offset",), ["'tendons[6].offset'", "6 tendons (indices 0 to 5, or a range a-b"]),
        (("tendons[0].stiffness",), ["tendons[0].stiffness is not set (None)"]),
        (("E_robot",), ["'E_robot' is not a scalar robot field"]),
    ],
)
def test_bad_params_are_refused_naming_the_field(two_segment, params, words):
    e = tdct.Experiment([0.0, 0.4], np.zeros((2, 3)), tdct.Actuation(TENSIONS))
    for call in (
        lambda: tdct.calibrate(two_segment, [e], params, progress=False),
        lambda: tdct.parameter_jacobian(two_segment, tdct.Actuation(TENSIONS), params=params),
    ):
        with pytest.raises(ValueError) as err:
            call()
        for w in words:
            assert w in str(err.value), (w, str(err.value))


@pytest.mark.parametrize(
    "at, words",
    [
        (0.5, ["at = 0.5 is outside the allowed range [0, 0.4] m (0 to the robot length 0.4 m)"]),
        (-1e-3, ["at = -0.001 is outside"]),
        ([0.1, 0.2], ["at must have shape ()"]),
        (np.nan, ["at must be finite"]),
    ],
)
def test_bad_arc_lengths_are_refused(two_segment, at, words):
    with pytest.raises(ValueError) as err:
        tdct.compliance(two_segment, tdct.Actuation(TENSIONS), at=at)
    for w in words:
        assert w in str(err.value), (w, str(err.value))


def test_general_experiments_stack_and_stay_out_of_shape_files(tmp_path):
    acts = [
        tdct.Actuation([1.0, 0.0], [0.05], [1e-3], driven=(1,)),
        tdct.Actuation([0.0, 2.0], [0.0], [2e-3], (1,)),
    ]
    loads = [tdct.Loads(tip_force=(0.0, 0.1, 0.0)), tdct.Loads(point_s=[0.1], point_force=[[0.0, 0.0, 0.2]])]
    exps = [
        tdct.Experiment([0.0, 0.1], np.zeros((2, 3)), a, ld, name=str(i))
        for i, (a, ld) in enumerate(zip(acts, loads, strict=True))
    ]
    with pytest.raises(ValueError, match="different numbers of point loads"):
        tdct.data.stack(exps)
    exps[0] = tdct.Experiment([0.0, 0.1], np.zeros((2, 3)), acts[0], tdct.Loads(point_s=[0.2], point_force=[[1.0, 0, 0]]))
    batch = tdct.data.stack(exps)
    assert batch.act.driven == (1,) and np.shape(batch.act.displacements) == (2, 1)
    np.testing.assert_array_equal(batch.load.point_s, [[0.2], [0.1]])
    np.testing.assert_array_equal(batch.tip_load(None).tip_force, np.zeros((2, 3)))
    with pytest.raises(ValueError, match="all must have the same driven tendons"):
        tdct.data.stack([exps[0], tdct.Experiment([0.0, 0.1], np.zeros((2, 3)), tdct.Actuation((1.0, 0.0), [0.0]))])
    with pytest.raises(ValueError, match="the shape file holds the tensions, one tube.s insertion"):
        tdct.write_experiment(tmp_path / "x.csv", exps[0])
