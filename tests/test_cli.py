"""The tdct command line: output matches the API, bad input exits 2, files are written."""

import importlib
import json
import os
import subprocess
import sys
import textwrap

import jax
import numpy as np
import pytest

import tdct_jax as tdct
from tdct_jax.cli import main


def test_json_output_matches_the_api(capsys, paper_case):
    _, _, _, sol = paper_case
    code = main(["solve", "--tensions", "6,0,0,0", "--insertion-mm", "80", "--tip-mass-g", "20", "--json"])
    assert code == 0
    out = json.loads(capsys.readouterr().out)
    np.testing.assert_allclose(out["tip_position_mm"], np.asarray(sol.tip_position) * 1e3, rtol=1e-12)
    np.testing.assert_allclose(out["tip_angle_deg"], np.degrees(float(sol.tip_angle)), rtol=1e-12)
    assert out["converged"] is True and out["iterations"] == int(sol.iterations)
    # one row per arc length: the two intervals' 2 x 21 nodes less the node repeated at the insertion
    assert len(out["shape"]["s_mm"]) == len(out["shape"]["position_mm"]) == 2 * (tdct.SolverOptions().steps + 1) - 1
    np.testing.assert_allclose(out["shape"]["position_mm"][-1], np.asarray(sol.tip_position) * 1e3, rtol=1e-12)


def test_human_output_csv_and_plot(tmp_path, capsys):
    csv, png = tmp_path / "shape.csv", tmp_path / "shape.png"
    code = main(
        ["solve", "--tensions", "6,0,0,0", "--insertion-mm", "80", "--tip-mass-g", "20", "--csv", str(csv), "--plot", str(png)]
    )
    assert code == 0
    text = capsys.readouterr().out
    assert "tip position [mm]" in text and "tip angle [deg]" in text and "converged:         yes" in text
    table = np.loadtxt(csv, delimiter=",", skiprows=1)
    assert table.shape[1] == 4 and table[-1, 3] > 100
    assert png.stat().st_size > 10_000


def test_bad_input_exits_2_with_the_reason(capsys, tmp_path):
    assert main(["solve", "--tensions=-1,0,0,0"]) == 2
    assert "tensions" in capsys.readouterr().err
    assert main(["solve", "--insertion-mm", "200"]) == 2
    assert "--insertion-mm 200 is outside the allowed range [0, 160] mm" in capsys.readouterr().err
    bad = tmp_path / "robot.toml"
    bad.write_text("E_silicone = -3.0\n")
    assert main(["solve", "--robot", str(bad)]) == 2
    assert "E_silicone" in capsys.readouterr().err


def test_robot_file_changes_the_answer(tmp_path, capsys, paper_case):
    stiff = tmp_path / "stiff.toml"
    stiff.write_text("[robot]\nE_silicone = 1.7e6\n")
    assert (
        main(["solve", "--tensions", "6,0,0,0", "--insertion-mm", "80", "--tip-mass-g", "20", "--json", "--robot", str(stiff)])
        == 0
    )
    out = json.loads(capsys.readouterr().out)
    ref = tdct.solve(tdct.Robot.paper(E_silicone=1.7e6), paper_case[1], paper_case[2])
    np.testing.assert_allclose(out["tip_position_mm"], np.asarray(ref.tip_position) * 1e3, rtol=1e-12)


def test_compliance_verb_matches_the_api(capsys, tmp_path, robot):
    png = tmp_path / "ellipse.png"
    args = [
        "compliance",
        "--tensions",
        "8,0,0,0",
        "--insertion-mm",
        "50",
        "--tip-force=0.05,-0.3,0.02",
        "--json",
        "--plot",
        str(png),
    ]
    assert main(args) == 0
    out = json.loads(capsys.readouterr().out)
    act, load = tdct.Actuation((8.0, 0, 0, 0), 0.05), tdct.Loads(tip_force=(0.05, -0.3, 0.02))
    CM = np.asarray(tdct.compliance(robot, act, load))
    np.testing.assert_allclose(out["compliance_mm_per_N"], CM * 1e3, rtol=1e-12)
    np.testing.assert_allclose(out["semi_axes_mm_per_N"], np.linalg.svd(CM, compute_uv=False) * 1e3, rtol=1e-10)
    assert png.stat().st_size > 10_000
    assert main(["compliance", "--tensions", "8,0,0,0", "--insertion-mm", "50", "--steps", "0"]) == 2
    assert "steps" in capsys.readouterr().err


