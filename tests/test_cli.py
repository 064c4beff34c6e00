"""The tdct command line: output matches the API, bad input exits 2, files are written."""

import json
import os
import subprocess
import sys
import textwrap

import jax
import numpy as np

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
    assert len(out["shape"]["s_mm"]) == len(out["shape"]["position_mm"]) == len(sol.s)


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
    assert "insertion = 0.2 is outside the allowed range [0, 0.16]" in capsys.readouterr().err
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
    ref = tdct.solve(tdct.Robot(E_silicone=1.7e6), paper_case[1], paper_case[2])
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
    act, load = tdct.Actuation((8.0, 0, 0, 0), 0.05), tdct.TipLoad(force=(0.05, -0.3, 0.02))
    CM = np.asarray(tdct.compliance(robot, act, load))
    np.testing.assert_allclose(out["compliance_mm_per_N"], CM * 1e3, rtol=1e-12)
    np.testing.assert_allclose(out["semi_axes_mm_per_N"], np.linalg.svd(CM, compute_uv=False) * 1e3, rtol=1e-10)
    assert png.stat().st_size > 10_000
    assert main(["compliance", "--tensions", "8,0,0,0", "--insertion-mm", "50", "--steps", "0"]) == 2
    assert "steps" in capsys.readouterr().err


def test_cli_compile_cache_is_on_by_default_and_off_in_tests_and_sweeps_get_every_core(tmp_path, monkeypatch):
    assert main(["solve", "--insertion-mm", "200"]) == 2  # the cache is set up before the input is read
    assert jax.config.jax_compilation_cache_dir is None  # conftest's TDCT_COMPILE_CACHE=0
    monkeypatch.setenv("TDCT_COMPILE_CACHE", str(tmp_path / "unused"))
    assert main(["solve", "--no-compile-cache", "--insertion-mm", "200"]) == 2
    assert jax.config.jax_compilation_cache_dir is None
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
    env = {k: v for k, v in os.environ.items() if k not in ("TDCT_COMPILE_CACHE", "JAX_NUM_CPU_DEVICES")}
    run = subprocess.run(
        [sys.executable, "-c", script], env=dict(env, XDG_CACHE_HOME=str(tmp_path)), capture_output=True, text=True, timeout=120
    )
    assert run.returncode == 0, run.stderr[-3000:]
    cache = tmp_path / "tdct_jax" / "xla"
    assert run.stdout.split() == [str(cache), str(os.cpu_count())]  # one CPU device per core
    assert any(cache.iterdir())
