"""Exact (autodiff) compliance matrix against central differences: accuracy V-curve and cost.

Run: python benchmarks/compliance_autodiff_vs_fd.py [--quick] [--repeats 20]
Writes benchmarks/results/compliance.json and compliance_fd_error.png (compliance_quick.json and
compliance_fd_error_quick.png with --quick: 3 repeats).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import jax
import numpy as np
from _common import timings, write_result

import tdct_jax as tdct
from tdct_jax.plotting import plot_fd_error

CONFIGS = {
    "no tube, 0 N, no mass": ((0.0, 0, 0, 0), 0.0, 0.0),
    "no tube, 8 N, 50 g": ((8.0, 0, 0, 0), 0.0, 0.05),
    "full tube, 0 N, no mass": ((0.0, 0, 0, 0), 0.16, 0.0),
    "full tube, 8 N, 50 g": ((8.0, 0, 0, 0), 0.16, 0.05),
    "80 mm, 8 N, 20 g": ((8.0, 0, 0, 0), 0.08, 0.02),
}
STEPS_N = [10.0**-k for k in range(1, 10)]


def _median_times(functions, repeats):
    """Median seconds of each function, their calls interleaved so that the machine's noise falls
    on all of them alike (the ratios are what this benchmark reports)."""
    times = np.array([[timings(f, 1)[0] for f in functions] for _ in range(repeats)])
    return [float(t) for t in np.median(times, axis=0)]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=20)
    parser.add_argument("--quick", action="store_true", help="3 repeats")
    args = parser.parse_args()
    repeats = 3 if args.quick else args.repeats
    out, suffix = Path(__file__).parent / "results", "_quick" if args.quick else ""
    out.mkdir(parents=True, exist_ok=True)

    robot = tdct.Robot.paper()
    t = time.perf_counter()
    jax.block_until_ready(tdct.compliance(robot, tdct.Actuation()))
    compile_s = time.perf_counter() - t
    print(f"compile + first exact compliance: {compile_s:.1f} s")

    rows = []
    for name, (tensions, insertion, mass) in CONFIGS.items():
        act, load = tdct.Actuation(tensions, insertion), tdct.Loads.from_mass(mass)
        CM = np.asarray(tdct.compliance(robot, act, load))
        errors = []
        for h in STEPS_N:
            fd = np.asarray(tdct.finite_difference_compliance(robot, act, load, step=h))
            errors.append(float(np.abs(fd - CM).max() / np.abs(CM).max()))
        t_ad, t_fd, t_solve = _median_times(
            [
                lambda act=act, load=load: tdct.compliance(robot, act, load),
                lambda act=act, load=load: tdct.finite_difference_compliance(robot, act, load, step=1e-5),
                lambda act=act, load=load: tdct.solve(robot, act, load).position,
            ],
            repeats,
        )
        best = int(np.argmin(errors))
        row = dict(
            config=name,
            CM_mm_per_N=(CM * 1e3).round(6).tolist(),
            fd_steps_N=STEPS_N,
            fd_relative_error=errors,
            best_fd_step_N=STEPS_N[best],
            best_fd_error=errors[best],
            autodiff_ms=t_ad * 1e3,
            fd_ms=t_fd * 1e3,
            solve_ms=t_solve * 1e3,
            fd_over_autodiff=t_fd / t_ad,
            autodiff_over_solve=t_ad / t_solve,
        )
        rows.append(row)
        print(
            f"{name:26s} best FD error {errors[best]:.1e} at {STEPS_N[best]:.0e} N; "
            f"autodiff {t_ad * 1e3:6.1f} ms, FD {t_fd * 1e3:6.1f} ms ({t_fd / t_ad:.1f}x), one solve {t_solve * 1e3:5.1f} ms"
        )

    write_result(out / f"compliance{suffix}.json", repeats=repeats, compile_and_first_compliance_s=compile_s, configs=rows)
    plot_fd_error(rows, out / f"compliance_fd_error{suffix}.png")
    print(f"wrote {out / f'compliance{suffix}.json'} and {out / f'compliance_fd_error{suffix}.png'}")


if __name__ == "__main__":
    main()
