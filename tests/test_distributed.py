"""``tdct sweep`` over two JAX processes on localhost (jax.distributed as under srun, CPU backend):
both killed with SIGKILL part way, rerun, each process computes only its unfinished chunks, and
the parts gather to the single-process sweep bit for bit."""

import os
import re
import socket

import numpy as np
import pytest
from conftest import kill_when_stalled, start_cli

import tdct_jax as tdct

# 16 points in chunks of 2: each process's 4 chunks hold the same points as the single process's
GRID = {
    "insertion": [0.0, 0.05, 0.1, 0.16],
    "tensions": [[2.0, 0.0, 0.0, 0.0], [4.0, 0.0, 0.0, 1.0], [6.0, 1.0, 0.0, 0.0], [8.0, 0.0, 0.0, 1.0]],
}
SPEC = f"chunk_size = 2\n[solver]\nsteps = 4\n[grid]\ninsertion = {GRID['insertion']}\ntensions = {GRID['tensions']}\n"
OPTIONS = dict(chunk_size=2, solver=tdct.SolverOptions(steps=4), progress=False)
CHUNKS = 4  # per process
STOP = 1  # chunks durable in each process when both are killed
TIMEOUT_S = 300


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def srun(stop: int, spec, out):
    """Starts ``tdct sweep`` as srun would with two tasks (SLURM's variables, a coordinator on localhost),
    with a compilation cache beside ``out`` that the rerun reads."""
    env = dict(os.environ, JAX_PLATFORMS="cpu", JAX_NUM_CPU_DEVICES="1", JAX_COORDINATOR_ADDRESS=f"127.0.0.1:{free_port()}")
    env["TDCT_COMPILE_CACHE"] = str(out.parent / "xla")
    env.pop("XLA_FLAGS", None)
    env.update(SLURM_JOB_ID="1", SLURM_STEP_NODELIST="localhost", SLURM_NTASKS="2", SLURM_STEP_NUM_TASKS="2", SLURM_LOCALID="0")
    return [start_cli(stop, "sweep", spec, "--out", out, "--quiet", env=env | dict(SLURM_PROCID=str(k))) for k in range(2)]


@pytest.mark.slow
def test_a_killed_two_process_sweep_resumes_per_part(tmp_path):
    spec, out = tmp_path / "grid.toml", tmp_path / "grid.npz"
    spec.write_text(SPEC)
    kill_when_stalled(*srun(STOP, spec, out))
    unfinished = ", ".join(f"part {k} (grid.part{k}-of-2.partial: {STOP} of {CHUNKS} chunks)" for k in range(2))
    with pytest.raises(ValueError, match=re.escape(f"2 of 2 parts are missing or unfinished: {unfinished}")):
        tdct.gather(out)

    workers = srun(-1, spec, out)
    try:
        one = tdct.sweep(grid={k: np.asarray(v) for k, v in GRID.items()}, **OPTIONS)  # while the workers compile
        ran = [w.communicate(timeout=TIMEOUT_S) for w in workers]
    finally:
        for w in workers:
            w.kill()
    for k, (w, (stdout, stderr)) in enumerate(zip(workers, ran, strict=True)):
        assert w.returncode == 0, stderr[-3000:]
        assert stdout.split("\n")[-3:] == [str(tmp_path / f"grid.part{k}-of-2.npz"), f"computed {CHUNKS - STOP}", ""]
        assert f"grid.part{k}-of-2.partial: {STOP} of {CHUNKS} chunks done" in stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["grid.part0-of-2.npz", "grid.part1-of-2.npz", "grid.toml", "xla"]
    two = tdct.gather(out)
    assert one.n_failed == 0 and two.shape == one.shape == (4, 4)
    for name in ("tip_position", "tip_rotation", "converged", "iterations", "residual_norm", "base_wrench"):
        np.testing.assert_array_equal(getattr(two, name), getattr(one, name), strict=True)
    for name in GRID:
        np.testing.assert_array_equal(two.inputs[name], one.inputs[name], strict=True)
        np.testing.assert_array_equal(two.axes[name], one.axes[name], strict=True)
