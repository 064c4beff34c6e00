"""Where a warm solve's time goes: Newton's Jacobian passes against one primal shooting pass.

Run: python benchmarks/profile_solve.py [--steps 16] [--repeats 50]
For numbers that do not depend on XLA's thread pool, pin to one core: taskset -c 0 python ...
Writes benchmarks/results/profile.json.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from _common import timings, write_result

import tdct_jax as tdct
from tdct_jax.rod import force_scale, shoot, straight_rod

STEPS = tdct.SolverOptions().steps


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=STEPS)
    parser.add_argument("--repeats", type=int, default=50)
    args = parser.parse_args()

    robot = tdct.Robot.paper()
    act, load = tdct.Actuation((6.0, 0, 0, 0), 0.080), tdct.Loads.from_mass(0.020)
    gravity, solver = jnp.asarray(tdct.STANDARD_GRAVITY), tdct.SolverOptions(steps=args.steps)
    F_c = force_scale(robot, act, load, gravity)
    x0 = straight_rod(robot, act, load, gravity, F_c)

    def residual(x):
        return shoot(robot, act, load, gravity, solver, x, F_c)[0]

    primal, jacobian = jax.jit(residual), jax.jit(jax.jacfwd(residual))
    sol = tdct.solve(robot, act, load, solver=solver)
    parts = {
        "solve": lambda: tdct.solve(robot, act, load, solver=solver).position,
        "primal shooting pass": lambda: primal(x0),
        "jacfwd pass (7 lanes)": lambda: jacobian(x0),
    }
    ms = {}
    for name, f in parts.items():
        jax.block_until_ready(f())
        ms[name] = float(np.median(timings(f, args.repeats)) * 1e3)
        print(f"{name:24s} {ms[name]:8.3f} ms")
    passes = int(sol.iterations) + 1  # Newton's first pass evaluates the start
    share = passes * ms["jacfwd pass (7 lanes)"] / ms["solve"]
    print(f"{int(sol.iterations)} Newton iterations: {passes} Jacobian passes = {100 * share:.0f}% of the solve")
    write_result(
        Path(__file__).parent / "results" / "profile.json",
        steps_per_segment=args.steps,
        repeats=args.repeats,
        config="6 N on tendon 1, 80 mm, 20 g",
        median_ms=ms,
        newton_iterations=int(sol.iterations),
        jacobian_share_of_solve=share,
    )


if __name__ == "__main__":
    main()
