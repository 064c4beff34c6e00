"""A robot on its rig (tdct_jax.rig) and its calibration from a recording (tdct_jax.calibrate_rig):
the drive against the straight robot's closed form, known values recovered from recordings the
library made, and ``tdct calibrate --dataset`` end to end on a slice of the real ftdcr-v4 data.

Every solve here is the ftdcr-v4 robot with 24 samples, so the programs compile once per session."""

import dataclasses
import importlib
import json
import re
import shutil
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import tdct_jax as tdct
from tdct_jax import cli
from tdct_jax import rig as rigs
from tdct_jax.calibrate_rig import RIG_SOLVER, identify_geometry, predict, synthesize_recording
from tdct_jax.recording import read_dataset

calibrate_rig = importlib.import_module("tdct_jax.calibrate_rig")  # tdct_jax.calibrate_rig is also a former name
DATA = Path(__file__).resolve().parents[1] / "data" / "ftdcr-v4"
N = 24
"""Samples per recording in this file (one compiled program per sample count)."""
PARAMS = (
    "sections[*].E",
    "tendons[0-2].stiffness",
    "tendons[3-5].stiffness",
    "tendons[6-8].stiffness",
    "pretension[0-2]",
    "pretension[3-5]",
    "pretension[6-8]",
    "tendons[0].angle",
    "tendons[4].angle",
    "tendons[8].angle",
    "rotation[0]",
    "rotation[1]",
    "translation[0]",
    "translation[1]",
    "translation[2]",
)
TRUTH = {
    "sections[*].E": 45e9,
    "tendons[0-2].stiffness": 220.0,
    "tendons[3-5].stiffness": 420.0,
    "tendons[6-8].stiffness": 500.0,
    "pretension[0-2]": 6.0,
    "pretension[3-5]": 2.5,
    "pretension[6-8]": 4.0,
    "tendons[0].angle": np.radians(-171.0),
    "tendons[4].angle": np.radians(-29.0),
    "tendons[8].angle": np.radians(131.0),
    "rotation[0]": 0.02,
    "rotation[1]": -0.01,
    "translation[0]": 0.001,
    "translation[1]": -0.002,
    "translation[2]": 0.008,
}


@pytest.fixture(scope="module")
def lab():
    """The robot file's rig with gravity on, across the robot (azimuth 90 degrees: along +y), without
    its tendon friction (test_friction.py has the rig with it)."""
    rig = frictionless(rigs.Rig.from_toml(DATA / "robot.toml"))
    return dataclasses.replace(rig, g=9.81, gravity_azimuth=np.pi / 2, gravity_elevation=0.0)


def frictionless(rig):
    sections = tuple(dataclasses.replace(s, friction=None) for s in rig.robot.sections)
    return dataclasses.replace(rig, robot=dataclasses.replace(rig.robot, sections=sections))


@pytest.fixture(scope="module")
def servos(lab):
    """Each segment bent toward its own direction by its own amount (up to 3 mm of servo travel,
    pulling the tendons on that side and releasing the others), drawn at random per sample
    (servo readings [m], (N, 9))."""
    rng = np.random.default_rng(7)
    phi, amplitude = rng.uniform(0, 2 * np.pi, (N, 3)), rng.uniform(0, 3e-3, (N, 3))
    angles = np.array([float(t.angle) for t in lab.robot.tendons]).reshape(3, 3)
    return (amplitude[:, :, None] * np.cos(phi[:, :, None] - angles[None])).reshape(N, 9)