def test_cli_compile_cache_is_on_by_default_and_sweeps_get_every_core(tmp_path, monkeypatch):
    session = jax.config.jax_compilation_cache_dir  # conftest's: one cache for the test session
    monkeypatch.setenv("TDCT_COMPILE_CACHE", str(tmp_path / "unused"))
    assert main(["solve", "--no-compile-cache", "--insertion-mm", "200"]) == 2
    assert jax.config.jax_compilation_cache_dir == session and not (tmp_path / "unused").exists()
    script = textwrap.dedent(
        """
        import jax
        from tdct_jax.cli import main
        assert main(["solve", "--insertion-mm", "200"]) == 2
        print(jax.config.jax_compilation_cache_dir)
        jax.jit(lambda x: x + 1.0)(1.0)  # a tiny, fast compile: cached too
        print(jax.device_count())
        """
    )
    env = {
        k: v for k, v in os.environ.items() if k not in ("TDCT_COMPILE_CACHE", "JAX_NUM_CPU_DEVICES", "JAX_COMPILATION_CACHE_DIR")
    }
    run = subprocess.run(
        [sys.executable, "-c", script], env=dict(env, XDG_CACHE_HOME=str(tmp_path)), capture_output=True, text=True, timeout=120
    )
    assert run.returncode == 0, run.stderr[-3000:]
    cache = tmp_path / "tdct_jax" / "xla"
    assert run.stdout.split() == [str(cache), str(os.cpu_count())]  # one CPU device per core
    assert any(cache.iterdir())


