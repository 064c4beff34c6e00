"""Warm-started updates along an actuation trajectory: the real-time control case.

A 1,000-step trajectory (tendons 1 and 4 and the insertion moving smoothly, 20 g at the tip) is
solved three ways: a Python control loop calling ``tdct.solve`` with each step's ``guess`` set to
the last base wrench (what a controller written in Python does), the same loop from the straight
rod each time (cold), and the whole trajectory inside one compiled ``lax.scan``
(``tdct.solve`` with each step's ``guess`` the last converged base wrench, under ``lax.scan``
and ``jax.jit``; no Python between steps). Reports the latency per update
(median and p90 for the loops, mean for the scan), Newton iterations and peak memory.

Run: python benchmarks/trajectory.py [--quick]
Writes benchmarks/results/trajectory.json (trajectory_quick.json with --quick: 200 steps).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from _common import peak_rss_mb, write_result
from jax import lax

import tdct_jax as tdct

STEPS = tdct.SolverOptions().steps


def trajectory(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Tensions (n, 4) [N] and insertions (n,) [m] of one smooth period."""
    phase = 2 * np.pi * np.arange(n) / n
    tensions = np.zeros((n, 4))
    tensions[:, 0] = 5 + 5 * np.sin(phase)
    tensions[:, 3] = 3 + 3 * np.sin(2 * phase)
    return tensions, 0.08 + 0.06 * np.sin(phase + 1.0)


def control_loop(robot, tensions, insertions, load, warm: bool):
    """Seconds per update and Newton iterations of a Python loop over the trajectory."""
    guess, seconds, iterations, tips = None, [], [], []
    for tau, d in zip(tensions, insertions, strict=True):
        t = time.perf_counter()
        sol = tdct.solve(robot, tdct.Actuation(tau, d), load, guess=guess)
        tip = np.asarray(sol.tip_position)  # a controller reads the tip: that waits for the solve
        seconds.append(time.perf_counter() - t)
        if not bool(sol.converged):
            raise RuntimeError(f"the solve at tensions {tau}, insertion {d} did not converge")
        guess = sol.base_wrench if warm else None
        iterations.append(int(sol.iterations))
        tips.append(tip)
    return np.array(seconds), np.array(iterations), np.array(tips)


def compiled_path(robot, load):
    """The trajectory as one compiled scan, each solve started from the last converged one:
    (tips, Newton iterations, converged) per step."""

    def step(guess, inputs):
        sol = tdct.solve(robot, tdct.Actuation(*inputs), load, guess=guess, throw=False)
        return jnp.where(sol.converged, sol.base_wrench, guess), (sol.tip_position, sol.iterations, sol.converged)

    @jax.jit
    def path(tensions, insertions):
        return lax.scan(step, jnp.full(6, jnp.nan), (tensions, insertions))[1]

    return path


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="200 steps")
    args = parser.parse_args()
    n = 200 if args.quick else 1000
    out = Path(__file__).parent / "results" / f"trajectory{'_quick' if args.quick else ''}.json"
    robot, load = tdct.Robot.paper(), tdct.Loads.from_mass(0.020)
    tensions, insertions = trajectory(n)
    jax.block_until_ready(tdct.solve(robot, tdct.Actuation(tensions[0], insertions[0]), load).position)

    rows, tips = [], {}
    for name, warm in (("Python loop, warm start", True), ("Python loop, cold start", False)):
        seconds, iterations, tips[name] = control_loop(robot, tensions, insertions, load, warm)
        rows.append(
            dict(
                method=name,
                median_ms=float(np.median(seconds) * 1e3),
                p90_ms=float(np.percentile(seconds, 90) * 1e3),
                mean_iterations=float(iterations.mean()),
            )
        )
        print(rows[-1], flush=True)

    scan = compiled_path(robot, load)
    scan(tensions, insertions)
    t = time.perf_counter()
    scan_tips, scan_iterations, converged = jax.block_until_ready(scan(tensions, insertions))
    scan_s = time.perf_counter() - t
    if not np.all(converged):
        raise RuntimeError("the compiled path did not converge everywhere")
    tips["compiled scan"] = np.asarray(scan_tips)
    rows.append(
        dict(
            method="compiled lax.scan, warm start",
            median_ms=scan_s * 1e3 / n,
            p90_ms=None,
            mean_iterations=float(np.mean(scan_iterations)),
        )
    )
    print(rows[-1], flush=True)
    agree = max(float(np.abs(tips[k] - tips["Python loop, cold start"]).max()) for k in tips)
    write_result(
        out,
        steps_per_segment=STEPS,
        trajectory_steps=n,
        rows=rows,
        max_tip_difference_between_methods_m=agree,
        peak_rss_mb=peak_rss_mb(),
    )
    print(f"the three methods' tips agree to {agree:.1e} m; peak RSS {peak_rss_mb():.0f} MB; wrote {out}")


if __name__ == "__main__":
    main()
