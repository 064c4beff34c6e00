"""Compile time of every inverse-kinematics entry point, each in a fresh process with no
compilation cache, and the number of while loops (shooting scans run inside them) in its program.

Entries on the paper robot: one target without an objective, with the least-tension one (whose
phase 2 the preferred-insertion objective shares) and with the stiffness one (all four tendons and
the insertion free), a batch of 8 targets, ``track`` over 4 targets; and ``tdct ik --target-mm`` as a
whole cold process (TDCT_COMPILE_CACHE=off, the CLI's cache switched off). Compile time is the
first call less a warm call of the same program; for the single-target programs also split into
tracing and XLA's compile, with their sizes. Goals (issue 24): every IK plan under 10 s, a
cold ``tdct ik`` under 15 s.

Run: python benchmarks/compile_times.py
Writes benchmarks/results/compile_times.json.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

from _common import write_result

ENTRIES = {
    "one target": "tdct.inverse_kinematics(robot, Target(tip), load=load)",
    "one target, least-tension objective": "tdct.inverse_kinematics(robot, Target(tip), load=load, objective='tension')",
    "one target, stiffness objective": "tdct.inverse_kinematics(robot, Target(tip), load=load, objective='stiffness')",
    "batch of 8": "tdct.inverse_kinematics(robot, Target(np.tile(tip, (8, 1))), load=load, throw=False)",
    "track of 4": "tdct.track(robot, Target(np.tile(tip, (4, 1))), load=load, throw=False)",
}

CHILD = """
import json, sys, time
import jax, numpy as np
import tdct_jax as tdct
from tdct_jax import Target
from tdct_jax.ik.driver import _solve_ik
robot, load = tdct.Robot.paper(), tdct.Loads.from_mass(0.01)
def call(tip):
    return jax.block_until_ready({call})
t = time.perf_counter(); call(np.array([0.0, 0.03, 0.14])); first = time.perf_counter() - t
t = time.perf_counter(); call(np.array([0.01, 0.02, 0.145])); warm = time.perf_counter() - t
print(json.dumps(dict(compile_s=first - warm, first_s=first, warm_s=warm)))
"""


def child(expression: str) -> dict:
    env = dict(os.environ, TDCT_COMPILE_CACHE="off", JAX_ENABLE_COMPILATION_CACHE="false")
    out = subprocess.run(
        [sys.executable, "-c", CHILD.format(call=expression)], env=env, capture_output=True, text=True, check=True
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def program_sizes() -> dict:
    """The single-target programs (without and with an objective) lowered and compiled in this
    process (no cache): tracing and lowering seconds, XLA compile seconds (CPU time of the
    process, which other processes' load changes less than wall time), lines of StableHLO and
    while loops (shooting scans run inside them)."""
    import jax
    import numpy as np

    import tdct_jax as tdct
    from tdct_jax.ik import _arguments
    from tdct_jax.ik.arguments import _problem
    from tdct_jax.ik.driver import _solve_ik

    jax.config.update("jax_enable_compilation_cache", False)
    sizes = {}
    robot, load = tdct.Robot.paper(), tdct.Loads.from_mass(0.01)
    for name, objective in (("one target", None), ("one target, stiffness objective", "stiffness")):
        prob, plan, v0, wrench0 = _problem(
            **_arguments(robot, tdct.Target(np.array([0.0, 0.03, 0.14])), load=load, objective=objective)
        )
        t = time.process_time()
        lowered = _solve_ik.lower(prob, v0, wrench0, plan)
        lower_cpu_s = time.process_time() - t
        text = lowered.as_text()
        t = time.process_time()
        lowered.compile()
        sizes[name] = dict(
            lower_cpu_s=lower_cpu_s,
            compile_cpu_s=time.process_time() - t,
            hlo_lines=text.count("\n"),
            while_loops=text.count("stablehlo.while"),
        )
    return sizes


def main() -> None:
    uptime = os.getloadavg()
    results = {name: child(expression) for name, expression in ENTRIES.items()}
    env = dict(os.environ, TDCT_COMPILE_CACHE="off")
    t = time.perf_counter()
    subprocess.run(["tdct", "ik", "--target-mm", "0,30,140", "--json"], env=env, capture_output=True, text=True, check=False)
    results["tdct ik --target-mm 0,30,140 (whole process)"] = dict(first_s=time.perf_counter() - t)
    for name, size in program_sizes().items():
        results[name].update(size)
    for name, r in results.items():
        print(f"{name:48s} " + ", ".join(f"{k} {v:.2f}" if isinstance(v, float) else f"{k} {v}" for k, v in r.items()))
    write_result(
        Path(__file__).parent / "results" / "compile_times.json",
        load_average_before=list(uptime),
        load_average_after=list(os.getloadavg()),
        entries=results,
    )


if __name__ == "__main__":
    main()
