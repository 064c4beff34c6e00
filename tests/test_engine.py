"""The batch engine's two passes: a quick Broyden pass for every lane, then the lanes it leaves
unconverged (stragglers, failures) solved again apart by the full solver. Every point's answer,
converged flag and result code must be the single solve's."""

import numpy as np
import pytest

import tdct_jax as tdct
from tdct_jax import batch

N = 1000
FAILING = np.arange(37, N, 100)  # one point in every 100, in ten different chunks


@pytest.fixture(scope="module")
def envelope():
    """1,000 random points over the operating envelope, 1% of them beyond the model (400 N with
    no tube: the residual stops being finite)."""
    rng = np.random.default_rng(7)
    tensions = np.zeros((N, 4))
    tensions[:, 0] = rng.uniform(0, 10, N)
    tensions[:, 3] = rng.uniform(0, 10, N) * (rng.random(N) < 0.3)
    insertion, mass = rng.uniform(0, 0.16, N), rng.uniform(0, 0.05, N)
    tensions[FAILING], insertion[FAILING] = (400.0, 0, 0, 0), 0.0
    return {"tensions": tensions, "insertion": insertion, "tip_mass": mass}


@pytest.fixture(scope="module")
def singles(robot, envelope):
    return [
        tdct.solve(robot, tdct.Actuation(t, d), tdct.Loads.from_mass(m), throw=False)
        for t, d, m in zip(envelope["tensions"], envelope["insertion"], envelope["tip_mass"], strict=True)
    ]


def test_engine_gives_the_single_solve_answer_at_every_point(robot, envelope, singles):
    res = tdct.sweep(robot, batch=envelope, progress=False, throw=False)
    codes = np.array([int(s.result) for s in singles])
    assert np.array_equal(res.result, codes) and np.array_equal(res.converged, codes == tdct.status.SUCCESS)
    assert np.array_equal(np.flatnonzero(~res.converged), FAILING)  # each failing point, and only those
    assert np.all(res.result[FAILING] == tdct.status.NONFINITE) and res.n_failed == len(FAILING)
    # failures went through the full solver: its iterations and load stages
    assert np.array_equal(res.stages[FAILING], [int(singles[i].stages) for i in FAILING])
    assert np.array_equal(res.iterations[FAILING], [int(singles[i].iterations) for i in FAILING])
    ok = res.converged
    tips = np.array([np.asarray(s.tip_position) for s in singles])
    assert np.max(np.abs(res.tip_position[ok] - tips[ok])) < 1e-9
    wrenches = np.array([np.asarray(s.base_wrench) for s in singles])
    assert np.max(np.abs(res.base_wrench[ok] - wrenches[ok])) < 1e-8


def test_stragglers_are_solved_again_by_the_full_solver(robot, envelope, singles, monkeypatch):
    monkeypatch.setattr(batch, "FIRST_PASS", 2)  # few lanes converge in two Broyden steps: the rest are retried
    part = {k: v[:40] for k, v in envelope.items()}
    res = tdct.sweep(robot, batch=part, progress=False, throw=False, chunk_size=16)
    full = np.array([(int(s.iterations), int(s.stages)) for s in singles[:40]])
    retried = np.all(np.column_stack([res.iterations, res.stages]) == full, axis=1)
    assert retried.sum() >= 30 and np.all(res.converged[~retried]) and np.all(res.iterations[~retried] <= 2)
    assert [int(s.result) for s in singles[:40]] == res.result.tolist()
    tips = np.array([np.asarray(s.tip_position) for s in singles[:40]])
    assert np.max(np.abs(res.tip_position[res.converged] - tips[res.converged])) < 1e-9


@pytest.mark.slow
def test_first_pass_shapes_and_compliance_match_the_full_solver(robot, envelope, monkeypatch):
    part = {k: v[:16] for k, v in envelope.items()}
    two = tdct.sweep(robot, batch=part, progress=False, throw=False, shapes=True, compliance=True, chunk_size=8)
    monkeypatch.setattr(batch, "FIRST_PASS", None)
    one = tdct.sweep(robot, batch=part, progress=False, throw=False, shapes=True, compliance=True, chunk_size=8)
    assert one.result.tolist() == two.result.tolist()
    ok = one.converged
    assert np.max(np.abs(one.position[ok] - two.position[ok])) < 1e-9
    assert np.max(np.abs(one.compliance[ok] - two.compliance[ok])) < 1e-7 * np.abs(one.compliance[ok]).max()


def test_continuation_stages_are_solver_options(robot):
    act, load = tdct.Actuation((6.0, 0, 0, 0), 0.08), tdct.Loads.from_mass(0.02)
    one_ramp = tdct.solve(robot, act, load, solver=tdct.SolverOptions(tol=1e-18, stages=(1, 2)), throw=False)
    # every ramp tried, and failed: at a tolerance under round-off, the last Newton's stall or its
    # step limit comes first as the last bits of the residual fall
    failed = (tdct.status.CONTINUATION_EXHAUSTED, tdct.status.NEWTON_LIMIT)
    assert int(one_ramp.stages) == 2 and int(one_ramp.result) in failed
    for bad in ((), (0, 4), (4, 1), (1.5,), "1,4"):
        with pytest.raises(ValueError, match="stages"):
            tdct.SolverOptions(stages=bad)