@pytest.mark.parametrize("robot_case", ["v4, no pretension", "222 mm, E 10 GPa, gravity"])
def test_large_pulls_at_zero_pretension_solve_from_the_straight_robot(lab, robot_case):
    """Servo readings of +-15 mm on every tendon at once (tips up to 140 mm off the axis, tendons
    going slack), each solved cold from the straight robot with the rig's solver: all converge.
    The v4 robot at zero pretension, and a 222 mm one with its backbone at E = 10 GPa under
    gravity across it."""
    rig = rigs.replace(lab, {"pretension[*]": 0.0})
    if robot_case.startswith("222"):
        r, L = rig.robot, 0.222
        tendons = tuple(dataclasses.replace(t, end=None if t.end is None else t.end * L / r.length) for t in r.tendons)
        robot = tdct.Robot(length=L, sections=(dataclasses.replace(r.sections[0], end=L, E=10e9),), tendons=tendons)
        rig = dataclasses.replace(rig, robot=robot)
    else:
        rig = dataclasses.replace(rig, g=0.0)
    servos = np.random.default_rng(3).uniform(-15e-3, 15e-3, (16, 9))
    n = rig.robot.n_tendons
    for servo in servos:
        act = tdct.Actuation(np.zeros(n), (), np.asarray(rig.displacements(servo)), tuple(range(n)))
        sol = tdct.solve(rig.robot, act, gravity=rig.gravity, solver=RIG_SOLVER, throw=False)
        assert sol.converged, (servo, int(sol.result), int(sol.iterations))
    assert np.asarray(sol.slack).any()  # the last pose has slack tendons


def test_geometry_from_single_tendon_pulls_from_any_start(lab, truth):
    """Pulls made by a known rig whose servos read negative when they pull (sign -1): each tendon
    pulled alone (1, 2, 3 mm, the others let go 10 mm, as in the v4 pulls), weightless. From a start whose tendon
    patterns are turned by 180 degrees plus up to +-30 degrees per tendon, with zero pretension,
    tendons 3 times as stiff and E doubled, the geometry step finds every angle, the registration's
    rotation about the axis (0.1 rad, not known to it) carried in the angles, and the servo sign."""
    known = dataclasses.replace(truth, sign=-1.0, g=0.0, rotation=np.array([0.0, 0.0, 0.1]))
    rows = [np.zeros(9)]
    for i in range(9):
        for pull in (1e-3, 2e-3, 3e-3):
            row = np.full(9, 10e-3)
            row[i] = -pull
            rows.append(row)
    pulls = synthesize_recording(known, np.array(rows))
    rng = np.random.default_rng(11)
    wrong = {
        f"tendons[{i}].angle": float(t.angle) + np.pi + np.radians(rng.uniform(-30, 30)) for i, t in enumerate(lab.robot.tendons)
    }
    wrong |= {"pretension[*]": 0.0, "sections[*].E": 2 * float(lab.robot.sections[0].E)}
    wrong |= {f"tendons[{i}].stiffness": 3 * float(t.stiffness) for i, t in enumerate(lab.robot.tendons)}
    start = rigs.replace(lab, wrong)
    found, geometry = identify_geometry(start, pulls)
    assert geometry.sign == -1.0 and float(found.sign) == -1.0 and geometry.samples.tolist() == [3] * 9
    turned = np.array([float(t.angle) for t in known.robot.tendons]) + 0.1  # the rotation about the axis
    error = np.angle(np.exp(1j * (geometry.angles - turned)))
    assert np.degrees(np.abs(error)).max() < 0.05, np.degrees(error)
    assert [float(t.angle) for t in found.robot.tendons] == pytest.approx(geometry.angles.tolist(), abs=0)


def test_rotation_vector_closed_form():
    t = 0.7
    rotation = jax.jit(rigs.rotation_matrix)
    R = rotation(jnp.array([0.0, 0.0, t]))
    expected = np.array([[np.cos(t), -np.sin(t), 0.0], [np.sin(t), np.cos(t), 0.0], [0.0, 0.0, 1.0]])
    np.testing.assert_allclose(R, expected, atol=1e-15)
    w = jnp.array([0.3, -0.2, 0.5])
    np.testing.assert_allclose(rotation(w) @ w, w, atol=1e-15)  # the axis stays
    np.testing.assert_allclose(rotation(w) @ rotation(-w), np.eye(3), atol=1e-15)
    d = jax.jit(jax.jacfwd(rigs.rotation_matrix))(jnp.zeros(3))  # at 0: dR/dw_k = e_k^
    np.testing.assert_allclose(d[:, :, 2], [[0, -1, 0], [1, 0, 0], [0, 0, 0]], atol=1e-15)


