"""Sweep throughput: the batch engine against a plain vmap of the single solve, side by side.

Run: python benchmarks/sweep_throughput.py [--quick] [--robots [--base PATH]]
The process splits the CPU into one JAX device per core (JAX_NUM_CPU_DEVICES, unless already set).
For one device and for all of them, each batch size, and 0% or 1% failing points (400 N with no
tube: the residual stops being finite), it times the engine (``tdct.sweep`` as shipped: a Broyden
first pass, then stragglers and failures solved again apart by the full solver) and the plain path
(``batch.FIRST_PASS = None``: every chunk one vmap of the full single solve) alternately,
``--repeats`` times each, and records both medians and the median of the pair-by-pair ratios; the
first call of each (compile included) is reported apart. Both see the same random envelope points
(tensions 0-10 N on tendon 1 and, for 30% of the points, tendon 4; insertions 0-160 mm; tip masses
0-50 g). Then the engine's chunk size on one device and on all, and its cost with shapes or the compliance
requested against tips only (one device). Each row also records the largest tip
difference between the two over the converged points, whether their result codes agree, and the
process's peak resident memory so far. Writes benchmarks/results/sweep_throughput[_quick].json.

With ``--robots`` it measures instead, on one device, the engine's throughput for the paper robot
(``Robot.paper()``) and for the two-segment six-tendon robot (robots/two_segment.toml: random
tensions 0-1.5 N on each tendon, tip masses 0-5 g), alternately. With ``--base PATH`` (a copy of
an earlier tdct_jax renamed ``tdct_base``, in PATH) that version's paper-robot sweep (its own API:
``tdct_base.Robot()``) joins the rounds on the same envelope points, with its largest tip
difference from today's (issue 23: the one description must not slow the paper robot). Writes
benchmarks/results/sweep_robots[_quick].json.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
import time
from pathlib import Path

import jax
import numpy as np
from _common import peak_rss_mb, write_result

import tdct_jax as tdct
from tdct_jax import batch
from tdct_jax.description import ROBOTS

ENGINE_FIRST_PASS = batch.FIRST_PASS


def envelope(n: int, failing: float = 0.0, seed: int = 0) -> dict:
    """n random points over the operating envelope; a fraction ``failing`` of them, spread evenly,
    at 400 N with no tube."""
    rng = np.random.default_rng(seed)
    tensions = np.zeros((n, 4))
    tensions[:, 0], tensions[:, 3] = rng.uniform(0, 10, n), rng.uniform(0, 10, n) * (rng.random(n) < 0.3)
    insertion = rng.uniform(0, 0.16, n)
    bad = np.linspace(0, n - 1, int(round(failing * n))).astype(int)
    tensions[bad], insertion[bad] = (400.0, 0, 0, 0), 0.0
    return {"tensions": tensions, "insertion": insertion, "tip_mass": rng.uniform(0, 0.05, n)}


def sweep(robot, points, first_pass, **options):
    batch.FIRST_PASS = first_pass
    try:
        return tdct.sweep(robot, batch=points, progress=False, throw=False, **options)
    finally:
        batch.FIRST_PASS = ENGINE_FIRST_PASS


def timed(robot, points, repeats: int, variants: dict) -> tuple[dict, dict, dict]:
    """Each variant (name -> (first_pass, sweep options)) on the same points, alternately:
    first-call seconds, the repeats' seconds and the results, by name."""
    first, times, results = {}, {name: [] for name in variants}, {}
    for name, (fp, options) in variants.items():
        t = time.perf_counter()
        results[name] = sweep(robot, points, fp, **options)
        first[name] = time.perf_counter() - t
    for _ in range(repeats):
        for name, (fp, options) in variants.items():
            t = time.perf_counter()
            sweep(robot, points, fp, **options)
            times[name].append(time.perf_counter() - t)
    return first, times, results


def side_by_side(robot, points, repeats: int, **options) -> dict:
    """The engine and the plain path on the same points, alternately."""
    variants = {"engine": (ENGINE_FIRST_PASS, options), "plain": (None, options)}
    first, times, results = timed(robot, points, repeats, variants)
    n = len(points["insertion"])
    e, p = results["engine"], results["plain"]
    ok = e.converged & p.converged
    return dict(
        points=n,
        engine_solves_per_s=n / float(np.median(times["engine"])),
        plain_solves_per_s=n / float(np.median(times["plain"])),
        speedup=float(np.median(np.array(times["plain"]) / np.array(times["engine"]))),
        engine_first_call_s=first["engine"],
        plain_first_call_s=first["plain"],
        failed=int(e.n_failed),
        same_result_codes=bool(np.array_equal(e.result, p.result)),
        max_tip_difference_m=float(np.max(np.abs(e.tip_position[ok] - p.tip_position[ok]))) if ok.any() else None,
        engine_mean_iterations=float(e.iterations.mean()),
        plain_mean_iterations=float(p.iterations.mean()),
        peak_rss_mb=peak_rss_mb(),
    )


def output_cost(robot, points, repeats: int, devices) -> list[dict]:
    """The engine's cost with shapes or the compliance requested, against tips only, alternately."""
    rows = []
    for extra in ("shapes", "compliance"):
        variants = {
            "tips": (ENGINE_FIRST_PASS, dict(devices=devices)),
            extra: (ENGINE_FIRST_PASS, {extra: True, "devices": devices}),
        }
        _, times, _ = timed(robot, points, repeats, variants)
        n = len(points["insertion"])
        rows.append(
            dict(
                output=extra,
                devices=len(devices),
                batch=n,
                tips_solves_per_s=n / float(np.median(times["tips"])),
                with_output_solves_per_s=n / float(np.median(times[extra])),
                cost_ratio=float(np.median(np.array(times[extra]) / np.array(times["tips"]))),
            )
        )
        print(rows[-1], flush=True)
    return rows


