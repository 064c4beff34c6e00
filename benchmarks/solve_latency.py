"""Compile time, warm single-solve latency and Newton iterations for paper configurations.

Run: python benchmarks/solve_latency.py [--quick] [--repeats 200] [--steps 16]
Writes benchmarks/results/latency.json (latency_quick.json with --quick: 20 repeats). For steady numbers pin to one core: taskset -c 0 python ...
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import jax
import numpy as np
from _common import timings, write_result

import tdct_jax as tdct

STEPS = tdct.SolverOptions().steps

CONFIGS = {
    "6 N, 80 mm, 20 g (Fig. 6)": ((6.0, 0, 0, 0), 0.080, 0.020),
    "10 N, no tube, 50 g": ((10.0, 0, 0, 0), 0.0, 0.050),
    "10 N, 70 mm, 50 g (Fig. 13A optimum)": ((10.0, 0, 0, 0), 0.070, 0.050),
    "3 + 5 N on tendons 1, 4, 120 mm, 0 g": ((3.0, 0, 0, 5.0), 0.120, 0.0),
    "0 N, tube to tip, 0 g": ((0.0, 0, 0, 0), 0.160, 0.0),
}
PAPER_SECONDS = 0.82


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=200)
    parser.add_argument("--steps", type=int, default=STEPS)
    parser.add_argument("--quick", action="store_true", help="20 repeats")
    args = parser.parse_args()
    repeats = 20 if args.quick else args.repeats
    out = Path(__file__).parent / "results" / f"latency{'_quick' if args.quick else ''}.json"

    robot = tdct.Robot()
    t0 = time.perf_counter()
    solver = tdct.SolverOptions(steps=args.steps)
    first = tdct.solve(robot, tdct.Actuation(), solver=solver)
    jax.block_until_ready(first.position)
    compile_s = time.perf_counter() - t0
    print(f"compile + first solve: {compile_s:.2f} s (steps = {args.steps} per segment)")

    rows = []
    for name, (tensions, insertion, mass) in CONFIGS.items():
        act, load = tdct.Actuation(tensions, insertion), tdct.TipLoad.from_mass(mass)
        sol = tdct.solve(robot, act, load, solver=solver)
        times = timings(lambda act=act, load=load: tdct.solve(robot, act, load, solver=solver).position, repeats)
        times_ms = times * 1e3
        row = dict(
            config=name,
            median_ms=float(np.median(times_ms)),
            p90_ms=float(np.percentile(times_ms, 90)),
            iterations=int(sol.iterations),
            residual_norm=float(sol.residual_norm),
            tip_position_mm=(np.asarray(sol.tip_position) * 1e3).round(4).tolist(),
            speedup_vs_paper=PAPER_SECONDS / float(np.median(times)),
        )
        rows.append(row)
        print(
            f"{name:40s} median {row['median_ms']:7.2f} ms  p90 {row['p90_ms']:7.2f} ms  {row['iterations']} iterations  {row['speedup_vs_paper']:.0f}x the paper's 0.82 s"
        )

    write_result(
        out,
        steps_per_segment=args.steps,
        repeats=repeats,
        compile_and_first_solve_s=compile_s,
        configs=rows,
    )
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