def test_pretension_holds_the_straight_robot(lab):
    """Servo 0, tendons exactly 120 degrees apart, no gravity: the robot stays straight, and each
    segment's tendons carry the tension of the closed form: tendon i, anchored at a_i, is pulled
    in by pretension_i a_i / EA_i and spans the backbone compressed by the tensions anchored
    beyond each point, l_i = int_0^a_i (1 - sum tau_j / (E A)) ds, so that
    a_i - l_i / (1 + tau_i / EA_i) = pretension_i a_i / EA_i."""
    seg = np.repeat(np.arange(3), 3)
    angles = np.radians([-174.0, -142.0, -120.0])[seg] + 2 * np.pi / 3 * np.tile(np.arange(3), 3)
    rig = rigs.replace(dataclasses.replace(lab, g=0.0), {f"tendons[{i}].angle": float(a) for i, a in enumerate(angles)})
    tip, unknowns, codes, _ = rigs.along(rig, jnp.zeros((N, 9)), RIG_SOLVER)
    assert np.all(np.asarray(codes) == 0)
    np.testing.assert_allclose(np.asarray(tip)[0, :2], 0.0, atol=1e-12)

    EA_b = 50e9 * np.pi * 0.0005**2
    anchors = np.array([0.06, 0.1225, 0.1865])
    EA = np.array([float(t.stiffness) for t in rig.robot.tendons])[::3]
    pre = np.asarray(rig.pretension)[::3]
    tau = pre.copy()
    for _ in range(200):  # fixed point: converges at once, the backbone being stiff
        load = np.array([3 * tau[k:].sum() for k in range(3)])  # compression in each segment's span
        l = np.cumsum(np.diff(np.r_[0.0, anchors]) * (1 - load / EA_b))
        tau = EA * (l / (anchors * (1 - pre / EA)) - 1)
    np.testing.assert_allclose(np.asarray(unknowns)[0, 6:], np.repeat(tau, 3), rtol=1e-8)


def test_a_rig_from_a_file_and_one_set_in_python_run_one_program(lab):
    """Python floats and numpy scalars become the same leaves (float64, not weakly typed), so the
    fixture's rig and the file's, as the command line reads it, share their compiled programs."""
    rig = frictionless(rigs.Rig.from_toml(DATA / "robot.toml"))
    assert [jax.typeof(x) for x in jax.tree.leaves(rig)] == [jax.typeof(x) for x in jax.tree.leaves(lab)]
    assert jax.typeof(lab.g) == jax.typeof(np.float64(0.0))


def test_names_values_and_errors(lab):
    assert rigs.value(lab, "pretension[0-2]") == pytest.approx(7.3149)
    moved = rigs.replace(lab, {"pretension[3-5]": 2.0, "rotation[2]": 0.1, "scale": 1.1, "tendons[0-2].stiffness": 250.0})
    assert np.asarray(moved.pretension)[3:6].tolist() == [2.0, 2.0, 2.0] and float(moved.rotation[2]) == 0.1
    assert [float(t.stiffness) for t in moved.robot.tendons[:4]] == [250.0, 250.0, 250.0, pytest.approx(390.1)]
    with pytest.raises(ValueError, match=re.escape("'rotation[3]': rotation has 3 entries (indices 0 to 2")):
        rigs.check_name(lab, "rotation[3]")
    with pytest.raises(ValueError, match="or a rig name: scale"):
        rigs.check_name(lab, "spool")
    with pytest.raises(ValueError, match="entries differ"):
        rigs.value(lab, "pretension[*]")
    with pytest.raises(ValueError, match=r"Rig.pretension.*-1"):
        rigs.replace(lab, {"pretension[0]": -1.0})


def test_rig_file_round_trip_and_errors(lab, tmp_path):
    path = tmp_path / "fitted.toml"
    path.write_text(lab.to_toml())
    back = rigs.Rig.from_toml(path)
    for a, b in zip(jax.tree.leaves(lab), jax.tree.leaves(back), strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-15, atol=1e-15)
    text = (DATA / "robot.toml").read_text()
    (tmp_path / "bad.toml").write_text(text.replace("scale = 1.0", "scale = 1.0\nspool = 2"))
    with pytest.raises(ValueError, match=re.escape("bad.toml: [rig] has unknown key(s) ['spool']")):
        rigs.Rig.from_toml(tmp_path / "bad.toml")
    (tmp_path / "bad.toml").write_text(text.replace("scale = 1.0", "scale = -1.0"))
    with pytest.raises(ValueError, match=r"bad.toml: \[rig\]: Rig.scale = -1"):
        rigs.Rig.from_toml(tmp_path / "bad.toml")
    (tmp_path / "bad.toml").write_text(text.replace("stiffness = 204.1", "max_tension = 100.0"))
    with pytest.raises(
        ValueError, match=r"tendon\(s\) 1 \(tendons\[0\]\), 2 \(tendons\[1\]\), 3 \(tendons\[2\]\) have no stiffness"
    ):
        rigs.Rig.from_toml(tmp_path / "bad.toml")