def robot_sweeps(n: int, repeats: int, device, base_path: str | None) -> list[dict]:
    """The paper robot's sweep, the two-segment robot's, and with ``base_path`` an earlier
    version's paper-robot sweep (its former API), on the same points, alternately."""
    paper = envelope(n)
    rng = np.random.default_rng(1)
    two = {"tensions": rng.uniform(0, 1.5, (n, 6)), "tip_mass": rng.uniform(0, 0.005, n)}
    options = dict(progress=False, throw=False, devices=[device])
    runs = {
        "Robot.paper()": lambda: tdct.sweep(tdct.Robot.paper(), batch=paper, **options),
        "two_segment.toml": lambda: tdct.sweep(tdct.Robot.from_toml(ROBOTS / "two_segment.toml"), batch=two, **options),
    }
    if base_path:
        sys.path.insert(0, base_path)
        old = importlib.import_module("tdct_base")
        runs = {"base Robot": lambda: old.sweep(old.Robot(), batch=paper, **options)} | runs
    first, results, times = {}, {}, {name: [] for name in runs}
    for name, run in runs.items():
        t = time.perf_counter()
        results[name] = run()
        first[name] = time.perf_counter() - t
    for r in range(repeats):
        for name in list(runs)[:: 1 if r % 2 else -1]:
            t = time.perf_counter()
            runs[name]()
            times[name].append(time.perf_counter() - t)
    tips = results["Robot.paper()"].tip_position
    rows = []
    for name, res in results.items():
        row = dict(robot=name, points=n, solves_per_s=n / float(np.median(times[name])), first_call_s=first[name])
        row |= dict(failed=int(res.n_failed), mean_iterations=float(res.iterations.mean()))
        if name != "two_segment.toml":
            row["max_tip_difference_from_Robot_m"] = float(np.max(np.abs(res.tip_position - tips)))
        rows.append(row)
        print(row, flush=True)
    return rows


def load() -> str:
    return Path("/proc/loadavg").read_text().split()[0] if Path("/proc/loadavg").exists() else "?"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="one batch size, two chunk sizes, one repeat")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--robots", action="store_true", help="Robot.paper() and two_segment.toml sweeps")
    parser.add_argument("--base", help="with --robots: folder holding an earlier tdct_jax copied as package tdct_base")
    args = parser.parse_args()
    if "JAX_NUM_CPU_DEVICES" not in os.environ:  # before JAX starts its backend
        jax.config.update("jax_num_cpu_devices", os.cpu_count() or 1)
    repeats = 1 if args.quick else args.repeats
    if args.robots:
        load_before = load()
        rows = robot_sweeps(256 if args.quick else 1024, repeats, jax.devices()[0], args.base)
        write_result(
            Path(__file__).parent / "results" / f"sweep_robots{'_quick' if args.quick else ''}.json",
            steps=tdct.SolverOptions().steps,
            first_pass=ENGINE_FIRST_PASS,
            repeats=repeats,
            load_average_1min=[load_before, load()],
            rows=rows,
        )
        return
    robot = tdct.Robot.paper()
    devices = jax.devices()
    device_sets = [devices[:1]] + ([devices] if len(devices) > 1 else [])
    batches = (128,) if args.quick else (256, 1024, 4096)
    failing_batch = 128 if args.quick else 512  # the plain path crawls through failures: a smaller batch
    chunks = (64, 256) if args.quick else (32, 64, 128, 256, 512)
    load_before = load()

    rows = []
    for devs in device_sets:
        for b, failing in [(b, 0.0) for b in batches] + [(failing_batch, 0.01)]:
            rec = side_by_side(robot, envelope(b, failing), repeats, devices=devs)
            rows.append(dict(kind="batch", devices=len(devs), batch=b, failing=failing, chunk=None, **rec))
            print(rows[-1], flush=True)
    chunk_batch = 256 if args.quick else 2048
    for devs in device_sets:
        for c in chunks:
            rec = side_by_side(robot, envelope(chunk_batch), repeats, devices=devs, chunk_size=c)
            rows.append(dict(kind="chunk", devices=len(devs), batch=chunk_batch, failing=0.0, chunk=c, **rec))
            print(rows[-1], flush=True)

    outputs = output_cost(robot, envelope(chunk_batch), repeats, devices[:1])

    name = f"sweep_throughput{'_quick' if args.quick else ''}.json"
    write_result(
        Path(__file__).parent / "results" / name,
        steps=tdct.SolverOptions().steps,
        first_pass=ENGINE_FIRST_PASS,
        default_chunks=batch.CHUNK_SIZES,
        repeats=repeats,
        load_average_1min=[load_before, load()],
        rows=rows,
        outputs=outputs,
    )
    print(f"{'kind':<6} {'dev':>3} {'batch':>6} {'fail':>5} {'chunk':>5} {'engine/s':>9} {'plain/s':>8} {'ratio':>6} tip diff")
    for r in rows:
        diff = "-" if r["max_tip_difference_m"] is None else f"{r['max_tip_difference_m']:.1e}"
        print(
            f"{r['kind']:<6} {r['devices']:>3} {r['batch']:>6} {r['failing']:>5.0%} {r['chunk'] or '-':>5}"
            f" {r['engine_solves_per_s']:>9.0f} {r['plain_solves_per_s']:>8.0f} {r['speedup']:>6.2f} {diff}"
        )
    for r in outputs:
        print(
            f"with {r['output']}: {r['with_output_solves_per_s']:.0f} solves/s against {r['tips_solves_per_s']:.0f}, {r['cost_ratio']:.2f}x"
        )


if __name__ == "__main__":
    main()
