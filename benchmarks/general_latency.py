"""Warm single-solve latency of the paper robot (``tdct.Robot.paper()``) and of the two-segment
six-tendon robot, interleaved in one process.

The two-segment robot's three anchors at its section end, and a point mass there, are one
breakpoint (``Robot.merged``); the same robot with each its own zero-length interval (``merged``
None, as when its breakpoints are traced) is timed beside it, with each one's node count.

Run: python benchmarks/general_latency.py [--rounds 30] [--base PATH]
With ``--base PATH`` (a copy of an earlier ``tdct_jax`` package renamed ``tdct_base``, in PATH),
that version's paper-robot solve (its own API: ``tdct_base.Robot()``, ``TipLoad.from_mass``) is
timed in the same rounds: the side-by-side comparison of issue 23. Rounds alternate their order;
each times 10 solves of each configuration. Medians and 25th percentiles (the latter steadier on
a shared machine). Writes benchmarks/results/general_latency.json.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
import time
from pathlib import Path

import numpy as np
from _common import write_result

import tdct_jax as tdct
from tdct_jax.description import ROBOTS
from tdct_jax.tree import unchecked

PAPER = [((6.0, 0, 0, 0), 0.080, 0.020), ((3.0, 0, 0, 5.0), 0.120, 0.0)]
TWO_SEGMENT = [1.5, 0.0, 0.4, 0.0, 0.8, 0.3]


def paper_runner():
    robot = tdct.Robot.paper()
    cases = [(tdct.Actuation(t, d), tdct.Loads.from_mass(m)) for t, d, m in PAPER]
    return [lambda a=a, ld=ld: tdct.solve(robot, a, ld).position.block_until_ready() for a, ld in cases]


def base_runner(base):
    """The same solves by an earlier tdct_jax (``tdct_base``), in its own (former) API."""
    robot = base.Robot()
    cases = [(base.Actuation(t, d), base.TipLoad.from_mass(m)) for t, d, m in PAPER]
    return [lambda a=a, ld=ld: base.solve(robot, a, ld).position.block_until_ready() for a, ld in cases]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=30)
    parser.add_argument("--base", help="folder holding an earlier tdct_jax copied as package tdct_base")
    args = parser.parse_args()
    runs = {"Robot.paper()": paper_runner()}
    if args.base:
        sys.path.insert(0, args.base)
        runs = {"base Robot": base_runner(importlib.import_module("tdct_base"))} | runs
    two = tdct.Robot.from_toml(ROBOTS / "two_segment.toml").replace(masses=(tdct.PointMass(0.2, 0.005),))
    apart = unchecked(tdct.Robot, **vars(two) | {"merged": None})
    act = tdct.Actuation(TWO_SEGMENT)
    nodes = {}
    for name, robot in (("two_segment.toml + mass at 0.2 m", two), ("the same, breakpoints not merged", apart)):
        runs[name] = [lambda robot=robot: tdct.solve(robot, act).position.block_until_ready()]
        nodes[name] = int(tdct.solve(robot, act).s.size)
    compile_s = {}
    for name, fs in runs.items():
        t = time.perf_counter()
        for f in fs:
            f()
        compile_s[name] = time.perf_counter() - t
    times = {name: [[] for _ in fs] for name, fs in runs.items()}
    for r in range(args.rounds):
        for name in list(runs)[:: 1 if r % 2 else -1]:
            for i, f in enumerate(runs[name]):
                for _ in range(10):
                    t = time.perf_counter()
                    f()
                    times[name][i].append(time.perf_counter() - t)
    rows = []
    for name, per_case in times.items():
        for i, ts in enumerate(per_case):
            ms = np.array(ts) * 1e3
            rows.append(dict(robot=name, case=i, median_ms=float(np.median(ms)), p25_ms=float(np.percentile(ms, 25))))
            print(f"{name:34s} case {i}: median {rows[-1]['median_ms']:.3f} ms, p25 {rows[-1]['p25_ms']:.3f} ms")
    out = Path(__file__).parent / "results" / "general_latency.json"
    write_result(out, rounds=args.rounds, load_average=os.getloadavg(), nodes=nodes, compile_and_first_s=compile_s, rows=rows)


if __name__ == "__main__":
    main()
