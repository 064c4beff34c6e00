"""Sweep throughput: solves per second against batch size and chunk size, with and without warm starts.

Run: python benchmarks/sweep_throughput.py [--quick]
Writes benchmarks/results/sweep_throughput.json (and _quick.json with --quick). Run with
JAX_NUM_CPU_DEVICES=K in the environment, JAX splits the CPU into K devices and every chunk is
sharded over them, so K cores work on a sweep (results in sweep_throughput_cpuK[_quick].json). Each figure is
the median of ``--repeats`` warm sweeps (compile excluded and reported separately); the envelope
is random tensions (0-10 N on tendon 1 and 4), insertions (0-160 mm) and tip masses (0-50 g).
Each row also records the process's peak resident memory so far (batches run smallest first).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import jax
import numpy as np
from _common import peak_rss_mb, write_result

import tdct_jax as tdct
from tdct_jax.batch import CHUNK_SIZES, lanes_per_call

STEPS = tdct.SolverOptions().steps
DEFAULT_CHUNK = CHUNK_SIZES["cpu"]


def envelope(n: int, seed: int = 0) -> dict:
    rng = np.random.default_rng(seed)
    tensions = np.zeros((n, 4))
    tensions[:, 0], tensions[:, 3] = rng.uniform(0, 10, n), rng.uniform(0, 10, n) * (rng.random(n) < 0.3)
    return {"tensions": tensions, "insertion": rng.uniform(0, 0.16, n), "tip_mass": rng.uniform(0, 0.05, n)}


def measure(run, repeats: int, first: bool = True) -> dict:
    """The first call (compile included; skipped when an earlier sweep compiled the same chunk
    size) and the median of ``repeats`` warm sweeps."""
    first_s = float("nan")
    if first:
        t = time.perf_counter()
        run()
        first_s = time.perf_counter() - t
    times, failed = [], 0
    for _ in range(repeats):
        t = time.perf_counter()
        res = run()
        times.append(time.perf_counter() - t)
        failed += res.n_failed
    n = int(np.prod(res.shape))
    median = float(np.median(times))
    return dict(
        points=n,
        first_call_s=first_s,
        median_s=median,
        solves_per_s=n / median,
        failed=failed,
        newton_iterations=int(res.iterations.sum()),
        peak_rss_mb=peak_rss_mb(),  # the process's, so far
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="batches up to 256, two chunk sizes, one repeat")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    devices = jax.device_count()
    repeats = 1 if args.quick else args.repeats
    robot = tdct.Robot()
    batches = (1, 16, 256) if args.quick else (1, 10, 100, 1000, 10000)
    chunks = (16, 64) if args.quick else (16, 64, 256, 1024)
    chunk_batch = 256 if args.quick else 512

    rows = []
    for b in batches:
        # 10,000 reuses the chunk size 1,000 compiled: no first call; large batches are timed once.
        rec = measure(
            lambda b=b: tdct.sweep(robot, batch=envelope(b), progress=False), 1 if b >= 1000 else repeats, first=b < 10000
        )
        rows.append(dict(kind="batch", batch=b, chunk=lanes_per_call(b, DEFAULT_CHUNK, devices), **rec))
        print(rows[-1], flush=True)
    for c in chunks:
        rec = measure(lambda c=c: tdct.sweep(robot, batch=envelope(chunk_batch), chunk_size=c, progress=False), 1)
        rows.append(dict(kind="chunk", batch=chunk_batch, chunk=c, **rec))
        print(rows[-1], flush=True)
    # Warm starts: paths of increasing tension (the last grid axis), one per insertion.
    n_paths, n_steps = (8, 6) if args.quick else (32, 16)
    grid = {"insertion": np.linspace(0, 0.16, n_paths), "tensions": np.outer(np.linspace(0, 10, n_steps), [1.0, 0, 0, 0])}
    for warm in (False, True):
        rec = measure(lambda w=warm: tdct.sweep(robot, grid=grid, warm_start=w, progress=False), 1)
        chunk = n_paths if warm else lanes_per_call(n_paths * n_steps, DEFAULT_CHUNK)
        rows.append(dict(kind="warm start" if warm else "cold start", batch=n_paths * n_steps, chunk=chunk, **rec))
        print(rows[-1], flush=True)
    name = f"sweep_throughput{f'_cpu{devices}' if devices > 1 else ''}{'_quick' if args.quick else ''}.json"
    write_result(Path(__file__).parent / "results" / name, steps=STEPS, repeats=repeats, devices=devices, rows=rows)
    print(f"{'kind':<11} {'batch':>6} {'chunk':>6} {'solves/s':>9} {'first call s':>12} {'iterations':>10} failed")
    for r in rows:
        print(
            f"{r['kind']:<11} {r['batch']:>6} {r['chunk']:>6} {r['solves_per_s']:>9.1f} {r['first_call_s']:>12.1f}"
            f" {r['newton_iterations']:>10} {r['failed']}"
        )


if __name__ == "__main__":
    main()
