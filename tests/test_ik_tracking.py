"""Warm tracking updates (``tdct.track``) against the actuations that made the targets and against
cold solves of the same targets: the same answers, in fewer steps."""

import numpy as np
import pytest

import tdct_jax as tdct

N_PATH = 40
TENDONS, INSERTION = (1, 2), 0.06  # two inputs for three task coordinates: one answer


@pytest.fixture(scope="module")
def path(robot):
    """A smooth closed path of tendons 1 and 2 inside their bounds and the tips an independent
    forward sweep puts there, holding 20 g."""
    phase = 2 * np.pi * np.arange(N_PATH) / N_PATH
    tensions = np.zeros((N_PATH, 4))
    tensions[:, 0], tensions[:, 1] = 4 + 2 * np.sin(phase), 3 + 2 * np.cos(phase)
    load = tdct.Loads.from_mass(0.02)
    forward = tdct.sweep(robot, tdct.Actuation(insertions=INSERTION), load, batch={"tensions": tensions}, progress=False)
    return tensions, load, np.asarray(forward.tip_position)


@pytest.fixture(scope="module")
def tracked(robot, path):
    tensions, load, tips = path
    return tdct.track(
        robot, tdct.Target(tips), load=load, tendons=TENDONS, insertion=INSERTION, guess=tdct.Actuation(tensions[0])
    )


@pytest.mark.slow
def test_warm_updates_reach_the_actuations_that_made_the_targets(tracked, path):
    tensions, _, tips = path
    assert np.all(np.asarray(tracked.result) == tdct.status.SUCCESS)
    np.testing.assert_allclose(np.asarray(tracked.tip_position), tips, rtol=0, atol=1e-10)
    np.testing.assert_allclose(np.asarray(tracked.actuation.tensions), tensions, rtol=0, atol=1e-6)


@pytest.mark.slow
def test_warm_updates_match_cold_solves_in_fewer_steps(robot, tracked, path):
    _, load, tips = path
    cold = [tdct.inverse_kinematics(robot, tdct.Target(tip), load=load, tendons=TENDONS, insertion=INSERTION) for tip in tips]
    np.testing.assert_allclose(np.asarray(tracked.actuation.tensions), [c.actuation.tensions for c in cold], rtol=0, atol=1e-6)
    warm, chords = np.asarray(tracked.iterations)[1:], np.asarray(tracked.chord_steps)[1:]
    cold_steps = np.array([int(c.iterations) for c in cold])
    print(
        f"steps per update: warm median {np.median(warm)} ({np.median(chords)} chord), max {warm.max()}; "
        f"cold median {np.median(cold_steps)}"
    )
    # a step from the last update's model (the first-order predictor), then chord steps with it: in
    # the median no Jacobian pass, where every cold step takes one
    assert np.all(np.asarray([int(c.chord_steps) for c in cold]) == 0)
    assert np.median(warm - chords) == 0 < np.median(cold_steps)
