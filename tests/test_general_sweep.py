"""Sweeps on a GeneralRobot (issue 23): the two-segment robot's sweeps over tensions and a field, and
over displacements (warm-started, with the tensions found, slack included), equal to independent
single solves; bad names and values refused before anything is compiled; a ``tdct sweep`` spec of
a general robot file (the batch engine's first pass with a displacement-driven tendon). Three
compiled sweep programs and two single-solve programs."""

import dataclasses
import importlib

import numpy as np
import pytest

import tdct_jax as tdct
from tdct_jax import batch
from tdct_jax.cli import main
from tdct_jax.description import ROBOTS

sweep_module = importlib.import_module("tdct_jax.sweep")  # the module: tdct_jax.sweep is the function

# The batch engine's first pass stops at QUICK_TOL times the solver's tolerance (shooting.py): its
# tips lie within 1e-9 m of the single solve's, both that close to the exact root.
TIP_ATOL = 1e-9  # m
TENSION_ATOL = 1e-8  # N: the same tolerance on the scaled unknowns, times a typical force of ~1 N
BASE_TENSIONS = [0.0, 0.0, 0.4, 0.0, 0.8, 0.3]
DRIVEN = (0,)
DISPLACEMENTS = np.linspace(-0.004, 0.004, 4)[:, None]  # m; the first pays out: slack
SPEC = """
robot = "two_segment.toml"
[base]
tensions = [0.0, 0.0, 0.4, 0.0, 0.8, 0.3]
driven = [1]                       # tendon 1, numbered from 1
displacements = [0.0]
[grid]
"sections[1].E" = [50e9, 54e9]
displacements = {linspace = [-0.004, 0.004, 4], tendons = [1]}
"""


@pytest.fixture(scope="module")
def two_segment():
    return tdct.Robot.from_toml(ROBOTS / "two_segment.toml")


@pytest.fixture(scope="module")
def tension_grid():
    tensions = np.tile(BASE_TENSIONS, (3, 1))
    tensions[:, 0] = np.linspace(0.0, 3.0, 3)
    return {"tensions": tensions, "sections[*].E": np.array([40e9, 60e9])}


@pytest.fixture(scope="module")
def tension_sweep(two_segment, tension_grid):
    return tdct.sweep(two_segment, grid=tension_grid, progress=False)


@pytest.fixture(scope="module")
def displacement_grid():
    return {"sections[1].E": np.array([50e9, 54e9]), "displacements": DISPLACEMENTS}


@pytest.fixture(scope="module")
def displacement_sweep(two_segment, displacement_grid):
    base = tdct.Actuation(BASE_TENSIONS, displacements=[0.0], driven=DRIVEN)
    return tdct.sweep(two_segment, base, grid=displacement_grid, warm_start=True, progress=False)


def single(robot, sections, E, act):
    """The single solve with the modulus E in the given sections, set without fields.py's names."""
    changed = tuple(dataclasses.replace(s, E=E) if i in sections else s for i, s in enumerate(robot.sections))
    return tdct.solve(dataclasses.replace(robot, sections=changed), act)


def test_tension_and_field_sweep_equals_single_solves(two_segment, tension_grid, tension_sweep):
    res = tension_sweep
    assert res.shape == (3, 2) and res.n_failed == 0
    for i, t in enumerate(tension_grid["tensions"]):
        for j, E in enumerate(tension_grid["sections[*].E"]):
            sol = single(two_segment, (0, 1), E, tdct.Actuation(t))
            np.testing.assert_allclose(res.tip_position[i, j], sol.tip_position, rtol=0, atol=TIP_ATOL)
            np.testing.assert_array_equal(res.tensions[i, j], t)  # tension-driven: the given ones
    # the modulus matters: the stiffer body bends less under the same tensions
    assert np.all(np.abs(res.tip_position[1:, 1, :2]) < np.abs(res.tip_position[1:, 0, :2]) + 1e-12)


@pytest.mark.slow
def test_warm_started_displacement_sweep_equals_single_solves_and_returns_the_tensions(two_segment, displacement_sweep):
    res = displacement_sweep
    assert res.shape == (2, len(DISPLACEMENTS)) and res.n_failed == 0 and res.tensions.shape == (2, len(DISPLACEMENTS), 6)
    for j, E in enumerate([50e9, 54e9]):
        for k, d in enumerate(DISPLACEMENTS):
            sol = single(two_segment, (1,), E, tdct.Actuation(BASE_TENSIONS, displacements=d, driven=DRIVEN))
            np.testing.assert_allclose(res.tip_position[j, k], sol.tip_position, rtol=0, atol=TIP_ATOL)
            np.testing.assert_allclose(res.tensions[j, k], sol.tensions, rtol=0, atol=TENSION_ATOL)
            # slack exactly where the single solve says so, with a tension of exactly 0 in both
            assert (res.tensions[j, k, 0] == 0.0) == bool(sol.slack[0])
    assert np.all(res.tensions[:, 0, 0] == 0.0) and np.all(res.tensions[:, -2:, 0] > 0)  # paid out: slack
    assert np.all(res.tensions[:, -1, 0] > res.tensions[:, -2, 0])  # pulled further: more tension


