"""Inverse kinematics against the forward solve, side by side in one run.

Four figures, each a median of warm calls (compile reported apart): a cold forward solve (from
the straight rod) and a cold IK (from the default start, all four tendons and the insertion free,
a reachable target); a warm forward update along a trajectory (``guess`` = the last base wrench)
and a tracking IK update (``tdct.track``, one compiled scan, per target, and its IK steps per warm
update, and how many of them took a Jacobian pass rather than a chord step); the IK's two
phase-1 methods ("augmented": shooting unknowns and inputs together;
"nested": a converged forward solve at every step); and batched IK throughput (targets per
second) against batched forward solves. Goals (issue 24): a tracking update in 0.5 ms and within
1.5x a warm forward update, a cold IK within 3x a cold forward solve.

Run: python benchmarks/ik.py [--quick]
Writes benchmarks/results/ik.json (ik_quick.json with --quick).
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
from jax import lax

import tdct_jax as tdct


def path(n: int):
    """A smooth actuation path (tendons 1 and 4, the insertion) and the tips it gives: the targets."""
    phase = 2 * np.pi * np.arange(n) / n
    tensions = np.zeros((n, 4))
    tensions[:, 0], tensions[:, 3] = 5 + 3 * np.sin(phase), 2 + 1.5 * np.sin(2 * phase)
    return tensions, 0.08 + 0.05 * np.sin(phase + 1.0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer repeats, a short path, a small batch")
    args = parser.parse_args()
    n_path, n_batch, repeats = (20, 64, 5) if args.quick else (100, 512, 20)
    out = Path(__file__).parent / "results" / f"ik{'_quick' if args.quick else ''}.json"
    robot, load = tdct.Robot.paper(), tdct.Loads.from_mass(0.02)
    tensions, insertions = path(n_path)
    tips = tdct.sweep(
        robot, tdct.Actuation(), load, batch={"tensions": tensions, "insertion": insertions}, progress=False
    ).tip_position
    rows, compile_s = {}, {}

    def measure(name, f, reps=repeats, per=1):
        """Median milliseconds of f over reps calls, divided by ``per`` (the updates or points in a call)."""
        t = time.perf_counter()
        jax.block_until_ready(f())
        compile_s[name] = time.perf_counter() - t
        rows[name] = float(np.median(timings(f, reps)) * 1e3) / per
        print(f"{name:48s} {rows[name]:9.3f} ms   (first call {compile_s[name]:.1f} s)", flush=True)

    act0 = tdct.Actuation(tensions[0], insertions[0])
    measure("cold forward solve", lambda: tdct.solve(robot, act0, load).position)
    for method in ("augmented", "nested"):
        measure(
            f"cold IK, {method}",
            lambda m=method: (
                tdct.inverse_kinematics(robot, tdct.Target(tips[0]), load=load, ik=tdct.IKOptions(method=m)).actuation.tensions
            ),
        )

    @jax.jit
    def forward_path(tensions, insertions):
        def step(guess, a):
            sol = tdct.solve(robot, tdct.Actuation(*a), load, guess=guess, throw=False)
            return sol.base_wrench, sol.tip_position

        return lax.scan(step, jnp.full(6, jnp.nan), (tensions, insertions))[1]

    measure("warm forward path (per update)", lambda: forward_path(tensions, insertions), max(3, repeats // 4), n_path)
    targets = tdct.Target(tips)
    measure(
        "tracking IK path, tdct.track (per update)",
        lambda: tdct.track(robot, targets, load=load, guess=act0).actuation.tensions,
        max(3, repeats // 4),
        n_path,
    )
    tracked = tdct.track(robot, targets, load=load, guess=act0)
    steps, chords = (np.asarray(a)[1:] for a in (tracked.iterations, tracked.chord_steps))  # the first update is cold
    tracking_steps = dict(
        median=float(np.median(steps)),
        mean=float(steps.mean()),
        max=int(steps.max()),
        jacobian_passes_mean=float((steps - chords).mean()),
    )
    print(f"tracking IK steps per warm update: {tracking_steps}")

    rng = np.random.default_rng(0)
    batch = {
        "tensions": rng.uniform(0, 8, (n_batch, 4)) * (rng.random((n_batch, 4)) < 0.5),
        "insertion": rng.uniform(0, 0.16, n_batch),
    }
    forward = tdct.sweep(robot, tdct.Actuation(), load, batch=batch, progress=False)
    measure(
        "batched forward solves (per point)",
        lambda: tdct.sweep(robot, tdct.Actuation(), load, batch=batch, progress=False).tip_position,
        3,
        n_batch,
    )
    measure(
        "batched IK (per target)",
        lambda: tdct.inverse_kinematics(robot, tdct.Target(forward.tip_position), load=load, throw=False).position_error,
        3,
        n_batch,
    )

    ratios = dict(
        tracking_over_warm_forward=rows["tracking IK path, tdct.track (per update)"] / rows["warm forward path (per update)"],
        cold_ik_over_cold_forward=rows["cold IK, augmented"] / rows["cold forward solve"],
        nested_over_augmented=rows["cold IK, nested"] / rows["cold IK, augmented"],
        batched_ik_over_batched_forward=rows["batched IK (per target)"] / rows["batched forward solves (per point)"],
    )
    for k, v in ratios.items():
        print(f"{k:40s} {v:6.2f}")
    write_result(
        out,
        quick=args.quick,
        load=os.getloadavg(),
        steps_per_segment=tdct.SolverOptions().steps,
        path_updates=n_path,
        batch=n_batch,
        median_ms=rows,
        first_call_s=compile_s,
        tracking_steps_per_update=tracking_steps,
        ratios=ratios,
        goals=dict(tracking_update_ms=0.5, tracking_over_warm_forward=1.5, cold_ik_over_cold_forward=3.0),
    )
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
