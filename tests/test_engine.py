"""The batch engine's two passes: lanes that need more than the first pass's Newton steps, load
continuation or fail are solved again apart, and every point's answer is the single solve's."""

import numpy as np
import pytest

import tdct_jax as tdct
from tdct_jax import batch


@pytest.fixture(scope="module")
def points():
    rng = np.random.default_rng(7)
    n = 24
    tensions = np.zeros((n, 4))
    tensions[:, 0] = rng.uniform(0, 10, n)
    insertion = rng.uniform(0, 0.16, n)
    tensions[3], insertion[3] = (400.0, 0, 0, 0), 0.0  # beyond the model: the residual stops being finite
    return {"tensions": tensions, "insertion": insertion, "tip_mass": rng.uniform(0, 0.05, n)}


def test_stragglers_and_failures_get_the_single_solve_answer(robot, points, monkeypatch):
    monkeypatch.setattr(batch, "FIRST_PASS", 2)  # most lanes need 3 Newton steps: retried
    res = tdct.sweep(robot, batch=points, progress=False, throw=False, chunk_size=16)
    singles = [
        tdct.solve(robot, tdct.Actuation(t, d), tdct.TipLoad.from_mass(m), throw=False)
        for t, d, m in zip(points["tensions"], points["insertion"], points["tip_mass"], strict=True)
    ]
    assert int(np.sum(res.iterations > 2)) >= 5  # the second pass did run
    assert [int(s.result) for s in singles] == res.result.tolist()
    assert res.result[3] == tdct.status.NONFINITE and res.n_failed == 1
    assert [int(s.iterations) for s in singles] == res.iterations.tolist()
    assert [int(s.stages) for s in singles] == res.stages.tolist()
    ok = res.result == tdct.status.SUCCESS
    tips = np.array([np.asarray(s.tip_position) for s in singles])
    assert np.max(np.abs(res.tip_position[ok] - tips[ok])) < 1e-9


def test_one_pass_gives_the_same_sweep(robot, points, monkeypatch):
    two = tdct.sweep(robot, batch=points, progress=False, throw=False, chunk_size=16)
    monkeypatch.setattr(batch, "FIRST_PASS", None)
    one = tdct.sweep(robot, batch=points, progress=False, throw=False, chunk_size=16)
    assert one.result.tolist() == two.result.tolist() and one.iterations.tolist() == two.iterations.tolist()
    ok = one.result == tdct.status.SUCCESS
    assert np.max(np.abs(one.tip_position[ok] - two.tip_position[ok])) < 1e-9


def test_continuation_stages_are_solver_options(robot):
    act, load = tdct.Actuation((6.0, 0, 0, 0), 0.08), tdct.TipLoad.from_mass(0.02)
    one_ramp = tdct.solve(robot, act, load, solver=tdct.SolverOptions(tol=1e-18, stages=(1, 2)), throw=False)
    assert int(one_ramp.stages) == 2 and int(one_ramp.result) == tdct.status.CONTINUATION_EXHAUSTED
    for bad in ((), (0, 4), (4, 1), (1.5,), "1,4"):
        with pytest.raises(ValueError, match="stages"):
            tdct.SolverOptions(stages=bad)
