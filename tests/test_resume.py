"""Sweeps that survive being stopped: a sweep killed with SIGKILL resumes from its finished chunks
(counted) to a file equal byte for byte to an uninterrupted run's; a changed sweep is refused,
naming the change; ``tdct sweep SPEC.toml`` equals the Python call; bad specs exit 2."""

import importlib
import os
import re
import sys

import jax
import numpy as np
import pytest
from conftest import kill_when_stalled, start_cli

import tdct_jax as tdct
from tdct_jax import checkpoint
from tdct_jax.cli import main

sweep_module = importlib.import_module("tdct_jax.sweep")  # the module: tdct_jax.sweep is the function

ROBOT = tdct.Robot.paper(E_silicone=0.9e6)
SOLVER = tdct.SolverOptions(steps=4)
BASE = tdct.Actuation((0.0, 0.0, 0.0, 2.0), 0.0)
# 9 points in chunks of 2: 5 chunks, the last padded
GRID = {
    "insertion": np.linspace(0.0, 0.16, 3),
    "tensions": np.outer(np.linspace(0.0, 6.0, 3), [1.0, 0.0, 0.0, 0.0]) + BASE.tensions,
}
OPTIONS = dict(grid=GRID, chunk_size=2, solver=SOLVER, progress=False)
CHUNKS = 5
STOP = 2  # chunks durable when the first run is killed
SPEC = """
robot = "robot.toml"
chunk_size = 2
[solver]
steps = 4
[base]
tensions = [0.0, 0.0, 0.0, 2.0]
[grid]
insertion = {linspace = [0.0, 0.16, 3]}
tensions = {linspace = [0.0, 6.0, 3], tendons = [1]}
"""
"""The grid of OPTIONS as a ``tdct sweep`` spec."""


@pytest.fixture
def spec(tmp_path):
    (tmp_path / "robot.toml").write_text("[robot]\nE_silicone = 0.9e6\n")
    (tmp_path / "grid.toml").write_text(SPEC)
    return tmp_path / "grid.toml"


def counting(monkeypatch) -> list:
    """Counts the chunks the batch engine computes for sweeps in this process."""
    computed, real = [], sweep_module.iter_batched

    def counted(*args, **kwargs):
        for chunk in real(*args, **kwargs):
            computed.append(chunk[0])
            yield chunk

    monkeypatch.setattr(sweep_module, "iter_batched", counted)
    return computed


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory):
    return tdct.sweep(ROBOT, BASE, out=tmp_path_factory.mktemp("whole") / "grid.npz", **OPTIONS)


def test_a_killed_sweep_resumes_where_it_stopped(spec, tmp_path, monkeypatch, capfd, uninterrupted):
    """``tdct sweep`` killed with SIGKILL once STOP chunks are durable; the same sweep from Python
    computes only the others and writes the uninterrupted run's file."""
    out = tmp_path / "grid.npz"
    env = dict(os.environ, JAX_NUM_CPU_DEVICES=str(jax.local_device_count()))  # the devices are in the fingerprint
    kill_when_stalled(start_cli(STOP, "sweep", spec, "--out", out, "--quiet", env=env))
    partial = tmp_path / "grid.partial"
    assert not out.exists() and sorted(p.name for p in partial.iterdir()) == [
        *(f"chunk-{i:06d}.npz" for i in range(STOP)),
        "manifest.json",
    ]
    with pytest.raises(ValueError, match=f"its partial folder grid.partial holds {STOP} of {CHUNKS} chunks"):
        tdct.gather(out)

    computed = counting(monkeypatch)
    assert tdct.sweep(ROBOT, BASE, out=out, **OPTIONS | dict(progress=True)) == out
    assert len(computed) == CHUNKS - STOP  # only the chunks not on disk
    err = capfd.readouterr().err
    assert f"resuming from {partial}: {STOP} of {CHUNKS} chunks done" in err
    assert f"| {2 * STOP}/9 [" in err.split("\r")[1]  # the progress bar starts at the points done
    assert re.search(r"\n9 points, 0 failed, [\d.]+ s\n$", err), err[-300:]  # the sweep's last line
    assert sorted(p.name for p in tmp_path.iterdir()) == ["grid.npz", "grid.toml", "robot.toml"]  # the partial folder is gone
    assert out.read_bytes() == uninterrupted.read_bytes()