@pytest.mark.parametrize(
    "grid, act, load, message",
    [
        ({"insertion": [0.0]}, None, None, "cannot sweep 'insertion': the robot has 0 tubes; sweep 'insertions', one depth each"),
        (
            {"sections[2].E": [1e9]},
            None,
            None,
            "'sections[2].E': the robot has 2 sections (indices 0 to 1, or a range a-b with a <= b)",
        ),
        ({"tendons[*].offsett": [0.01]}, None, None, "'tendons[*].offsett' is not a scalar robot field"),
        (
            {"sections[*].E": [5e10, -1.0]},
            None,
            None,
            "sections[*].E[1]: sections[0].E = -1 is outside the allowed range (0, inf]",
        ),
        ({"tensions": [[1.0, 0.0]]}, None, None, "tensions: each point must have shape (6,)"),
        ({"tensions": [np.zeros(6), -np.ones(6)]}, None, None, "tensions[1] = [-1., -1., -1., -1., -1., -1.] is outside"),
        ({"displacements": [[0.001]]}, None, None, "no tendon is displacement-driven"),
        ({"point_force": [np.zeros((1, 3))]}, None, None, "the base load has no point loads"),
        (
            {"point_force": [np.zeros((1, 3))]},
            None,
            tdct.Loads(point_s=[0.1, 0.2]),
            "point_force: each point must have shape (2, 3), got values of shape (1, 1, 3)",
        ),
        ({"insertions": [[0.0]]}, None, None, "insertions: each point must have shape (0,)"),
        ({"tip_mass": [0.0]}, tdct.Actuation(np.zeros(6), driven=(6,), displacements=[0.0]), None, "driven = (6,)"),
    ],
)
def test_bad_names_and_values_error_before_any_compile(two_segment, monkeypatch, grid, act, load, message):
    def compile_nothing(*args, **kwargs):
        raise AssertionError("the batch engine started")

    monkeypatch.setattr(sweep_module, "iter_batched", compile_nothing)
    with pytest.raises(ValueError) as e:
        tdct.sweep(two_segment, act, load, grid=grid, progress=False)
    assert message in str(e.value)


@pytest.mark.slow
def test_spec_file_sweep_of_a_general_robot(two_segment, displacement_sweep, tmp_path):
    (tmp_path / "two_segment.toml").write_text((ROBOTS / "two_segment.toml").read_text())
    (tmp_path / "spec.toml").write_text(SPEC)
    assert main(["sweep", str(tmp_path / "spec.toml"), "--out", str(tmp_path / "s.npz"), "--quiet"]) == 0
    with np.load(tmp_path / "s.npz") as data:
        np.testing.assert_array_equal(data["axis_displacements"], DISPLACEMENTS)
        np.testing.assert_array_equal(data["axis_sections[1].E"], [50e9, 54e9])
        # the spec's points are those of the warm-started sweep, solved cold (the engine's first pass)
        assert data["converged"].all() and data["iterations"].max() <= batch.FIRST_PASS
        np.testing.assert_allclose(data["tip_position"], displacement_sweep.tip_position, rtol=0, atol=TIP_ATOL)
        np.testing.assert_allclose(data["tensions"], displacement_sweep.tensions, rtol=0, atol=TENSION_ATOL)
        np.testing.assert_array_equal(data["tensions"][:, 0, 0], 0.0)  # slack: exactly 0


def test_bad_spec_names_the_file_key_and_value(tmp_path, capsys):
    (tmp_path / "two_segment.toml").write_text((ROBOTS / "two_segment.toml").read_text())
    spec = tmp_path / "spec.toml"
    spec.write_text(SPEC.replace("driven = [1]", "driven = [7]"))
    assert main(["sweep", str(spec), "--out", str(tmp_path / "s.npz")]) == 2
    assert f"{spec}: [base] driven = [7] must list tendons numbered 1 to 6" in capsys.readouterr().err
    spec.write_text(SPEC.replace('"sections[1].E" = [50e9, 54e9]', '"sections[1].E" = [50e9, 0.0]'))
    assert main(["sweep", str(spec), "--out", str(tmp_path / "s.npz")]) == 2
    assert f"{spec}: [grid] sections[1].E[1]: sections[1].E = 0 is outside the allowed range (0, inf]" in capsys.readouterr().err
