"""Runs every benchmark, each in a fresh process, and writes a summary of their results.

Run: python benchmarks/run_all.py [--quick]
Each script writes its own benchmarks/results/<name>.json (<name>_quick.json with --quick); this
one adds results/summary.md (summary_quick.md) with the headline table: each speed figure beside
the tip error it was measured at. It fails only when a script fails (a crash or a disagreement
between solvers), never on speed.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).parent
RESULTS = HERE / "results"
SCRIPTS = (
    ("solve_latency.py", {}),
    ("accuracy_steps.py", {}),
    ("baseline.py", {}),
    ("compliance_autodiff_vs_fd.py", {}),
    ("trajectory.py", {}),
    ("peer_pyelastica.py", {}),  # writes nothing without the peer extra
    ("sweep_throughput.py", {}),  # one device, then one per core
    ("durable_sweep.py", {}),
    ("ik.py", {}),
    ("dynamics_speed.py", {}),  # about 30 s quick; the full run is long (compiles per step length)
    ("gpu_throughput.py", {}),  # writes nothing where JAX sees no GPU
)
"""(script, extra environment) in the order they run."""


def _load(name: str, suffix: str) -> dict | None:
    path = RESULTS / f"{name}{suffix}.json"
    return json.loads(path.read_text()) if path.exists() else None


def _table(header: tuple, rows: list) -> list[str]:
    """A markdown table and the blank line after it."""
    cells = [f"| {' | '.join(map(str, row))} |" for row in (header, *rows)]
    return [cells[0], "|" + "---|" * len(header), *cells[1:], ""]


def summary(suffix: str, seconds: dict) -> str:
    """The headline table in markdown, from the results files of one run."""
    lines = [f"# Benchmark summary{' (quick)' if suffix else ''}", ""]
    latency, accuracy, base = _load("latency", suffix), _load("accuracy_steps", suffix), _load("baseline", suffix)
    compliance, sweep = _load("compliance", suffix), _load("sweep_throughput", suffix)
    trajectory = _load("trajectory", suffix)
    peer = _load("peer_pyelastica", suffix)
    gpu = _load("gpu_throughput", suffix)
    errors = {r["steps_per_segment"]: r["max_tip_error_um"] for r in accuracy["rows"]} if accuracy else {}

    def accuracy_at(steps) -> str:
        return f"{errors[steps]:.2g} um" if steps in errors else "see accuracy_steps"

    if latency:
        lines += [f"Measured {latency['date']} on {latency['machine']}, jax {latency['jax']}.", ""]
    if base:
        lines += _table(
            ("configuration", "steps", "tip difference vs tdct_jax", "numpy/scipy solve", "tdct_jax solve", "ratio"),
            [
                (
                    r["config"],
                    r["steps"],
                    f"{r['tip_relative_difference']:.1e} rel.",
                    f"{r['baseline_solve_ms']:.0f} ms",
                    f"{r['tdct_jax_solve_ms']:.1f} ms",
                    f"{r['solve_ratio']:.0f}x",
                )
                for r in base["configs"]
            ],
        )
    if accuracy:
        lines += _table(
            ("steps per segment", "max tip error over the envelope", "warm solve (median)"),
            [
                (r["steps_per_segment"], f"{r['max_tip_error_um']:.2e} um", f"{r['solve_median_ms']:.2f} ms")
                for r in accuracy["rows"]
            ],
        )
        n = sum(accuracy["configurations"].values())
        lines += [
            f"Fewest steps per segment with every tip within {accuracy['target_um']:g} um of the "
            f"{accuracy['reference_steps_per_segment']}-step reference over the {n:,} envelope configurations: "
            f"{accuracy['recommended_steps_per_segment']}.",
            "",
        ]
    if latency:
        lines += _table(
            ("configuration", "warm solve median", "p90", "tip error at this step count"),
            [
                (r["config"], f"{r['median_ms']:.1f} ms", f"{r['p90_ms']:.1f} ms", accuracy_at(latency["steps_per_segment"]))
                for r in latency["configs"]
            ],
        )
        lines += [f"Compile and first solve: {latency['compile_and_first_solve_s']:.1f} s.", ""]
    if compliance:
        lines += _table(
            ("configuration", "exact compliance", "solve", "ratio", "best central differences vs exact"),
            [
                (
                    r["config"],
                    f"{r['autodiff_ms']:.1f} ms",
                    f"{r['solve_ms']:.1f} ms",
                    f"{r['autodiff_over_solve']:.2f}x",
                    f"{r['best_fd_error']:.1e} rel.",
                )
                for r in compliance["configs"]
            ],
        )
    if peer:
        pe, tj = peer["pyelastica"], peer["tdct_jax"]
        lines += _table(
            (f"cantilever, {1e3 * peer['force_N']:g} mN tip force, no gravity", "time", "tip deflection error vs exact"),
            [
                (
                    f"PyElastica {pe['version']}, damped dynamics to 0.1%",
                    f"{1e3 * pe['best']['time_to_tolerance_s']:.0f} ms",
                    f"{pe['best']['final_relative_error']:.1e}",
                ),
                ("tdct_jax static solve (warm)", f"{tj['median_ms']:.2f} ms", f"{tj['relative_error']:.1e}"),
            ],
        )
    if trajectory:
        lines += _table(
            (f"{trajectory['trajectory_steps']}-step trajectory", "per update", "p90", "Newton iterations", "tip error"),
            [
                (
                    r["method"],
                    f"{r['median_ms']:.2f} ms",
                    "-" if r["p90_ms"] is None else f"{r['p90_ms']:.2f} ms",
                    f"{r['mean_iterations']:.2f}",
                    accuracy_at(trajectory["steps_per_segment"]),
                )
                for r in trajectory["rows"]
            ],
        )
    if sweep:
        lines += [f"Sweeps, the batch engine against a plain vmap of the single solve (load {sweep['load_average_1min']}):", ""]
        lines += _table(
            ("CPU devices", "batch", "failing", "engine solves/s", "plain solves/s", "ratio (median of pairs)", "peak memory"),
            [
                (
                    r["devices"],
                    r["batch"],
                    f"{r['failing']:.0%}",
                    f"{r['engine_solves_per_s']:.0f}",
                    f"{r['plain_solves_per_s']:.0f}",
                    f"{r['speedup']:.2f}x",
                    f"{r['peak_rss_mb']:.0f} MB",
                )
                for r in sweep["rows"]
                if r["kind"] == "batch"
            ],
        )
        if sweep.get("outputs"):
            lines += _table(
                ("engine output (one device)", "solves/s", "tips only", "cost against tips only (median of pairs)"),
                [
                    (
                        r["output"],
                        f"{r['with_output_solves_per_s']:.0f}",
                        f"{r['tips_solves_per_s']:.0f}",
                        f"{r['cost_ratio']:.2f}x",
                    )
                    for r in sweep["outputs"]
                ],
            )
    ik = _load("ik", suffix)
    if ik:
        lines += [f"Inverse kinematics against the forward solve ({ik['date']}, load {ik['load'][0]:.1f}):", ""]
        lines += _table(("what", "median"), [(k, f"{v:.3f} ms") for k, v in ik["median_ms"].items()])
        lines += _table(("ratio", "measured", "goal"), [(k, f"{v:.2f}", ik["goals"].get(k, "")) for k, v in ik["ratios"].items()])
    dynamics = _load("dynamics_speed", suffix)
    if dynamics:
        lines += [f"`tdct.simulate`, a tendon pulled in 0.1 s (load {dynamics['load_average'][0]:.1f}):", ""]
        lines += _table(
            (
                "robot",
                "dt",
                "RK4 steps",
                "intervals",
                "Newton tol",
                "per time step",
                "real-time factor",
                "chord/Newton steps",
                "tip vs reference",
                "compile",
            ),
            [
                (
                    r["robot"],
                    f"{r['dt_ms']:g} ms",
                    r["rk4_steps"],
                    r.get("intervals", 1),
                    f"{r['newton_tol']:.0e}",
                    f"{r['ms_per_time_step']:.2f} ms",
                    f"{r['real_time_factor']:.2f}x",
                    f"{r['mean_newton_steps']:.2f}",
                    "-" if r["max_tip_error_um"] is None else f"{r['max_tip_error_um']:.1f} um",
                    f"{r['compile_s']:.1f} s",
                )
                for r in dynamics["rows"]
                if dynamics["quick"]
                or r.get("working")
                or r["rk4_steps"] != 20
                or r["newton_tol"] != 1e-10
                or r.get("intervals") == 1
            ],
        )
    if gpu:
        lines += [f"On the GPU ({gpu['device']}, {gpu['date']}, jax {gpu['jax']}, {gpu['steps']} steps):", ""]
        lines += _table(
            ("sweep", "points", "lanes per call", "solves/s", "compile", "peak GPU memory", "peak host memory", "failed"),
            [
                (
                    r["kind"],
                    r["points"],
                    r["lanes"],
                    f"{r['solves_per_s']:,.0f}",
                    f"{r['compile_s']:.1f} s",
                    "-" if r["peak_device_bytes"] is None else f"{r['peak_device_bytes'] / 2**20:,.0f} MiB",
                    "-" if r["peak_host_bytes"] is None else f"{r['peak_host_bytes'] / 2**20:,.0f} MiB",
                    r["failed"],
                )
                for r in gpu["rows"]
            ],
        )
        if gpu["cpu_agreement"]:
            lines += [f"Tips against the CPU's: {gpu['cpu_agreement']['max_tip_difference_m']:.1e} m at most.", ""]
    if seconds:
        lines += ["Script times: " + ", ".join(f"{k} {v:.0f} s" for k, v in seconds.items()), ""]
    return "\n".join(lines)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="every script in its quick mode (a few minutes in all)")
    args = parser.parse_args()
    suffix = "_quick" if args.quick else ""
    seconds = {}
    for script, env in SCRIPTS:
        name = " ".join([*(f"{k}={v}" for k, v in env.items()), script])
        print(f"== {name}", flush=True)
        start = time.perf_counter()
        command = [sys.executable, str(HERE / script), *(["--quick"] if args.quick else [])]
        done = subprocess.run(command, cwd=HERE, env={**os.environ, **env})
        seconds[name] = time.perf_counter() - start
        if done.returncode:
            print(f"run_all: {name} failed with exit code {done.returncode}", file=sys.stderr)
            return 1
    text = summary(suffix, seconds)
    (RESULTS / f"summary{suffix}.md").write_text(text)
    print(text)
    print(f"total {sum(seconds.values()):.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