@pytest.fixture(scope="module")
def truth(lab):
    return rigs.replace(lab, TRUTH)


@pytest.mark.slow
def test_calibration_recovers_known_values(lab, truth, servos):
    """Noise-free tips made with known values: every fitted value within 1% of the truth (angles
    and the registration, which may be zero, within 1e-4 rad and 0.01 mm). With 1 mm noise the
    truth lies within 3 standard errors of every estimate."""
    exact = synthesize_recording(truth, servos)
    fit = tdct.calibrate(lab, exact, PARAMS, progress=False)
    for p in PARAMS:
        if p.startswith(("tendons[0].angle", "tendons[4]", "tendons[8]", "rotation")):
            assert abs(fit.values[p] - TRUTH[p]) < 1e-4, p
        elif p.startswith("translation"):
            assert abs(fit.values[p] - TRUTH[p]) < 1e-5, p
        else:
            assert fit.values[p] == pytest.approx(TRUTH[p], rel=0.01), p
    assert fit.after["rmse"] < 1e-6 < fit.before["rmse"]

    noisy = synthesize_recording(truth, servos, noise=1e-3, seed=3)
    fit = tdct.calibrate(lab, noisy, PARAMS, progress=False)
    assert fit.noise == pytest.approx(1e-3, rel=0.35)
    for p in PARAMS:
        assert abs(fit.values[p] - TRUTH[p]) < 3 * fit.std_errors[p], (p, fit.values[p], fit.std_errors[p])


@pytest.mark.slow
def test_cli_calibrates_a_slice_end_to_end(tmp_path, capsys, monkeypatch):
    """``tdct calibrate --dataset`` on the first N samples of each file: the fitted robot file reads
    back, the report's numbers agree with its prediction, and the fit lowers the training error.
    Samples that fail do not stop it: made to fail along the sequence, sample 5 is reached from its
    neighbour after it, and sample 9, failing both ways, is left out and named by its file line."""
    along = rigs.along

    def failing(rig, servos, solver):
        tip, x, codes, profiles = along(rig, servos, solver)
        if np.array_equal(servos, train_servos):
            return tip, x, codes.at[np.array([5, 9])].set(tdct.status.NEWTON_LIMIT), profiles
        if np.array_equal(servos, train_servos[::-1]):
            return tip, x, codes.at[N - 1 - 9].set(tdct.status.NEWTON_LIMIT), profiles
        return tip, x, codes, profiles  # the validation file

    train_servos = read_dataset(DATA / "dataset.toml").train.displacements[:N]
    monkeypatch.setattr(rigs, "along", failing)
    fit_step, guesses = calibrate_rig._fit_step, []

    def losing(x, rig, servos, start, *rest):  # the first trial step loses sample 3 from its last solution
        r, J, unknowns, codes = fit_step(x, rig, servos, start, *rest)
        guesses.append(np.asarray(start))
        return r, J, unknowns, codes.at[3].set(tdct.status.NEWTON_LIMIT) if len(guesses) == 2 else codes

    monkeypatch.setattr(calibrate_rig, "_fit_step", losing)
    for name, keep in (("train.csv", N), ("val.csv", N), ("tendon_pull.csv", 200)):
        lines = (DATA / name).read_text().splitlines()[: keep + 1]
        (tmp_path / name).write_text("\n".join(lines) + "\n")
    # without friction: the fit's side-by-side steps (with friction every step runs along the recording)
    (tmp_path / "robot.toml").write_text(re.sub(r"\nfriction = .*\n", "\n", (DATA / "robot.toml").read_text()))
    shutil.copy(DATA / "dataset.toml", tmp_path)
    out = tmp_path / "out"
    code = cli.main(
        [
            "calibrate",
            "--dataset",
            str(tmp_path / "dataset.toml"),
            "--params",
            ",".join(PARAMS),
            "--out",
            str(out),
            "--max-steps",
            "3",
            "--json",
            "--quiet",
        ]
    )
    report = json.loads(capsys.readouterr().out)
    assert code in (0, 1)  # 1: stopped at --max-steps, its best values kept (the fit's accuracy: the test above)
    fit = report["fit"]
    assert fit["left_out_lines"] == [11]  # sample 9: the file's header is line 1
    # the lost sample was solved again along the recording, at the trial's values, and the trial re-run from there
    assert not np.array_equal(guesses[2][3], guesses[1][3])
    assert fit["after_mm"]["rmse"] < fit["before_mm"]["rmse"] and fit["after_mm"]["n"] == N - 1
    fitted = rigs.Rig.from_toml(out / "fitted.toml")
    assert rigs.value(fitted, "pretension[0-2]") == pytest.approx(fit["values"]["pretension[0-2]"], rel=1e-12)
    data = read_dataset(tmp_path / "dataset.toml")
    again = predict(fitted, data.validation)
    assert again.errors["rmse"] * 1e3 == pytest.approx(report["validation"]["errors_mm"]["rmse"], abs=1e-4)  # mm, 4 decimals
    assert (out / "prediction.png").stat().st_size > 10_000


