"""Inverse kinematics against truths the IK code did not produce: forward solves it must invert,
brute-force searches over actuation grids, scans of the redundant input, central differences."""

import json

import numpy as np
import pytest

import tdct_jax as tdct
from tdct_jax.cli import main

G = np.array([0.0, -9.81, 0.0])
REACH_M = 1e-9  # 1e-6 mm, as the issue asks


@pytest.fixture(scope="module")
def round_trip(robot):
    """1,000 random actuations over the envelope -> forward tips -> IK from the default start."""
    rng = np.random.default_rng(7)
    n = 1000
    tensions = rng.uniform(0, 10, (n, 4)) * (rng.random((n, 4)) < 0.5)
    insertion, mass = rng.uniform(0, 0.16, n), rng.uniform(0, 0.05, n)
    forward = tdct.sweep(robot, batch={"tensions": tensions, "insertion": insertion, "tip_mass": mass}, progress=False)
    loads = tdct.Loads.from_mass(mass)  # a batch of loads, one per target
    return forward, tdct.inverse_kinematics(robot, tdct.Target(forward.tip_position), load=loads, throw=False)


def test_round_trip_reaches_random_reachable_targets_within_bounds(round_trip):
    forward, result = round_trip
    error = np.asarray(result.position_error)
    reached = (error <= REACH_M) & (np.asarray(result.result) == tdct.status.SUCCESS)
    print(f"round trip: {reached.mean():.2%} reached within 1e-6 mm; steps mean {np.mean(result.iterations):.1f}")
    assert reached.mean() >= 0.999
    tensions, insertion = np.asarray(result.actuation.tensions), np.asarray(result.actuation.insertion)
    assert tensions.min() >= 0.0 and tensions.max() <= 10.0
    assert insertion.min() >= 0.0 and insertion.max() <= 0.16
    # the tip of the IK's own forward solution is where the independent forward sweep put it
    np.testing.assert_allclose(np.asarray(result.tip_position)[reached], forward.tip_position[reached], rtol=0, atol=REACH_M)


def test_retried_targets_get_the_answer_of_one_ik_from_every_start(robot, round_trip):
    """The batch tries a target's other starts side by side only where its first start fell short;
    each then has what one IK trying its starts in turn finds: the targets with the most steps
    (those retried) against single IKs."""
    forward, result = round_trip
    steps = np.asarray(result.iterations)
    hardest = np.argsort(steps)[-3:]
    assert steps[hardest].min() > np.median(steps)
    for i in hardest:
        load = tdct.Loads.from_mass(float(forward.inputs["tip_mass"][i]))
        one = tdct.inverse_kinematics(robot, tdct.Target(forward.tip_position[i]), load=load, throw=False)
        assert int(one.iterations) == steps[i] and int(one.result) == int(result.result[i])
        np.testing.assert_allclose(one.actuation.tensions, result.actuation.tensions[i], rtol=0, atol=1e-9)
        np.testing.assert_allclose(one.actuation.insertion, result.actuation.insertion[i], rtol=0, atol=1e-12)


@pytest.fixture(scope="module")
def tendon_1_tips(robot):
    """Tips over a fine grid of tendon-1 tensions (0.1 N) and insertions (2 mm): the brute force."""
    grid = {"tensions": np.outer(np.linspace(0, 10, 101), [1.0, 0, 0, 0]), "insertion": np.linspace(0, 0.16, 81)}
    return tdct.sweep(robot, grid=grid, progress=False).tip_position


@pytest.mark.parametrize("method", ["augmented", "nested"])
@pytest.mark.parametrize("position", [(0.0, 0.0, 0.20), (0.0, 0.03, -0.03)], ids=["beyond the length", "behind the base"])
def test_unreachable_targets_return_the_nearest_pose_a_brute_force_search_finds(robot, position, method, tendon_1_tips):
    result = tdct.inverse_kinematics(robot, tdct.Target(position), tendons=(1,), ik=tdct.IKOptions(method=method))
    assert int(result.result) == tdct.status.UNREACHABLE
    brute = np.linalg.norm(tendon_1_tips - np.asarray(position), axis=-1).min()
    print(f"nearest distance: IK {1e3 * float(result.position_error):.4f} mm, brute force {1e3 * brute:.4f} mm")
    assert abs(float(result.position_error) - brute) <= 0.01 * brute
    np.testing.assert_allclose(np.linalg.norm(np.asarray(result.tip_position) - position), result.position_error, rtol=1e-12)


