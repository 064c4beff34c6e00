"""Bad input gets a ValueError naming field, value and range; non-convergence is never silent."""

import numpy as np
import pytest

import tdct_jax as tdct


@pytest.mark.parametrize(
    "kwargs, words",
    [
        (dict(tensions=(-1.0, 0, 0, 0)), ["tensions", "-1", "[0, inf]"]),
        (dict(tensions=(np.nan, 0, 0, 0)), ["tensions", "finite"]),
        (dict(tensions=(np.inf, 0, 0, 0)), ["tensions", "finite"]),
        (dict(insertion=-0.01), ["insertion", "-0.01", "[0"]),
        (dict(insertion="deep"), ["insertion", "numeric"]),
        (dict(tensions=((1.0, 2.0),)), ["tensions", "shape"]),
    ],
)
def test_bad_actuation(kwargs, words):
    with pytest.raises(ValueError) as e:
        tdct.Actuation(**kwargs)
    for w in words:
        assert w in str(e.value)


@pytest.mark.parametrize(
    "kwargs, words",
    [
        (dict(length=0.0), ["length", "(0, inf]"]),
        (dict(E_silicone=-1.0), ["E_silicone", "-1"]),
        (dict(E_tube=0.0), ["E_tube"]),
        (dict(nu_silicone=0.7), ["nu_silicone", "0.7", "(-1, 0.5]"]),
        (dict(outer_diameter=float("nan")), ["outer_diameter", "finite"]),
        (dict(tube_outer_diameter=2e-3), ["tube_outer_diameter", "0.002", "channel"]),
        (dict(tendon_offset=0.0199), ["tendon_offset", "0.0199"]),
        (dict(density_silicone=-5.0), ["density_silicone", "-5"]),
    ],
)
def test_bad_robot(kwargs, words):
    with pytest.raises(ValueError) as e:
        tdct.Robot(**kwargs)
    for w in words:
        assert w in str(e.value)


def test_bad_tip_load():
    with pytest.raises(ValueError, match=r"force must have shape \(3,\)"):
        tdct.TipLoad(force=(0.0, 1.0))
    with pytest.raises(ValueError, match="moment must be finite"):
        tdct.TipLoad(moment=(0.0, np.nan, 0.0))
    with pytest.raises(ValueError, match="mass"):
        tdct.TipLoad.from_mass(-0.01)


def test_solve_checks_insertion_against_length_and_tendon_count(robot):
    with pytest.raises(ValueError, match=r"insertion = 0.2 is outside the allowed range \[0, 0.16\]"):
        tdct.solve(robot, tdct.Actuation(insertion=0.2))
    with pytest.raises(ValueError, match="4 tendons"):
        tdct.solve(robot, tdct.Actuation(tensions=(1.0, 2.0, 3.0)))
    with pytest.raises(ValueError, match="transition"):
        tdct.solve(robot, tdct.Actuation(), transition="smooth")
    with pytest.raises(ValueError, match="steps"):
        tdct.solve(robot, tdct.Actuation(), steps=0)
    with pytest.raises(ValueError, match="gravity must have shape"):
        tdct.solve(robot, tdct.Actuation(), gravity=(0.0, -9.81))
    with pytest.raises(TypeError, match="tdct.Actuation"):
        tdct.solve(robot, (1.0, 0, 0, 0))


def test_robot_toml(tmp_path):
    good = tmp_path / "robot.toml"
    good.write_text("[robot]\nlength = 0.2\nE_silicone = 1.0e6\ntendon_angles = [0.0, 3.14159]\n")
    r = tdct.Robot.from_toml(good)
    assert float(r.length) == 0.2 and r.n_tendons == 2
    for text, word in [
        ("length = ", "cannot read"),
        ("lenght = 0.2", "unknown field"),
        ("length = -1.0", "length"),
    ]:
        bad = tmp_path / "bad.toml"
        bad.write_text(text)
        with pytest.raises(ValueError, match=word) as e:
            tdct.Robot.from_toml(bad)
        assert "bad.toml" in str(e.value)
    with pytest.raises(ValueError, match="cannot read"):
        tdct.Robot.from_toml(tmp_path / "missing.toml")


def test_non_convergence_is_loud(paper_case):
    robot, act, load, _ = paper_case
    sol = tdct.solve(robot, act, load, max_iter=1)
    # One Newton step per load stage: the plain attempt, then ramps of 4 and 16 stages.
    assert not bool(sol.converged) and 1 <= int(sol.iterations) <= 1 + 4 + 16
    with pytest.raises(
        tdct.ConvergenceError,
        match=r"tip (force|moment) . residual .* > tol 1e-10 after \d+ iterations; raise max_iter \(now 1\)",
    ):
        tdct.solve(robot, act, load, max_iter=1, throw=True)