@pytest.mark.parametrize(
    "edit, words",
    [
        (lambda t: t.replace('"servo_7_mm"]', '"servo_7_mm", "servo_7_mm"]'), "servo_7_mm"),
        (lambda t: t.replace('tip_z = "mm"\n', ""), "tip_z"),
        (lambda t: t.replace('"tip_y", "tip_z"]', '"tip_y"]'), "tip needs 3 columns (x, y, z of the measured tip), got 2"),
    ],
)
def test_cli_bad_dataset_exits_2(tmp_path, capsys, edit, words):
    for name in ("train.csv", "val.csv", "robot.toml", "tendon_pull.csv"):
        shutil.copy(DATA / name, tmp_path)
    (tmp_path / "dataset.toml").write_text(edit((DATA / "dataset.toml").read_text()))
    assert cli.main(["calibrate", "--dataset", str(tmp_path / "dataset.toml"), "--quiet"]) == 2
    assert words in capsys.readouterr().err


def test_cli_refuses_a_servo_reading_beyond_the_tendon_before_any_solve(tmp_path, capsys):
    """A reading typed 1000 times too large (metres read as millimetres) names file, line, column and value."""
    for name in ("val.csv", "robot.toml", "dataset.toml", "tendon_pull.csv"):
        shutil.copy(DATA / name, tmp_path)
    lines = (DATA / "train.csv").read_text().splitlines()
    header, row = lines[0].split(","), lines[4].split(",")
    k = header.index("servo_3_mm")
    row[k] = str(1000 * float(row[k]))
    lines[4] = ",".join(row)
    (tmp_path / "train.csv").write_text("\n".join(lines) + "\n")
    assert cli.main(["calibrate", "--dataset", str(tmp_path / "dataset.toml"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "train.csv:5: column servo_3_mm:" in err and "moves tendon 2 by" in err and "beyond its rest length 60 mm" in err, err


def test_a_sample_solves_by_multiple_shooting_where_the_solver_asks(lab, monkeypatch):
    """``solver.intervals`` > 1 reaches multiple shooting (``roots.root``), with the same tip and unknowns."""
    from tdct_jax import multiple

    calls, root = [], multiple.root
    monkeypatch.setattr(multiple, "root", lambda *args: calls.append(1) or root(*args))
    servo, guess = np.linspace(0.0, 2e-3, lab.robot.n_tendons), np.full(6 + lab.robot.n_tendons, np.nan)
    sample = jax.jit(rigs.solve_sample, static_argnames="solver")
    one = sample(lab, servo, guess, RIG_SOLVER)
    assert not calls
    two = sample(lab, servo, guess, dataclasses.replace(RIG_SOLVER, intervals=2))
    assert calls and int(one[2]) == int(two[2]) == 0
    np.testing.assert_allclose(two[0], one[0], rtol=0, atol=1e-11)
    np.testing.assert_allclose(two[1], one[1], rtol=1e-8, atol=1e-10)
