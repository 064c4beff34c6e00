"""A sweep over two JAX processes on localhost (jax.distributed, CPU backend), each writing its
part, gathers to the single-process sweep bit for bit."""

import os
import socket
import subprocess
import sys
import textwrap

import numpy as np

import tdct_jax as tdct

# 8 points in chunks of 2: each process's chunks hold the same points as the single process's
GRID = {"insertion": [0.0, 0.05, 0.1, 0.16], "tensions": [[2.0, 0.0, 0.0, 0.0], [8.0, 0.0, 0.0, 1.0]]}
OPTIONS_TEXT = "dict(chunk_size=2, solver=tdct.SolverOptions(steps=4), progress=False)"
OPTIONS = eval(OPTIONS_TEXT)
TIMEOUT_S = 300
WORKER = (
    textwrap.dedent(
        """
    import sys, jax
    address, k, out = sys.argv[1], int(sys.argv[2]), sys.argv[3]
    jax.distributed.initialize(coordinator_address=address, num_processes=2, process_id=k, initialization_timeout=120)
    import numpy as np, tdct_jax as tdct
    grid = {name: np.asarray(v) for name, v in GRID.items()}
    print(tdct.sweep(grid=grid, out=out, **OPTIONS))
    """
    )
    .replace("GRID", repr(GRID))
    .replace("OPTIONS", OPTIONS_TEXT)
)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_two_process_sweep_gathers_to_the_single_process_sweep(tmp_path):
    address, out = f"127.0.0.1:{free_port()}", tmp_path / "grid.npz"
    env = dict(os.environ, JAX_PLATFORMS="cpu")
    env.pop("XLA_FLAGS", None)
    workers = [
        subprocess.Popen(
            [sys.executable, "-c", WORKER, address, str(k), str(out)],
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        for k in range(2)
    ]
    try:
        one = tdct.sweep(grid={k: np.asarray(v) for k, v in GRID.items()}, **OPTIONS)  # while the workers compile
        ran = [w.communicate(timeout=TIMEOUT_S) for w in workers]
    finally:
        for w in workers:
            w.kill()
    for k, (w, (stdout, stderr)) in enumerate(zip(workers, ran, strict=True)):
        assert w.returncode == 0, stderr[-3000:]
        assert stdout.split()[-1] == str(tmp_path / f"grid.part{k}-of-2.npz")
    two = tdct.gather(out)
    assert one.n_failed == 0 and two.shape == one.shape == (4, 2)
    for name in ("tip_position", "tip_rotation", "converged", "iterations", "residual_norm", "base_wrench"):
        np.testing.assert_array_equal(getattr(two, name), getattr(one, name), strict=True)
    for name in GRID:
        np.testing.assert_array_equal(two.inputs[name], one.inputs[name], strict=True)
        np.testing.assert_array_equal(two.axes[name], one.axes[name], strict=True)