@pytest.mark.parametrize(
    "argv, words",
    [
        (["solve", "--tensions", "-5,0,0,0"], "--tensions -5,0,0,0 (value 1: -5) is outside the allowed range [0, inf] N"),
        (["solve", "--tip-force", "-0.15,0,0", "--tensions", "1,0,0"], "--tensions 1,0,0 has 3 values: the robot has 4 tendons"),
        (["solve", "--insertion-mm", "200"], "--insertion-mm 200 is outside the allowed range [0, 160] mm"),
        (["solve", "--insertion-mm", "-1e-3"], "--insertion-mm -0.001 is outside the allowed range [0, 160] mm"),
        (["solve", "--tip-mass-g", "-3"], "--tip-mass-g -3 is outside the allowed range [0, inf] g"),
        (["compliance", "--max-iter", "0"], "--max-iter 0 is outside the allowed range [1, inf]"),
        (["solve", "--set", "sections[*].E=-3"], "--set: sections[0].E = -3 is outside the allowed range (0, inf] Pa"),
        (["solve", "--set", "E_silicone=-3"], "--set: sections[0].E = -3 is outside the allowed range (0, inf]"),
        (["synth", "--out", "x", "--tensions", "2,-1,0,0"], "--tensions 2,-1,0,0 (value 2: -1) is outside"),
        (
            ["synth", "--out", "x", "--preset", "paper", "--noise-mm", "-0.1"],
            "--noise-mm -0.1 is outside the allowed range [0, inf] mm",
        ),
        (["calibrate", "nofile.csv", "--max-steps", "0"], "--max-steps 0 is outside the allowed range [1, inf]"),
        (["solve", "--tensions", "nan,0,0,0"], "argument --tensions: expected finite numbers"),
    ],
)
def test_bad_flags_exit_2_in_the_units_typed_without_a_traceback(argv, words, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert words in err and "Traceback" not in err


def test_negative_values_are_read_as_typed(capsys, robot):
    args = ["solve", "--tensions", "6,0,0,0", "--tip-force", "-0.15,0,-0.05", "--tip-moment", "-1e-3,0,0", "--json"]
    assert main(args) == 0
    out = json.loads(capsys.readouterr().out)
    load = tdct.Loads(tip_force=(-0.15, 0.0, -0.05), tip_moment=(-1e-3, 0.0, 0.0))
    ref = tdct.solve(robot, tdct.Actuation((6.0, 0, 0, 0)), load)
    np.testing.assert_allclose(out["tip_position_mm"], np.asarray(ref.tip_position) * 1e3, rtol=1e-12)


@pytest.mark.parametrize(
    "argv, where",
    [
        (["solve", "--plot", "nodir/shape.png"], "--plot nodir/shape.png: the folder nodir does not exist"),
        (["solve", "--csv", "/proc/x.csv"], "--csv /proc/x.csv: cannot write a file in /proc"),
        (["compliance", "--plot", "."], "--plot .: is a folder"),
        (["synth", "--preset", "paper", "--out", "/proc/x"], "--out /proc/x: cannot write a file in /proc"),
        (["reproduce", "--quick", "--out", "/proc/x"], "--out /proc/x: cannot write a file in /proc"),
        (["calibrate", "shapes", "--plot", "nodir/fit.png"], "--plot nodir/fit.png: the folder nodir does not exist"),
        (["solve", "--plot", "shape.xyz"], "--plot shape.xyz: .xyz is not an image format matplotlib writes; allowed: none, "),
        (["calibrate", "shapes", "--plot", "fit.xyz"], "--plot fit.xyz: .xyz is not an image format matplotlib writes"),
        (["sweep", "spec.toml", "--out", "s.csv"], "--out s.csv: .csv is not a sweep's file format (for a CSV: tdct.gather"),
        (["sweep", "spec.toml", "--out", "/proc/s.npz"], "--out /proc/s.npz: cannot write a file in /proc"),
    ],
)
def test_unwritable_outputs_exit_2_before_any_computation(argv, where, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    computed = []
    for name in ("solve", "compliance_and_solution", "calibrate", "synthesize", "reproduce", "sweep"):
        for module in ("tdct_jax.cli", "tdct_jax.calibrate", "tdct_jax.reproduce", "tdct_jax.sweep"):
            if hasattr(importlib.import_module(module), name):
                monkeypatch.setattr(importlib.import_module(module), name, lambda *a, name=name, **k: computed.append(name))
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert where in err and "Traceback" not in err
    assert computed == []  # nothing was solved, fitted or synthesized


def test_max_iter_reaches_the_solve_and_its_message(capsys):
    assert main(["solve", "--tensions", "6,0,0,0", "--insertion-mm", "80", "--max-iter", "1"]) == 1
    err = capsys.readouterr().err
    assert "Newton used its limit of max_iter = 1 steps per load stage" in err and "--max-iter" in err
    assert "Traceback" not in err


def test_inputs_beyond_the_calibrated_range_get_a_note(capsys):
    assert main(["solve", "--tensions", "20,0,0,0", "--no-gravity"]) == 0
    err = capsys.readouterr().err
    assert "tdct: note: tensions up to 20 N are outside the range [0, 10] N this robot was calibrated over" in err


def test_version(capsys):
    assert main(["--version"]) == 0
    assert capsys.readouterr().out.strip() == f"tdct {tdct.__version__}"


def test_values_typed_in_another_unit_get_a_note(capsys, tmp_path):
    long = tmp_path / "long.toml"
    long.write_text("length = 160\n")
    assert main(["solve", "--robot", str(long), "--tip-mass-g", "-1"]) == 2  # a bad flag stops it before solving
    err = capsys.readouterr().err
    assert (
        f"tdct: note: robot file {long}: length = 160 m is far outside the plausible range [0.005, 5] m: did you mean 160 millimetres (0.16 m)?"
        in err
    )
    assert err.count("tdct: note:") == 1 and "tdct: error: --tip-mass-g -1" in err
