"""Bad input gets a ValueError naming field, value and range; non-convergence is never silent."""

import warnings

import jax
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
        (dict(tensions=((1.0, 2.0),), insertions=(0.0, 0.1, 0.2)), ["tensions", "shape"]),
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
        tdct.Loads.from_mass(-0.01)


def test_solve_checks_insertion_against_length_and_tendon_count(robot):
    with pytest.raises(ValueError, match=r"insertions = \[0.2\] is outside the allowed range \[0, 0.16\]"):
        tdct.solve(robot, tdct.Actuation(insertions=0.2))
    with pytest.raises(ValueError, match="4 tendons"):
        tdct.solve(robot, tdct.Actuation(tensions=(1.0, 2.0, 3.0)))
    with pytest.raises(ValueError, match="transition"):
        tdct.solve(robot, tdct.Actuation(), solver=tdct.SolverOptions(transition="smooth"))
    with pytest.raises(ValueError, match="steps"):
        tdct.solve(robot, tdct.Actuation(), solver=tdct.SolverOptions(steps=0))
    with pytest.raises(ValueError, match="gravity must have shape"):
        tdct.solve(robot, tdct.Actuation(), gravity=(0.0, -9.81))
    with pytest.raises(TypeError, match="tdct.Actuation"):
        tdct.solve(robot, (1.0, 0, 0, 0))


def test_a_sequence_holding_a_traced_number_is_one_traced_array():
    """``Actuation((tau, 0, 0, 0), d)`` and ``Target((0, h, 0))`` with tau, h traced (inside jit,
    vmap, grad) build their arrays from the traced numbers, as they do from concrete ones."""
    tensions = jax.jit(lambda t: tdct.Actuation((t, 0.0, 0.0, 0.0), 0.08).tensions)(6.0)
    np.testing.assert_array_equal(tensions, [6.0, 0.0, 0.0, 0.0])
    batch = jax.jit(jax.vmap(lambda t: tdct.Actuation([t, 2 * t, 0.0, 0.0], 0.08).tensions))(np.array([1.0, 3.0]))
    np.testing.assert_array_equal(batch, [[1.0, 2.0, 0.0, 0.0], [3.0, 6.0, 0.0, 0.0]])
    position = jax.jit(lambda h: tdct.Target((0.0, h, 0.0)).position)(0.03)
    np.testing.assert_array_equal(position, [0.0, 0.03, 0.0])
    assert jax.jit(jax.grad(lambda h: tdct.Target((h, 2 * h, 0.0)).position @ np.array([1.0, 1.0, 0.0])))(0.5) == 3.0


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


FAILURES = {  # each failure kind, forced: (actuation, solver options, what the message says)
    tdct.status.NEWTON_LIMIT: (
        tdct.Actuation((6.0, 0, 0, 0), 0.08),
        tdct.SolverOptions(max_iter=1),
        r"Newton limit reached: Newton used its limit of max_iter = 1 steps per load stage .*"
        r"\(\d+ steps in all; the loads were ramped in up to 16 stages\)\. Raise max_iter",
    ),
    tdct.status.CONTINUATION_EXHAUSTED: (
        tdct.Actuation((6.0, 0, 0, 0), 0.08),
        tdct.SolverOptions(tol=1e-18),  # below round-off: every step is rejected
        r"load continuation exhausted: Newton stalled .* even with the loads ramped in 16 stages",
    ),
    tdct.status.NONFINITE: (
        tdct.Actuation((400.0, 0, 0, 0), 0.0),  # 40x the calibrated range
        tdct.SolverOptions(),
        r"non-finite residual: the shooting residual is not finite",
    ),
}


