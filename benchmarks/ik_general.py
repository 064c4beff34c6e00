"""IK round trip on the two-segment robot (issue 23, acceptance 6): 1,000 random actuations
(tensions uniform in [0, 3] N, each tendon slack half the time, gravity on) -> forward tips ->
IK with all six tendons free and the least-tension objective (one batched call).

Reports the fraction reached within 1e-6 mm with status SUCCESS, the fraction within 1e-6 mm
whatever the status, the median and 95th percentile position error, the wall time per IK (the
batched call, compile included, and a warm second call on the first 64 targets) and the load
average. tests/test_general_ik.py runs the same on the first 40.

Run: python benchmarks/ik_general.py [--n N]
Writes benchmarks/results/ik_general.json.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import jax
import numpy as np
from _common import write_result

import tdct_jax as tdct
from tdct_jax.description import ROBOTS

REACH_M = 1e-9


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=1000, help="actuations (default 1000)")
    n = parser.parse_args().n
    jax.config.update("jax_enable_x64", True)
    robot = tdct.Robot.from_toml(ROBOTS / "two_segment.toml")
    rng = np.random.default_rng(23)
    tensions = rng.uniform(0, 3, (n, 6)) * (rng.random((n, 6)) < 0.5)
    tips = np.stack([np.asarray(tdct.solve(robot, tdct.Actuation(t)).tip_position) for t in tensions])
    t = time.perf_counter()
    result = tdct.inverse_kinematics(robot, tdct.Target(tips), objective="tension", throw=False)
    total = time.perf_counter() - t
    t = time.perf_counter()
    tdct.inverse_kinematics(robot, tdct.Target(tips[:64]), objective="tension", throw=False)
    warm = (time.perf_counter() - t) / 64
    error, code = np.asarray(result.position_error), np.asarray(result.result)
    codes, counts = np.unique(code, return_counts=True)
    fields = dict(
        n=n,
        reached_success=float(np.mean((error <= REACH_M) & (code == tdct.status.SUCCESS))),
        within_1e6_mm=float(np.mean(error <= REACH_M)),
        median_error_m=float(np.median(error)),
        p95_error_m=float(np.percentile(error, 95)),
        max_error_m=float(error.max()),
        status_counts={str(int(c)): int(k) for c, k in zip(codes, counts, strict=True)},  # 0 SUCCESS, 4 OUTER_LIMIT
        total_s_compile_included=total,
        s_per_ik_compile_included=total / n,
        s_per_ik_warm_64=warm,
        loadavg=os.getloadavg(),
    )
    for k, v in fields.items():
        print(f"{k:28s} {v}")
    write_result(Path(__file__).parent / "results" / "ik_general.json", **fields)


if __name__ == "__main__":
    main()
