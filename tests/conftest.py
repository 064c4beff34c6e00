import gc
import json
import os
import signal
import subprocess
import sys
import tempfile
import threading
from pathlib import Path
from typing import NamedTuple

import jax
import jax.monitoring
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


LOG = os.environ.get("TDCT_COMPILE_LOG")
"""A file to which each real compile appends a line: the test, the jitted function's name, seconds."""


class CompileCounter:
    """The XLA programs this process builds, split into real compiles and loads from the session's
    compilation cache (a program another worker compiled first), with the test that asked for each.
    JAX times every build under "/jax/core/compile/backend_compile_duration" and, for a load, records
    "/jax/compilation_cache/cache_hits" inside that timed span; programs found in a process's own
    in-memory caches record neither. Subprocesses (CLI runs, the notebook's kernel) are not counted."""

    BUILD = "/jax/core/compile/backend_compile_duration"
    HIT = "/jax/compilation_cache/cache_hits"

    def __init__(self):
        self.test = "(outside tests)"
        self.per_test: dict[str, list] = {}  # nodeid -> [compiles, compile seconds]
        self.hits = 0
        self._hit = False

    def on_event(self, event, **_):
        if event == self.HIT:
            self._hit = True

    def on_duration(self, event, seconds, fun_name="?", **_):
        if event != self.BUILD:
            return
        if self._hit:
            self.hits, self._hit = self.hits + 1, False
        else:
            entry = self.per_test.setdefault(self.test, [0, 0.0])
            entry[0], entry[1] = entry[0] + 1, entry[1] + seconds
            if LOG:
                with open(LOG, "a") as log:
                    log.write(f"{self.test}\t{fun_name}\t{seconds:.2f}\n")

    def report(self) -> dict:
        return {"hits": self.hits, "per_test": self.per_test}


COMPILES = CompileCounter()
jax.monitoring.register_event_listener(COMPILES.on_event)
jax.monitoring.register_event_duration_secs_listener(COMPILES.on_duration)
WORKER_REPORTS: list[dict] = []  # the controller's copy of each xdist worker's COMPILES.report()


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item):
    COMPILES.test = item.nodeid  # fixtures set up for this test are charged to it
    yield
    COMPILES.test = "(outside tests)"


@pytest.hookimpl(optionalhook=True)
def pytest_testnodedown(node, error):
    if "compiles" in getattr(node, "workeroutput", {}):
        WORKER_REPORTS.append(json.loads(node.workeroutput["compiles"]))


def compile_totals() -> tuple[int, int, float, list]:
    """(compiles, cache loads, compile seconds, [(compiles, seconds, nodeid)], most seconds first) over
    this process and every worker that reported."""
    hits, per_test = 0, {}
    for report in [COMPILES.report(), *WORKER_REPORTS]:
        hits += report["hits"]
        for test, (n, seconds) in report["per_test"].items():
            entry = per_test.setdefault(test, [0, 0.0])
            entry[0], entry[1] = entry[0] + n, entry[1] + seconds
    ranked = sorted(((n, s, t) for t, (n, s) in per_test.items()), key=lambda r: r[1], reverse=True)
    return sum(n for n, _, _ in ranked), hits, sum(s for _, s, _ in ranked), ranked


@pytest.hookimpl(tryfirst=True)
def pytest_sessionfinish(session):
    if hasattr(session.config, "workeroutput"):  # an xdist worker: hand the counts to the controller
        session.config.workeroutput["compiles"] = json.dumps(COMPILES.report())
        return
    limit = os.environ.get("TDCT_MAX_COMPILES")
    if limit and compile_totals()[0] > int(limit) and session.exitstatus == pytest.ExitCode.OK:
        session.exitstatus = pytest.ExitCode.TESTS_FAILED


def pytest_terminal_summary(terminalreporter, config):
    if hasattr(config, "workeroutput"):
        return
    compiles, hits, seconds, ranked = compile_totals()
    write = terminalreporter.write_line
    terminalreporter.section("compiled programs")
    write(f"{compiles} XLA compiles ({seconds:.0f} s of compiling), {hits} loaded from the session's compilation cache")
    for n, s, test in ranked[:10]:
        write(f"{n:5d} {s:7.1f} s  {test}")
    limit = os.environ.get("TDCT_MAX_COMPILES")
    if limit and compiles > int(limit):
        write(f"FAILED: {compiles} compiles, more than TDCT_MAX_COMPILES={limit}", red=True)


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


class Section(NamedTuple):
    """Section properties of a one-section robot with one tube (the paper's), by the textbook
    formulas: E, G, area A, second moments I_x, I_y of the silicone; EI and rho A of the tube."""

    E: float
    G: float
    A: float
    I_x: float
    I_y: float
    EI_tube: float
    rho: float
    rho_tube: float


def section(robot) -> Section:
    sec, tube, n = robot.sections[0], robot.tubes[0], robot.n_tendons
    D, dc, dt = float(sec.outer_diameter), float(sec.inner_diameter), float(sec.tendon_channel_diameter)
    r = np.array([[float(t.offset) * np.cos(float(t.angle)), float(t.offset) * np.sin(float(t.angle))] for t in robot.tendons])
    A = np.pi / 4 * (D**2 - dc**2 - n * dt**2)
    disc, own, hole = np.pi / 64 * (D**4 - dc**4), np.pi / 64 * dt**4, np.pi / 4 * dt**2
    I_x = disc - np.sum(own + hole * r[:, 1] ** 2)
    I_y = disc - np.sum(own + hole * r[:, 0] ** 2)
    Do, Di = float(tube.outer_diameter), float(tube.inner_diameter)
    E = float(sec.E)
    G = E / (2 * (1 + float(sec.nu)))
    tube_area = np.pi / 4 * (Do**2 - Di**2)
    EI_tube = float(tube.E) * np.pi / 64 * (Do**4 - Di**4)
    return Section(E, G, A, I_x, I_y, EI_tube, float(sec.density) * A, float(tube.density) * tube_area)


def rel_err(a, b):
    """Largest relative deviation of a from the reference b."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    return float(np.max(np.abs(a - b)) / np.max(np.abs(b)))


@pytest.fixture(scope="session")
def robot():
    return tdct.Robot.paper()


HEIGHT, MASS = 0.03, 0.02
"""A tip height [m] reached with tendon 1 and the tube, holding a tip mass [kg]: the IK guide's and
the notebook's redundancy example."""


@pytest.fixture(scope="session")
def stiffest(robot):
    """The stiffest way along -y to hold the tip at HEIGHT with MASS, tendon 1 and the tube (session
    scope: its program takes tens of seconds to compile, and module fixtures are rebuilt whenever a
    worker comes back to their module)."""
    target = tdct.Target((0.0, HEIGHT, 0.0), axes="y")
    options = dict(load=tdct.Loads.from_mass(MASS), tendons=(1,), objective=tdct.Stiffness(direction=(0.0, -1.0, 0.0)))
    return tdct.inverse_kinematics(robot, target, **options)


@pytest.fixture(scope="session")
def paper_case(robot):
    """The paper's Fig. 6 setting: 6 N on tendon 1, 80 mm of tube, 20 g at the tip."""
    act = tdct.Actuation(tensions=(6.0, 0.0, 0.0, 0.0), insertions=0.08)
    load = tdct.Loads.from_mass(0.020)
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
