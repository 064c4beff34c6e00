"""Tip accuracy and cost against the number of RK4 steps: the table the default step count comes from.

The operating envelope, sampled two ways: random configurations (0-10 N on random tendon subsets,
0-160 mm of tube, tip forces up to 0.5 N in any direction, gravity on) and a stressed set that
holds the hardest cases found so far, high tension on one or two neighbouring tendons with a
compressive tip force (a tip force with a negative z component). At each step count the tip is
compared with a solution many times finer; the table reports the worst and the median error, a
high percentile and how many points exceed 0.2 and 1 um, and the worst points themselves. Beside
each row: the warm single-solve latency at that step count (the Fig. 6 configuration, median).
Last, how far the tips move with one more Newton step on the constitutive relations than the
default (full run only, on the first 512 points).

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
"""The default step count keeps the tip within 1 micrometre of the converged solution."""


def envelope(n: int, seed: int = 0) -> dict:
    """Random configurations over the operating envelope."""
    rng = np.random.default_rng(seed)
    tensions = rng.uniform(0, 10, (n, 4)) * (rng.random((n, 4)) < 0.5)
    direction = rng.normal(size=(n, 3))
    force = direction / np.linalg.norm(direction, axis=1, keepdims=True) * rng.uniform(0, 0.5, (n, 1))
    return {"tensions": tensions, "insertion": rng.uniform(0, 0.16, n), "force": force}


def stressed(n: int, seed: int = 1) -> dict:
    """High tension (7-10 N) on one tendon or two neighbouring ones, and a compressive tip force
    (z component -0.1 to -0.5 N, any lateral part, at most 0.5 N): the slowest to converge."""
    rng = np.random.default_rng(seed)
    tensions = np.zeros((n, 4))
    first = rng.integers(0, 4, n)
    tensions[np.arange(n), first] = rng.uniform(7, 10, n)
    pair = rng.random(n) < 0.5
    tensions[np.arange(n)[pair], (first[pair] + 1) % 4] = rng.uniform(5, 10, pair.sum())
    fz = -rng.uniform(0.1, 0.5, n)
    lateral = rng.normal(size=(n, 2))
    room = np.sqrt(np.maximum(0.5**2 - fz**2, 0.0)) * rng.random(n)
    lateral *= (room / np.linalg.norm(lateral, axis=1))[:, None]
    force = np.column_stack([lateral, fz])
    return {"tensions": tensions, "insertion": rng.uniform(0, 0.16, n), "force": force}


def tips(robot, batch, steps):
    """Tip positions and whether each converged, at ``steps`` RK4 steps per segment."""
    res = tdct.sweep(robot, batch=batch, solver=tdct.SolverOptions(steps=steps), progress=False, throw=False)
    return res.tip_position, res.converged


def constitutive_newton_effect(robot, batch) -> float:
    """How far [um] the tips move with one more Newton step on the constitutive relations than the
    default segments.NEWTON_STEPS, at the default step count (two recompiles)."""
    default = segments.NEWTON_STEPS
    by_newton = {}
    for k in (default + 1, default):  # ends on the default
        segments.NEWTON_STEPS = k
        jax.clear_caches()
        by_newton[k] = tips(robot, batch, STEPS)[0]
    um = float(np.nanmax(np.linalg.norm(by_newton[default + 1] - by_newton[default], axis=1)) * 1e6)
    print(f"constitutive Newton steps {default} -> {default + 1}: tips move by at most {um:.1e} um")
    return um


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="8 configurations, steps 8..50, fewer repeats")
    args = parser.parse_args()
    out = Path(__file__).parent / "results" / f"accuracy_steps{'_quick' if args.quick else ''}.json"

    robot = tdct.Robot.paper()
    if args.quick:
        n_random, n_stressed, steps_list, reference_steps, repeats = 48, 16, (8, 16, 25), 200, 10
    else:
        n_random, n_stressed, steps_list, reference_steps, repeats = 2000, 500, (8, 12, 16, 20, 25, 32, 50), 400, 40
    sets = {"random": envelope(n_random), "stressed": stressed(n_stressed)}
    batch = {k: np.concatenate([sets["random"][k], sets["stressed"][k]]) for k in sets["random"]}
    kind = np.array(["random"] * n_random + ["stressed"] * n_stressed)
    start = time.perf_counter()
    reference, ok = tips(robot, batch, reference_steps)
    print(f"reference: {len(kind)} configurations at {reference_steps} steps per segment ({time.perf_counter() - start:.0f} s)")

    act, load = tdct.Actuation((6.0, 0, 0, 0), 0.080), tdct.Loads.from_mass(0.020)
    rows, worst = [], []
    for steps in steps_list:
        tip, converged = tips(robot, batch, steps)
        both = ok & converged
        err = np.linalg.norm(tip - reference, axis=1)[both]
        tdct.solve(robot, act, load, solver=tdct.SolverOptions(steps=steps))
        solve_ms = 1e3 * timings(
            lambda steps=steps: tdct.solve(robot, act, load, solver=tdct.SolverOptions(steps=steps)).position, repeats
        )
        by_kind = {k: float(err[kind[both] == k].max() * 1e6) for k in sets}
        rows.append(
            dict(
                steps_per_segment=steps,
                total_steps=2 * steps,
                points=int(both.sum()),
                not_converged=int((~converged).sum()),
                max_tip_error_um=float(err.max() * 1e6),
                max_tip_error_um_by_set=by_kind,
                p99_9_tip_error_um=float(np.percentile(err, 99.9) * 1e6),
                median_tip_error_um=float(np.median(err) * 1e6),
                points_above_1_um=int((err > 1e-6).sum()),
                points_above_0_2_um=int((err > 0.2e-6).sum()),
                solve_median_ms=float(np.median(solve_ms)),
            )
        )
        r = rows[-1]
        print(
            f"steps {steps:4d} per segment: tip error max {r['max_tip_error_um']:.3g} um (random {by_kind['random']:.3g}, "
            f"stressed {by_kind['stressed']:.3g}), 99.9% {r['p99_9_tip_error_um']:.3g} um, median {r['median_tip_error_um']:.2g} um, "
            f"{r['points_above_1_um']} above 1 um, {r['points_above_0_2_um']} above 0.2 um; warm solve {r['solve_median_ms']:.1f} ms",
            flush=True,
        )
        if steps == STEPS:
            index = np.flatnonzero(both)[np.argsort(err)[::-1][:5]]
            worst = [
                dict(
                    set=str(kind[i]),
                    tensions_N=batch["tensions"][i].round(3).tolist(),
                    insertion_mm=round(1e3 * float(batch["insertion"][i]), 2),
                    tip_force_N=batch["force"][i].round(4).tolist(),
                    tip_error_um=float(np.linalg.norm(tip[i] - reference[i]) * 1e6),
                )
                for i in index
            ]
    newton_um = None if args.quick else constitutive_newton_effect(robot, {k: v[:512] for k, v in batch.items()})
    within = [r["steps_per_segment"] for r in rows if r["max_tip_error_um"] * 1e-6 <= TARGET_M]
    recommended = min(within) if within else None
    print(f"fewest steps per segment with every tip within {TARGET_M * 1e6:g} um over the envelope: {recommended}")
    write_result(
        out,
        quick=args.quick,
        configurations=dict(random=n_random, stressed=n_stressed),
        reference_steps_per_segment=reference_steps,
        reference_not_converged=int((~ok).sum()),
        target_um=TARGET_M * 1e6,
        default_steps_per_segment=STEPS,
        recommended_steps_per_segment=recommended,
        worst_at_default=worst,
        constitutive_newton_steps=segments.NEWTON_STEPS,
        tip_change_with_one_more_constitutive_step_um=newton_um,
        rows=rows,
    )
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