def interrupt_after_first_chunk(out, **arguments) -> None:
    """Runs a sweep that Ctrl-C stops after its first chunk."""
    real = sweep_module.iter_batched

    def interrupt(*args, **kwargs):
        for i, chunk in enumerate(real(*args, **kwargs)):
            if i == 1:
                raise KeyboardInterrupt
            yield chunk

    with pytest.MonkeyPatch.context() as m:
        m.setattr(sweep_module, "iter_batched", interrupt)
        with pytest.raises(KeyboardInterrupt):
            tdct.sweep(ROBOT, BASE, out=out, **OPTIONS | arguments)


@pytest.fixture(scope="module")
def interrupted(tmp_path_factory):
    """The partial folder a sweep stopped by Ctrl-C leaves."""
    out = tmp_path_factory.mktemp("interrupted") / "grid.npz"
    interrupt_after_first_chunk(out)
    return out


@pytest.mark.parametrize(
    "change, message",
    [
        (dict(grid={**GRID, "insertion": np.array([0.0, 0.08, 0.15])}), "grid axis insertion: values differ"),
        (dict(grid={**GRID, "insertion": np.array([0.0, 0.16])}), "grid axis insertion: shape (3,) then (2,)"),
        (dict(robot=tdct.Robot.paper()), "robot.sections[0].E: 900000.0 then 850000.0"),
        (dict(solver=tdct.SolverOptions(steps=4, tol=1e-12)), "solver.tol: 1e-10 then 1e-12"),
        (dict(chunk_size=4), "chunk_size: 2 then 4"),
        (dict(act=tdct.Actuation((1.0, 0.0, 0.0, 2.0))), "act.tensions: [0.0, 0.0, 0.0, 2.0] then [1.0, 0.0, 0.0, 2.0]"),
        (dict(gravity=None), "gravity: [0.0, -9.81, 0.0] then [0.0, 0.0, 0.0]"),
    ],
)
def test_a_changed_sweep_is_refused_naming_the_change(interrupted, change, message):
    arguments = dict(robot=ROBOT, act=BASE) | OPTIONS | change
    with pytest.raises(ValueError) as e:
        tdct.sweep(out=interrupted, **arguments)
    assert message in str(e.value) and "overwrite=True" in str(e.value)
    assert (interrupted.parent / "grid.partial" / "chunk-000000.npz").exists()  # nothing discarded


def test_overwrite_starts_afresh(tmp_path, monkeypatch):
    out = tmp_path / "grid.npz"
    partial = tmp_path / "grid.partial"
    partial.mkdir()
    (partial / "manifest.json").write_text('{"output": "grid.npz", "chunks": 1, "fingerprint": {"chunk_size": 64}}')
    with pytest.raises(ValueError, match="chunk_size: 64 then 2"):
        tdct.sweep(ROBOT, BASE, out=out, **OPTIONS)
    computed = counting(monkeypatch)
    tdct.sweep(ROBOT, BASE, out=out, overwrite=True, **OPTIONS)
    assert len(computed) == CHUNKS and not partial.exists()


def test_a_sweep_stopped_while_joining_its_chunks_computes_nothing(tmp_path, monkeypatch, uninterrupted):
    out = tmp_path / "grid.npz"
    with monkeypatch.context() as m:
        m.setattr(checkpoint.Partial, "finish", lambda *args: sys.exit("stopped"))
        with pytest.raises(SystemExit):
            tdct.sweep(ROBOT, BASE, out=out, **OPTIONS)
    assert checkpoint.progress(tmp_path / "grid.partial") == (CHUNKS, CHUNKS) and not out.exists()
    computed = counting(monkeypatch)
    tdct.sweep(ROBOT, BASE, out=out, **OPTIONS)
    assert computed == [] and out.read_bytes() == uninterrupted.read_bytes()


def test_sweep_command_writes_the_python_calls_file(spec, tmp_path, capsys, uninterrupted, monkeypatch):
    out = tmp_path / "cli.npz"
    assert main(["sweep", str(spec), "--out", str(out), "--quiet"]) == 0
    assert capsys.readouterr().out.strip() == str(out)
    assert out.read_bytes() == uninterrupted.read_bytes()

    computed = counting(monkeypatch)  # run again: complete, nothing computed
    assert main(["sweep", str(spec), "--out", str(out)]) == 0
    captured = capsys.readouterr()
    assert computed == [] and captured.out.strip() == str(out) and out.read_bytes() == uninterrupted.read_bytes()
    assert f"9 points, 0 failed: {out} was complete already, nothing computed" in captured.err and "--overwrite" in captured.err
    spec.write_text(SPEC.replace("steps = 4", "steps = 5"))  # another sweep: refused, naming the change
    assert main(["sweep", str(spec), "--out", str(out), "--quiet"]) == 2
    assert f"{out} holds a different, finished sweep (solver.steps: 4 then 5)" in capsys.readouterr().err
    assert computed == []
    spec.write_text(SPEC)
    assert main(["sweep", str(spec), "--out", str(out), "--quiet", "--overwrite"]) == 0  # recomputed
    assert len(computed) == CHUNKS and out.read_bytes() == uninterrupted.read_bytes()