def test_tracking_a_path_equals_solving_each_target_alone(robot):
    acts = [tdct.Actuation((t, 0, 0, 0), 0.05) for t in (4.0, 4.5, 5.0, 5.5)]
    tips = np.stack([np.asarray(tdct.solve(robot, a).tip_position) for a in acts])
    tracked = tdct.track(robot, tdct.Target(tips, axes="yz"), tendons=(1,), insertion=0.05)
    assert np.all(np.asarray(tracked.result) == tdct.status.SUCCESS)
    np.testing.assert_allclose(np.asarray(tracked.actuation.tensions)[:, 0], [4.0, 4.5, 5.0, 5.5], rtol=1e-8)
    steps, chords = np.asarray(tracked.iterations), np.asarray(tracked.chord_steps)
    # the first update is cold, a Jacobian pass a step; the warm ones chord steps from its model only
    assert chords[0] == 0 and np.all(chords[1:] == steps[1:]) and np.all(steps[1:] > 0)


@pytest.mark.parametrize(
    "make, words",
    [
        (lambda r: tdct.Target((0.0, np.nan, 0.1)), ["position must be finite"]),
        (lambda r: tdct.Target((0.0, 0.1)), ["position must have shape (3,)"]),
        (lambda r: tdct.Target((0.0, 0.0, 0.1), direction=(0.0, 0.0, 0.0)), ["direction", "nonzero"]),
        (lambda r: tdct.Target((0.0, 0.0, 0.1), axes="yw"), ["axes = 'yw'"]),
        (lambda r: tdct.Bounds(tension=(10.0, 2.0)), ["bounds.tension", "lowest <= highest"]),
        (lambda r: tdct.Bounds(tension=(-1.0, 10.0)), ["bounds.tension", "[0, inf] N"]),
        (
            lambda r: tdct.inverse_kinematics(r, (0.0, 0.0, 0.1), bounds=tdct.Bounds(insertion=(0.0, 0.2))),
            ["bounds.insertion", "0.16"],
        ),
        (lambda r: tdct.inverse_kinematics(r, (0.0, 0.0, 0.1), objective="softest"), ["objective = 'softest'", "stiffness"]),
        (lambda r: tdct.inverse_kinematics(r, (0.0, 0.0, 0.1), tendons=(0, 5)), ["tendons", "[1, 4]"]),
        (
            lambda r: tdct.inverse_kinematics(r, (0.0, 0.0, 0.1), objective=tdct.Stiffness(direction=(0, 0, 0))),
            ["Stiffness.direction", "nonzero"],
        ),
        (lambda r: tdct.inverse_kinematics(r, (0.0, 0.0, 0.1), tendons=5), ["tendons = 5", "[1, 4]"]),
        (lambda r: tdct.IKOptions(tol=0.0), ["IKOptions.tol = 0", "(0, inf]"]),
        (lambda r: tdct.IKOptions(max_steps=2.5), ["IKOptions.max_steps = 2.5", "integer >= 1"]),
        (lambda r: tdct.IKOptions(method="newton"), ["IKOptions.method = 'newton'", "augmented"]),
        (
            lambda r: tdct.inverse_kinematics(r, (0.0, 0.0, 0.1), objective=tdct.PreferredInsertion(depth=0.2)),
            ["PreferredInsertion.depth = 0.2", "[0, 0.16]"],
        ),
        (
            lambda r: tdct.inverse_kinematics(r, (0.0, 0.0, 0.1), tendons=1, insertion=0.06, objective="stiffness"),
            ["objective = 'stiffness': nothing to choose: 1 free input(s)", "for 3 task coordinate(s) (x, y, z)", "axes="],
        ),
        (
            lambda r: tdct.inverse_kinematics(r, tdct.Target((0.0, 0.0, 0.1), axes="yz"), tendons=(1,), objective="tension"),
            ["nothing to choose: 2 free input(s) (tendons (1,) and the insertion) for 2 task coordinate(s) (y, z)"],
        ),
        (lambda r: tdct.track(r, tdct.Target(np.zeros((0, 3)))), ["track needs at least one target", "(0, 3)"]),
        (lambda r: tdct.Target((0.0, 0.0, 0.1), tip_angle=np.radians(400)), ["tip_angle = 6.98", "[-3.14159, 3.14159] rad"]),
    ],
)
def test_bad_ik_input_names_field_value_and_range(robot, make, words):
    with pytest.raises(ValueError) as e:
        make(robot)
    for w in words:
        assert w in str(e.value), str(e.value)