@pytest.mark.parametrize("code", FAILURES)
def test_each_failure_kind_has_its_code_and_raises_its_own_message(robot, code):
    act, solver, words = FAILURES[code]
    load = tdct.Loads.from_mass(0.02)
    sol = tdct.solve(robot, act, load, solver=solver, throw=False)
    assert int(sol.result) == code and not bool(sol.converged)
    # One Newton step per load stage at least: the plain attempt, then ramps of 4 and 16 stages.
    assert int(sol.iterations) >= 3 and int(sol.stages) == 16
    with pytest.raises(tdct.ConvergenceError, match=words) as e:
        tdct.solve(robot, act, load, solver=solver)  # throw=True is the default
    assert e.value.result == code


def test_result_codes_per_lane_under_jit_and_vmap(robot):
    tensions = np.array([[6.0, 0, 0, 0], [400.0, 0, 0, 0], [0.0, 3.0, 0, 0]])

    @jax.jit
    def codes(solver):  # the options are an argument, their numbers leaves: one program serves both calls
        return jax.vmap(lambda tau: tdct.solve(robot, tdct.Actuation(tau, 0.0), solver=solver, throw=False).result)(tensions)

    def code(solver):
        return np.asarray(codes(solver)).tolist()

    assert code(tdct.SolverOptions()) == [tdct.status.SUCCESS, tdct.status.NONFINITE, tdct.status.SUCCESS]
    assert code(tdct.SolverOptions(max_iter=1)) == [tdct.status.NEWTON_LIMIT] * 3
    # throw=True inside the compiled program: the check runs there, lane by lane, with the message.
    with pytest.raises(Exception, match=r"ConvergenceError: the shooting solve did not converge: non-finite residual"):
        jax.jit(jax.vmap(lambda tau: tdct.solve(robot, tdct.Actuation(tau, 0.0)).tip_position))(tensions).block_until_ready()


@pytest.mark.parametrize(
    "make, words",
    [
        (lambda: tdct.SolverOptions(tol=np.inf), ["tol must be finite"]),
        (lambda: tdct.SolverOptions(tol=np.nan), ["tol must be finite"]),
        (lambda: tdct.SolverOptions(tol=0.0), ["tol = 0", "(0, inf]"]),
        (lambda: tdct.SolverOptions(max_iter=2.5), ["max_iter = 2.5", "integer >= 1"]),
        (lambda: tdct.SolverOptions(tendon_model="tilted"), ["tendon_model", "'exact', 'paper'"]),
        (lambda: tdct.Robot(tendon_angles=(0.0, 0.1, np.pi)), ["tendons 1 and 2", "overlap", "0.001 m"]),
        (lambda: tdct.Robot(tendon_offset=1.1e-3), ["tendon_offset = 0.0011", "[0.00125, 0.0095] m", "central channel"]),
        (lambda: tdct.Robot(calibrated_tension=(10.0, 0.0)), ["calibrated_tension", "lowest <= highest"]),
        (lambda: tdct.Robot(calibrated_tip_force=(0.0, -1.0)), ["calibrated_tip_force", "-1"]),
    ],
)
def test_bad_solver_options_and_robot_geometry(make, words):
    with pytest.raises(ValueError) as e:
        make()
    for w in words:
        assert w in str(e.value), str(e.value)


def test_finite_difference_step_must_be_positive(robot):
    for step in (0.0, -1e-3, np.nan):
        with pytest.raises(ValueError, match="step"):
            tdct.finite_difference_compliance(robot, tdct.Actuation(), step=step)


def test_robot_file_errors_name_file_field_value_unit_and_range(tmp_path):
    bad = tmp_path / "soft.toml"
    bad.write_text("[robot]\nE_silicone = -3.0\n")
    with pytest.raises(ValueError, match=r"robot file .*soft.toml: E_silicone = -3 is outside the allowed range \(0, inf\] Pa"):
        tdct.Robot.from_toml(bad)
    bad.write_text("[robot]\ndensity_silicone = -1130\n")
    with pytest.raises(ValueError, match=r"soft.toml: density_silicone = -1130 .* \[0, inf\] kg/m\^3"):
        tdct.Robot.from_toml(bad)


