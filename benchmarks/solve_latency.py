"""Compile time, warm single-solve latency and Newton iterations for paper configurations.

Run: python benchmarks/solve_latency.py [--quick] [--repeats 200] [--steps 16]
Writes benchmarks/results/latency.json (latency_quick.json with --quick: 20 repeats). For steady numbers pin to one core: taskset -c 0 python ...

With --intervals 2,4,8: single against multiple shooting (SolverOptions.intervals) instead, side
by side in one process, the variants alternated call by call: warm solves of CONFIGS[:3], a
small vmapped batch, compile times, and the agreement with single shooting of tips, implicit
derivatives d tip / d(tensions, insertion, sections[*].E) and compliance; writes
benchmarks/results/multiple_shooting.json (multiple_shooting_quick.json with --quick).
With --general 4,8: the same for the shipped two-segment robot (a Robot with a point
load at 0.1 m and a point mass at 0.3 m: 4 breakpoint intervals, its section end and the three
anchors there one breakpoint, K dividing 4 x steps), by
tensions and by displacements (four tendons driven), tips and compliance compared; writes
benchmarks/results/multiple_shooting_general.json.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from _common import timings, write_result

import tdct_jax as tdct
from tdct_jax.description import ROBOTS
from tdct_jax.mechanics import compliance_and_solution

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
    parser.add_argument("--intervals", help="compare single shooting with these K, e.g. 2,4,8")
    parser.add_argument("--general", help="the same for the two-segment robot, e.g. 4,8")
    args = parser.parse_args()
    repeats = 20 if args.quick else args.repeats
    if args.general:
        return compare_general(args, repeats, [int(k) for k in args.general.split(",")])
    if args.intervals:
        return compare_intervals(args, repeats, [int(k) for k in args.intervals.split(",")])
    out = Path(__file__).parent / "results" / f"latency{'_quick' if args.quick else ''}.json"

    robot = tdct.Robot.paper()
    t0 = time.perf_counter()
    solver = tdct.SolverOptions(steps=args.steps)
    first = tdct.solve(robot, tdct.Actuation(), solver=solver)
    jax.block_until_ready(first.position)
    compile_s = time.perf_counter() - t0
    print(f"compile + first solve: {compile_s:.2f} s (steps = {args.steps} per segment)")

    rows = []
    for name, (tensions, insertion, mass) in CONFIGS.items():
        act, load = tdct.Actuation(tensions, insertion), tdct.Loads.from_mass(mass)
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


def _derivatives(robot, act, load, solver):
    """d tip position / d(tensions (4), insertion, sections[*].E), (3, 6), by implicit differentiation."""

    def tip(v):
        r = robot.replace({"sections[*].E": v[5]})
        return tdct.solve(r, tdct.Actuation(v[:4], v[4]), load, solver=solver, throw=False).tip_position

    E = robot.sections[0].E
    v = jnp.concatenate([jnp.asarray(act.tensions, float), jnp.array([act.insertion, E])])
    return jax.jit(jax.jacfwd(tip))(v) * jnp.concatenate([jnp.ones(4), jnp.array([1.0, E])])


def _relative(a, b):
    return float(np.max(np.abs(np.asarray(a) - np.asarray(b))) / np.max(np.abs(np.asarray(b))))


def compare_intervals(args, repeats, Ks):
    """Single shooting against multiple shooting with each K in Ks, alternated call by call."""
    out = Path(__file__).parent / "results" / f"multiple_shooting{'_quick' if args.quick else ''}.json"
    robot = tdct.Robot.paper()
    variants = {K: tdct.SolverOptions(steps=args.steps, intervals=K) for K in [1, *Ks]}
    configs = list(CONFIGS.items())[:3]
    problems = [(name, tdct.Actuation(t, d), tdct.Loads.from_mass(m)) for name, (t, d, m) in configs]
    compile_s = {}
    for K, solver in variants.items():
        t0 = time.perf_counter()
        jax.block_until_ready(tdct.solve(robot, *problems[0][1:], solver=solver).position)
        compile_s[K] = time.perf_counter() - t0
    print(f"uptime: {os.getloadavg()}; compile + first solve [s]: {compile_s}")
    rows = []
    for name, act, load in problems:
        sols = {K: tdct.solve(robot, act, load, solver=s) for K, s in variants.items()}
        C = {K: tdct.compliance(robot, act, load, solver=s, full=True) for K, s in variants.items()}
        D = {K: _derivatives(robot, act, load, s) for K, s in variants.items()}
        times = {K: [] for K in variants}
        for _ in range(repeats):
            for K, s in variants.items():
                times[K].append(timings(lambda act=act, load=load, s=s: tdct.solve(robot, act, load, solver=s).position, 1)[0])
        med = {K: float(np.median(t)) * 1e3 for K, t in times.items()}
        row = dict(config=name, median_ms={str(K): m for K, m in med.items()}, ratio_to_single={})
        for K in Ks:
            row["ratio_to_single"][str(K)] = med[K] / med[1]
            row.setdefault("iterations", {})[str(K)] = int(sols[K].iterations)
            row.setdefault("tip_difference_m", {})[str(K)] = float(np.max(np.abs(sols[K].tip_position - sols[1].tip_position)))
            row.setdefault("path_difference_m", {})[str(K)] = float(np.max(np.abs(sols[K].position - sols[1].position)))
            row.setdefault("derivative_relative_difference", {})[str(K)] = _relative(D[K], D[1])
            row.setdefault("compliance_relative_difference", {})[str(K)] = _relative(C[K], C[1])
        row["iterations"]["1"] = int(sols[1].iterations)
        rows.append(row)
        print(
            name,
            "median ms",
            {K: round(m, 3) for K, m in med.items()},
            "ratios",
            {K: round(r, 3) for K, r in row["ratio_to_single"].items()},
        )
        print(
            "  tip diff",
            row["tip_difference_m"],
            "deriv",
            row["derivative_relative_difference"],
            "C",
            row["compliance_relative_difference"],
        )

    # a small batch: lanes already run side by side
    B = 16
    rng = np.random.default_rng(0)
    tensions = rng.uniform(0, 8, (B, 4))
    insertions = rng.uniform(0, 0.16, B)
    batch = {}
    for K, s in variants.items():
        f = jax.jit(jax.vmap(lambda t, d, s=s: tdct.solve(robot, tdct.Actuation(t, d), solver=s, throw=False).tip_position))
        jax.block_until_ready(f(tensions, insertions))
        batch[K] = (f, [])
    for _ in range(max(repeats // 4, 5)):
        for f, t in batch.values():
            t.append(timings(lambda f=f: f(tensions, insertions), 1)[0])
    batch_ms = {str(K): float(np.median(t)) * 1e3 for K, (f, t) in batch.items()}
    print(f"vmapped batch of {B}: median ms {batch_ms}; uptime {os.getloadavg()}")
    write_result(
        out,
        steps_per_segment=args.steps,
        repeats=repeats,
        load_average=os.getloadavg(),
        compile_and_first_solve_s={str(K): v for K, v in compile_s.items()},
        configs=rows,
        batch=dict(lanes=B, median_ms=batch_ms),
    )
    print(f"wrote {out}")


def compare_general(args, repeats, Ks):
    """``compare_intervals`` for the two-segment robot with a point load and a point mass."""
    out = Path(__file__).parent / "results" / f"multiple_shooting_general{'_quick' if args.quick else ''}.json"
    robot = tdct.Robot.from_toml(ROBOTS / "two_segment.toml").replace(masses=(tdct.PointMass(0.3, 0.005),))
    load = tdct.Loads(tip_force=[0.02, 0, 0], point_s=[0.1], point_force=[[0.0, 0.05, -0.02]], point_moment=[[1e-3, 0, 5e-4]])
    acts = {
        "by tensions": tdct.Actuation([1.5, 0.0, 0.4, 0.0, 0.8, 0.3]),
        "by displacements (tendons 0, 2, 4, 5)": tdct.Actuation(
            np.zeros(6), displacements=[2e-3, 1e-3, 1e-3, 5e-4], driven=(0, 2, 4, 5)
        ),
    }
    variants = {K: tdct.SolverOptions(steps=args.steps, intervals=K) for K in [1, *Ks]}
    rows, compile_s = [], {}
    for name, act in acts.items():
        sols, C, times = {}, {}, {K: [] for K in variants}
        for K, s in variants.items():
            t0 = time.perf_counter()
            C[K], sols[K] = compliance_and_solution(robot, act, load, solver=s)
            compile_s[f"{name}, {K}"] = time.perf_counter() - t0
        for _ in range(repeats):
            for K, s in variants.items():
                times[K].append(timings(lambda act=act, s=s: tdct.solve(robot, act, load, solver=s).position, 1)[0])
        med = {K: float(np.median(t)) * 1e3 for K, t in times.items()}
        row = dict(config=name, median_ms={str(K): m for K, m in med.items()}, ratio_to_single={}, iterations={})
        for K in variants:
            row["iterations"][str(K)] = int(sols[K].iterations)
        for K in Ks:
            row["ratio_to_single"][str(K)] = med[K] / med[1]
            row.setdefault("path_difference_m", {})[str(K)] = float(np.max(np.abs(sols[K].position - sols[1].position)))
            row.setdefault("tension_relative_difference", {})[str(K)] = _relative(sols[K].tensions, sols[1].tensions)
            row.setdefault("compliance_relative_difference", {})[str(K)] = _relative(C[K], C[1])
        rows.append(row)
        print(name, "median ms", {K: round(m, 3) for K, m in med.items()}, "ratios", row["ratio_to_single"])
        print("  path diff", row["path_difference_m"], "C", row["compliance_relative_difference"])
    print(f"load average {os.getloadavg()}")
    write_result(
        out,
        steps_per_segment=args.steps,
        repeats=repeats,
        load_average=os.getloadavg(),
        compile_and_first_solve_s=compile_s,
        configs=rows,
    )
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