def test_cli_ik_reaches_prints_json_and_exits_by_status(capsys, robot):
    tip = np.asarray(tdct.solve(robot, tdct.Actuation((5.0, 0, 0, 0), 0.04), tdct.Loads.from_mass(0.01)).tip_position)
    target = ",".join(f"{1e3 * x:.9f}" for x in tip)
    args = [
        "ik",
        "--target-mm",
        target,
        "--axes",
        "yz",
        "--tendons",
        "1,3",
        "--tip-mass-g",
        "10",
        "--objective",
        "tension",
        "--json",
    ]
    assert main(args) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["status"] == "converged" and out["position_error_mm"] < 1e-6
    assert set(out) >= {"tensions_N", "insertion_mm", "tip_position_mm", "tip_angle_deg", "compliance_along_direction_mm_per_N"}
    np.testing.assert_allclose(out["tip_position_mm"], 1e3 * tip, atol=1e-6)
    assert sum(t**2 for t in out["tensions_N"]) <= 5.0**2  # no more than the actuation that made the target
    assert main(["ik", "--target-mm", "0,0,300", "--tendons", "1", "--json"]) == 1  # unreachable: nearest pose printed
    out = json.loads(capsys.readouterr().out)
    assert out["status"] == "target unreachable" and out["position_error_mm"] > 100
    assert main(["ik", "--target-mm", "0,0,nan"]) == 2
    assert main(["ik", "--target-mm", "0,0,100", "--tendons", "5"]) == 2
    assert "--tendons 5 is outside the allowed range [1, 4]" in capsys.readouterr().err


@pytest.mark.parametrize(
    "argv, words",
    [
        (["--tip-angle-deg", "400"], "--tip-angle-deg 400 is outside the allowed range [-180, 180] deg"),
        (["--axes", "yw"], "--axes yw: the target components that count, each once, from x, y, z"),
        (["--max-steps", "0"], "--max-steps 0 is outside the allowed range [1, inf]"),
        (
            ["--objective", "stiffness", "--tendons", "1", "--insertion-mm", "60"],
            "--objective stiffness: nothing to choose: 1 free input(s) (tendons 1; --insertion-mm 60 fixes the tube) for 3 "
            "target component(s) (x, y, z); an objective needs more free inputs than target components: give more --tendons, "
            "leave out --insertion-mm, or fewer --axes",
        ),
        (
            ["--axes", "y", "--tip-angle-deg", "10", "--tendons", "1", "--objective", "tension"],
            "for 2 target component(s) (y and the tip angle)",
        ),
    ],
)
def test_cli_ik_refuses_at_once(argv, words, capsys):
    assert main(["ik", "--target-mm", "0,30,100", *argv]) == 2
    err = capsys.readouterr().err
    assert words in err and "Traceback" not in err


def test_cli_ik_target_typed_in_metres_gets_a_note(capsys):
    argv = ["ik", "--target-mm", "0,0,0.15", "--objective", "stiffness", "--tendons", "1", "--insertion-mm", "60"]
    assert main(argv) == 2  # nothing to choose: stops before solving
    assert (
        "tdct: note: --target-mm 0,0,0.15: 0.15 mm from the base is 0.00094 robot lengths away: did you type metres (150 mm)?"
        in capsys.readouterr().err
    )
    with pytest.warns(tdct.UnitWarning, match=r"target position: 150 m from the base is 938 robot lengths away.* millimetres"):
        with pytest.raises(ValueError, match="nothing to choose"):
            tdct.inverse_kinematics(tdct.Robot.paper(), (0.0, 0.0, 150.0), tendons=(1,), insertion=0.0, objective="tension")
