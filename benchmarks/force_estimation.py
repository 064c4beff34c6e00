"""Where is it touching, and how hard: an unknown point force on the paper's robot estimated from a
measured shape with 0.1 mm noise (issue 26, acceptance 5), over random cases.

Each case: random tensions (each tendon 0-3 N or slack), a random insertion, a force of 0.2-0.5 N
normal to the body (a frictionless contact on its side) at a random arc length, the shape sampled
at 161 points (every mm) with Gaussian noise. Estimated three ways: with the prior that the force
is normal to the body (``axial_noise``), with all three components free, and from 33 points (an
FBG fibre's spacing). Reported: location error in % of L and magnitude error in %, mean, median,
95th percentile and max; the share of location errors within 3 stated standard errors; the time
per estimate. Two ranges of location: the outer 60% of the body (the acceptance's setting) and
the whole of it, where forces near the base hardly bend the robot and the estimate degrades as the
stated uncertainty says.

Run: python benchmarks/force_estimation.py [--cases N]
Writes benchmarks/results/force_estimation.json.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np
from _common import write_result
from tqdm import tqdm

import tdct_jax as tdct
from tdct_jax.estimate import estimate_force, synthesize

HERE = Path(__file__).parent
SETTINGS = {
    "normal prior, 161 points, s in [0.4, 1] L": dict(axial_noise=1e-3, points=161, lo=0.4),
    "all components free, 161 points, s in [0.4, 1] L": dict(axial_noise=None, points=161, lo=0.4),
    "normal prior, 33 points, s in [0.4, 1] L": dict(axial_noise=1e-3, points=33, lo=0.4),
    "normal prior, 161 points, s in [0.1, 1] L": dict(axial_noise=1e-3, points=161, lo=0.1),
}


def statistics(errors) -> dict:
    e = 100 * np.asarray(errors)
    return dict(mean=float(e.mean()), median=float(np.median(e)), p95=float(np.percentile(e, 95)), max=float(e.max()))


def run(cases: int, axial_noise, points: int, lo: float, seed: int = 0) -> dict:
    robot, rng = tdct.Robot.paper(), np.random.default_rng(seed)
    L = float(robot.length)
    loc, mag, z, seconds, failed = [], [], [], [], 0
    for _ in tqdm(range(cases), leave=False):
        act = tdct.Actuation(rng.uniform(0, 3, 4) * (rng.random(4) < 0.5), rng.uniform(0, L))
        s, magnitude = rng.uniform(lo, 1.0) * L, rng.uniform(0.2, 0.5)
        exp, _ = synthesize(robot, act, s, magnitude, rng.uniform(0, 2 * np.pi), points=points, rng=rng)
        t = time.perf_counter()
        e = estimate_force(robot, exp, axial_noise=axial_noise, throw=False)
        seconds.append(time.perf_counter() - t)
        failed += not e.converged
        loc.append(abs(e.s - s) / L)
        mag.append(abs(e.magnitude / magnitude - 1))
        z.append(abs(e.s - s) / max(e.std_s, 1e-300))
    return dict(
        location_error_percent_of_L=statistics(loc),
        magnitude_error_percent=statistics(mag),
        location_within_3_std=float(np.mean(np.array(z) < 3)),
        not_converged=failed,
        seconds_per_estimate_median=float(np.median(seconds[1:])),
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", type=int, default=100)
    args = parser.parse_args()
    results = {}
    for name, setting in tqdm(SETTINGS.items(), desc="settings"):
        results[name] = run(args.cases, **setting)
        tqdm.write(f"{name}: {results[name]}")
    write_result(
        HERE / "results" / "force_estimation.json",
        cases=args.cases,
        noise_m=1e-4,
        force_N="0.2-0.5, normal to the body",
        load_average=os.getloadavg(),
        settings=results,
    )


if __name__ == "__main__":
    main()
