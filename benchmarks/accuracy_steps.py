"""Tip accuracy and cost against the number of RK4 steps: the table the default step count comes from.

For random configurations over the operating envelope (0-10 N on random tendons, 0-160 mm of
tube, tip forces up to 0.5 N in any direction, gravity on), the tip at each step count is compared
with a solution 16x finer than the finest step count tested. Beside each error: the warm
single-solve latency at that step count (the Fig. 6 configuration, median). Last, how far the
tips move with one more Newton step on the constitutive relations than the default (full run only).

Run: python benchmarks/accuracy_steps.py [--quick]
Writes benchmarks/results/accuracy_steps.json (accuracy_steps_quick.json with --quick).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import jax
import numpy as np
from _common import timings, write_result

import tdct_jax as tdct
from tdct_jax import segments

STEPS = tdct.SolverOptions().steps

TARGET_M = 1e-6
"""Issue 6: the default step count keeps the tip within 1 micrometre of the converged solution."""
MARGIN = 2.0
"""The default must meet the target with this factor to spare."""


def envelope(n: int, seed: int = 0) -> dict:
    rng = np.random.default_rng(seed)
    tensions = rng.uniform(0, 10, (n, 4)) * (rng.random((n, 4)) < 0.5)
    direction = rng.normal(size=(n, 3))
    force = direction / np.linalg.norm(direction, axis=1, keepdims=True) * rng.uniform(0, 0.5, (n, 1))
    return {"tensions": tensions, "insertion": rng.uniform(0, 0.16, n), "force": force}


def tips(robot, batch, steps):
    res = tdct.sweep(
        robot, batch=batch, solver=tdct.SolverOptions(steps=steps), progress=False, chunk_size=len(batch["insertion"])
    )
    if res.n_failed:
        raise RuntimeError(f"{res.n_failed} configurations did not converge at steps = {steps}")
    return res.tip_position


def constitutive_newton_effect(robot, batch) -> float:
    """How far [um] the tips move with one more Newton step on the constitutive relations than the
    default segments.NEWTON_STEPS, at the default step count (two recompiles)."""
    default = segments.NEWTON_STEPS
    by_newton = {}
    for k in (default + 1, default):  # ends on the default
        segments.NEWTON_STEPS = k
        jax.clear_caches()
        by_newton[k] = tips(robot, batch, STEPS)
    um = float(np.linalg.norm(by_newton[default + 1] - by_newton[default], axis=1).max() * 1e6)
    print(f"constitutive Newton steps {default} -> {default + 1}: tips move by at most {um:.1e} um")
    return um


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="8 configurations, steps 8..50, fewer repeats")
    args = parser.parse_args()
    out = Path(__file__).parent / "results" / f"accuracy_steps{'_quick' if args.quick else ''}.json"

    robot = tdct.Robot()
    n, steps_list, repeats = (8, (8, 12, 16, 25, 50), 10) if args.quick else (32, (8, 12, 16, 20, 25, 32, 50, 100, 200), 40)
    batch = envelope(n)
    reference_steps = 16 * max(steps_list)
    start = time.perf_counter()
    reference = tips(robot, batch, reference_steps)
    print(f"reference: {n} configurations at {reference_steps} steps per segment ({time.perf_counter() - start:.0f} s)")

    act, load = tdct.Actuation((6.0, 0, 0, 0), 0.080), tdct.TipLoad.from_mass(0.020)
    rows = []
    for steps in steps_list:
        err = np.linalg.norm(tips(robot, batch, steps) - reference, axis=1)
        tdct.solve(robot, act, load, solver=tdct.SolverOptions(steps=steps))
        solve_ms = 1e3 * timings(
            lambda steps=steps: tdct.solve(robot, act, load, solver=tdct.SolverOptions(steps=steps)).position, repeats
        )
        rows.append(
            dict(
                steps_per_segment=steps,
                total_steps=2 * steps,
                max_tip_error_um=float(err.max() * 1e6),
                median_tip_error_um=float(np.median(err) * 1e6),
                solve_median_ms=float(np.median(solve_ms)),
            )
        )
        r = rows[-1]
        print(
            f"steps {steps:4d} per segment: tip error max {r['max_tip_error_um']:.2e} um, median {r['median_tip_error_um']:.2e} um; "
            f"warm solve {r['solve_median_ms']:.1f} ms"
        )
    newton_um = None if args.quick else constitutive_newton_effect(robot, batch)
    ok = [r["steps_per_segment"] for r in rows if r["max_tip_error_um"] * 1e-6 * MARGIN <= TARGET_M]
    recommended = min(ok) if ok else None
    print(f"fewest steps per segment within {TARGET_M * 1e6:g} um / {MARGIN:g} over the envelope: {recommended}")
    write_result(
        out,
        quick=args.quick,
        configurations=n,
        reference_steps_per_segment=reference_steps,
        target_um=TARGET_M * 1e6,
        margin=MARGIN,
        recommended_steps_per_segment=recommended,
        constitutive_newton_steps=segments.NEWTON_STEPS,
        tip_change_with_one_more_constitutive_step_um=newton_um,
        rows=rows,
    )
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