def test_inputs_beyond_the_calibrated_range_warn_but_solve(robot, tmp_path):
    with pytest.warns(tdct.CalibrationWarning, match=r"tensions up to 20 N are outside the range \[0, 10\] N"):
        tdct.solve(robot, tdct.Actuation((20.0, 0, 0, 0)), gravity=None)
    wide = tmp_path / "wide.toml"
    wide.write_text("[robot]\ncalibrated_tension = [0.0, 25.0]\n")
    with warnings.catch_warnings():
        warnings.simplefilter("error", tdct.CalibrationWarning)  # the file declares 0-25 N: no note
        tdct.solve(tdct.Robot.from_toml(wide), tdct.Actuation((20.0, 0, 0, 0)), gravity=None)
    with pytest.warns(tdct.CalibrationWarning, match="tip force magnitudes up to 0.8 N"):
        tdct.sweep(robot, batch={"force": [[0.0, -0.8, 0.0]]}, progress=False)


@pytest.mark.parametrize(
    "make, words",
    [
        (
            lambda: tdct.Robot(length=160),
            "length = 160 m is far outside the plausible range [0.005, 5] m: did you mean 160 millimetres (0.16 m)?",
        ),
        (
            lambda: tdct.Robot(E_silicone=0.85),
            "E_silicone = 0.85 Pa is far outside the plausible range [1000, 1e+09] Pa: did you mean 0.85 MPa",
        ),
        (lambda: tdct.Robot(E_tube=83.0), "did you mean 83 GPa (8.3e+10 Pa)?"),
        (lambda: tdct.Robot(density_silicone=1.13), "did you mean 1.13 g/cm^3 (1130 kg/m^3)?"),
        (
            lambda: tdct.Loads.from_mass(0.01, gravity=(0, -9810, 0)),
            "|gravity| = 9810 m/s^2 is far outside the plausible range [0, 100] m/s^2: did you mean 9810 mm/s^2 (9.81 m/s^2)?",
        ),
    ],
)
def test_values_typed_in_another_unit_get_a_note_naming_it(make, words):
    with pytest.warns(tdct.UnitWarning) as caught:
        make()
    assert words in str(caught[0].message)
    assert caught[0].filename == __file__  # attributed to the caller's line


def test_plausible_values_get_no_unit_note(tmp_path):
    with warnings.catch_warnings():
        warnings.simplefilter("error", tdct.UnitWarning)
        tdct.Robot(length=0.5, E_silicone=2e6, tendon_channel_diameter=0.0, density_silicone=0.0)
        tdct.Loads.from_mass(0.01, gravity=(0.0, -1.62, 0.0))  # the moon
    long = tmp_path / "long.toml"
    long.write_text("length = 160\n")
    with pytest.warns(tdct.UnitWarning, match=r"robot file .*long.toml: length = 160 m .* did you mean 160 millimetres"):
        tdct.Robot.from_toml(long)


def test_gather_says_a_file_is_not_a_sweep(tmp_path):
    (tmp_path / "shape.csv").write_text("s_mm,x_mm\n0,0\n")
    np.savez(tmp_path / "other.npz", a=np.zeros(2))
    with pytest.raises(ValueError, match=r"shape.csv: not a tdct sweep result .*: it is not an .npz \(zip\) archive"):
        tdct.gather(tmp_path / "shape.csv")
    with pytest.raises(ValueError, match=r"other.npz: not a tdct sweep result .* lacks the arrays \['result', 'shape'"):
        tdct.gather(tmp_path / "other.npz")


@pytest.mark.parametrize(("kw", "n"), [({"displacements": [1e-3]}, 0), ({"displacements": [1e-3, 2e-3], "driven": (0,)}, 1)])
def test_displacements_name_driven(kw, n):
    """Displacements without (enough) driven tendons: the message names driven= (issue 48)."""
    with pytest.raises(ValueError, match=rf"one per driven tendon, and driven = .* names {n}; driven= lists the tendons"):
        tdct.Actuation(tensions=[0.0] * 4, **kw)