def test_an_interrupted_sweep_command_says_a_rerun_resumes(spec, tmp_path, capsys, monkeypatch):
    real = sweep_module.iter_batched

    def interrupt(*args, **kwargs):
        yield next(real(*args, **kwargs))
        raise KeyboardInterrupt

    monkeypatch.setattr(sweep_module, "iter_batched", interrupt)
    assert main(["sweep", str(spec), "--out", str(tmp_path / "grid.npz"), "--quiet"]) == 130
    err = capsys.readouterr().err
    assert "tdct: interrupted; the finished chunks are kept: rerunning the same command resumes from them" in err


@pytest.mark.parametrize(
    "edit, message",
    [
        (("chunk_size = 2", "chunk_size = 0"), "chunk_size = 0 must be an integer >= 1"),
        (("[0.0, 0.16, 3]", "[0.0, 0.2, 3]"), "grid.toml: [grid] insertion[2] = 0.2 is outside the allowed range [0, 0.16] m"),
        (("insertion = {linspace = [0.0, 0.16, 3]}", "insertion = []"), "grid.toml: [grid] insertion: no values"),
        (
            (("chunk_size = 2", "chunk_size = 2\nwarm_start = true"), ("[grid]", "[batch]")),
            "grid.toml: warm_start = true needs a [grid] table",
        ),
        (("[0.0, 0.16, 3]", "[0.0, 0.16, 0]"), "grid.insertion.linspace count = 0 must be an integer >= 1"),
        (
            ("tendons = [1]", "tendons = [5]"),
            "grid.tensions.tendons = [5] must list the entries the linspace sets, from [1, 2, 3, 4]",
        ),
        (("steps = 4", "steps = 4\ntol = -1.0"), "[solver] tol = -1 is outside the allowed range (0, inf]"),
        (("steps = 4", "stepz = 4"), "[solver] unknown key(s) ['stepz']"),
        (("[grid]", "[grids]"), "unknown key(s) ['grids']"),
        (
            ('robot = "robot.toml"', 'robot = "robot.toml"\ngravity = "on"'),
            "gravity = 'on' must be true (standard, -y), false (none) or [gx, gy, gz]",
        ),
        (
            ("[0.0, 0.0, 0.0, 2.0]", "[0.0, 0.0, 0.0, -2.0]"),
            "[base] tensions = [ 0.,  0.,  0., -2.] is outside the allowed range [0, inf] N",
        ),
        (("insertion = {", "insertion = {step = 1, "), "grid.insertion: unknown key(s) ['step']"),
        (('robot = "robot.toml"', 'robot = "missing.toml"'), "cannot read robot file"),
        (("[grid]", "[batch]\ninsertion = [0.0]\n[grid]"), "found both"),
    ],
)
def test_a_bad_spec_exits_2_naming_key_value_and_range(spec, tmp_path, capsys, edit, message):
    text = SPEC
    for old, new in edit if isinstance(edit[0], tuple) else [edit]:
        text = text.replace(old, new)
    spec.write_text(text)
    assert main(["sweep", str(spec), "--out", str(tmp_path / "x.npz"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("tdct: error: ") and err.count("\n") == 1 and message in err, err
    assert not (tmp_path / "x.partial").exists()


@pytest.mark.slow
def test_failures_in_finished_chunks_raise_after_the_resume(tmp_path):
    """throw=True counts the failed points of the chunks an earlier run finished too."""
    options = dict(solver=tdct.SolverOptions(steps=4, max_iter=1))
    whole = tdct.sweep(ROBOT, BASE, **OPTIONS | options, throw=False)
    first = int(np.flatnonzero(~whole.converged.ravel())[0])
    assert first < 2  # a point of the first chunk fails
    interrupt_after_first_chunk(tmp_path / "grid.npz", **options)
    with pytest.raises(tdct.ConvergenceError, match=rf"point {first} \(of 9; {whole.n_failed} failed, throw=False") as e:
        tdct.sweep(ROBOT, BASE, out=tmp_path / "grid.npz", **OPTIONS | options)
    assert f"{tmp_path / 'grid.npz'} was still written with every point's result code" in str(e.value)
    assert "their result codes are kept" in e.value.cli_message and "Raise --max-iter" in e.value.cli_message
    np.testing.assert_array_equal(tdct.gather(tmp_path / "grid.npz").result, whole.result, strict=True)
