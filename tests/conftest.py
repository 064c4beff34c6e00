import gc
import os
import signal
import subprocess
import sys
import tempfile
import threading
from pathlib import Path

import jax
import numpy as np
import pytest

import tdct_jax as tdct
from tdct_jax.cli import enable_compile_cache

# One compilation cache for the whole test session, fresh each session: a program compiled once (a
# solver configuration, an IK plan) is loaded, not compiled again, by the other pytest workers and
# by the subprocesses the tests start (CLI runs, the notebook's kernel), which inherit these.
SESSION_CACHE = os.environ.setdefault("TDCT_TEST_XLA_CACHE", tempfile.mkdtemp(prefix="tdct-test-xla-"))
os.environ["TDCT_COMPILE_CACHE"] = SESSION_CACHE
os.environ["JAX_COMPILATION_CACHE_DIR"] = SESSION_CACHE
os.environ["JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"] = "0"
os.environ["JAX_PERSISTENT_CACHE_MIN_ENTRY_SIZE_BYTES"] = "-1"
enable_compile_cache(SESSION_CACHE)
jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_rank_promotion", "raise")

NO_GRAVITY = None
MAX_MAPS = 30_000
"""Memory maps a test process may hold before it drops its compiled programs. Every program XLA:CPU
compiles keeps a few hundred maps while it is cached; a worker that compiles a hundred programs
reaches Linux's default limit of 65,530 (vm.max_map_count), and the next compile aborts the process
("Fatal Python error: Aborted" in the compilation cache's write). Dropped programs come back from
the session's compilation cache, not from a new compile; no single test compiles enough to go from
this limit to Linux's."""


@pytest.fixture(autouse=True)
def _drop_compiled_programs_when_maps_run_high():
    yield
    maps = Path("/proc/self/maps")
    if maps.exists() and maps.read_bytes().count(b"\n") > MAX_MAPS:
        jax.clear_caches()
        gc.collect()


def rel_err(a, b):
    """Largest relative deviation of a from the reference b."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    return float(np.max(np.abs(a - b)) / np.max(np.abs(b)))


@pytest.fixture(scope="session")
def robot():
    return tdct.Robot()


HEIGHT, MASS = 0.03, 0.02
"""A tip height [m] reached with tendon 1 and the tube, holding a tip mass [kg]: the IK guide's and
the notebook's redundancy example."""


@pytest.fixture(scope="session")
def stiffest(robot):
    """The stiffest way along -y to hold the tip at HEIGHT with MASS, tendon 1 and the tube (session
    scope: its program takes tens of seconds to compile, and module fixtures are rebuilt whenever a
    worker comes back to their module)."""
    target = tdct.Target((0.0, HEIGHT, 0.0), axes="y")
    options = dict(load=tdct.TipLoad.from_mass(MASS), tendons=(1,), objective=tdct.Stiffness(direction=(0.0, -1.0, 0.0)))
    return tdct.inverse_kinematics(robot, target, **options)


@pytest.fixture(scope="session")
def paper_case(robot):
    """The paper's Fig. 6 setting: 6 N on tendon 1, 80 mm of tube, 20 g at the tip."""
    act = tdct.Actuation(tensions=(6.0, 0.0, 0.0, 0.0), insertion=0.08)
    load = tdct.TipLoad.from_mass(0.020)
    return robot, act, load, tdct.solve(robot, act, load, throw=True)


STOPPING_CLI = """
import importlib, sys, time
from tdct_jax.cli import main

sweep_module = importlib.import_module("tdct_jax.sweep")

stop, real, computed = int(sys.argv[1]), sweep_module.iter_batched, []

def stopping(*args, **kwargs):
    for i, chunk in enumerate(real(*args, **kwargs)):
        if i == stop:
            print("stalled", flush=True)
            time.sleep(600)
        computed.append(chunk[0])
        yield chunk

sweep_module.iter_batched = stopping
code = main(sys.argv[2:])
print("computed", len(computed))
sys.exit(code)
"""
"""``python -c STOPPING_CLI STOP ARGS...`` runs ``tdct ARGS...``; its sweep stalls for good once STOP
chunks are durable (printing "stalled"), or with STOP -1 runs to the end and prints "computed N",
the chunks it computed."""


def start_cli(stop: int, *args, env=None) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-c", STOPPING_CLI, str(stop), *map(str, args)],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def kill_when_stalled(*runs: subprocess.Popen, timeout_s: float = 300) -> None:
    """Waits until each run has stalled (killing them all after ``timeout_s``), then kills them with SIGKILL."""
    timer = threading.Timer(timeout_s, lambda: [run.kill() for run in runs])
    timer.start()
    try:
        for run in runs:
            line = run.stdout.readline()
            assert line.strip() == "stalled", run.stderr.read()[-3000:]
    finally:
        timer.cancel()
        for run in runs:
            run.send_signal(signal.SIGKILL)
            run.communicate()
    assert all(run.returncode == -signal.SIGKILL for run in runs)
