"""Peer: PyElastica's damped dynamics against tdct_jax's static solve on a tip-loaded cantilever.

Problem: the paper robot tdct_jax.Robot.paper() as a plain silicone cantilever (no tube, no tension, no
gravity) with a 5 mN tip force along -y. Reference: the small-deflection closed form of the rod
both codes discretise (extensible, shearable, no shear coefficient), the Timoshenko cantilever
delta = F L^3 / (3 E I_x) + F L / (G A); the script raises if tdct_jax differs from it by more
than 1e-4 (the geometric nonlinearity at this load is 4e-5).

PyElastica (optional extra "peer"; without it the script says so and exits 0): a
CosseratRod.straight_rod of N_ELEMENTS elements with tdct_jax's area and density, and its
shear_matrix and bend_matrix overwritten with tdct_jax's diag(GA, GA, EA) and
diag(E I_x, E I_y, G (I_x + I_y)); OneEndFixedBC, EndpointForces, AnalyticalLinearDamper,
PositionVerlet at CFL of the axial-wave limit. OneEndFixedBC clamps the whole first element, which
acts as a clamp at its centre and leaves a plain rod 1.5 / n too soft (2.96% at 50 elements), so
the rod is dx / 2 longer and starts at z = -dx / 2 (the plain clamp is run once and reported).
The damping constant is scanned around the critical damping 2 omega_1 of the first bending mode
and the fastest reported: the peer's best case. "Time to 0.1%" is the stepping wall time until
the tip stays within 0.1% of the exact deflection for the rest of the run, an oracle criterion that
favours the peer. numba compiles into a fresh NUMBA_CACHE_DIR (unless set) in a warm-up run,
reported apart, as is the setup.

tdct_jax, in the same process: compile and first solve, the median and p90 of warm solves at the
default steps, and the tip error against the same reference. The ratio is PyElastica's time to
0.1% over tdct_jax's median warm solve.

Run: PYTHONPATH=. python benchmarks/peer_pyelastica.py [--quick] [--out PATH]
Writes benchmarks/results/peer_pyelastica.json (--quick: peer_pyelastica_quick.json; one damping
constant, fewer repeats). Needs the extra: pip install -e ".[peer]".
"""

from __future__ import annotations

import argparse
import importlib.metadata
import os
import shutil
import tempfile
import time
from pathlib import Path

import jax
import numpy as np
from _common import paper_section, timings, write_result

import tdct_jax as tdct

STEPS = tdct.SolverOptions().steps

# numba caches PyElastica's compiled kernels on disk (cache=True), so only the first run after an
# install would show the compile time: compile into a fresh folder unless the user chose one.
FRESH_NUMBA_CACHE = "NUMBA_CACHE_DIR" not in os.environ
if FRESH_NUMBA_CACHE:
    os.environ["NUMBA_CACHE_DIR"] = tempfile.mkdtemp(prefix="peer_pyelastica_numba_")
_t = time.perf_counter()
try:
    import elastica as ea
except ImportError:  # the optional extra "peer"
    ea = None
ELASTICA_IMPORT_S = time.perf_counter() - _t

FORCE = 5e-3
"""Tip force along -y [N]: small enough that the linear closed form is exact to 4e-5."""
TOLERANCE = 1e-3
"""Relative tip-deflection error that counts as settled (0.1%)."""
NONLINEARITY_LIMIT = 1e-4
"""Largest allowed |tdct_jax - closed form| / closed form: above it the closed form is no reference."""
N_ELEMENTS = 50
CFL = 0.8
"""dt as a fraction of the axial-wave limit dx / sqrt(E / rho)."""
SIM_TIME = 2.0
"""Simulated time of each PyElastica run [s]: the tip must stay within TOLERANCE until then."""
CHECK_EVERY = 10
"""PositionVerlet steps between reads of the tip."""
GAMMA_FACTORS = (0.6, 0.7, 0.8, 0.9, 1.0, 1.2)
"""Damping constants scanned, as multiples of 2 omega_1 (critical damping of the first mode)."""
QUICK_GAMMA_FACTOR = 0.9
"""The fastest of GAMMA_FACTORS in the full run (2026-11-23)."""


def section(robot: tdct.Robot) -> dict:
    """tdct_jax's silicone section as floats (SI)."""
    p = paper_section(robot)
    return {k: p[k] for k in ("L", "E", "G", "A", "I_x", "I_y", "rho")}


def exact_deflection(sec: dict, force: float) -> float:
    """Small-deflection tip deflection of the shearable cantilever (Timoshenko, no shear coefficient) [m]."""
    return force * sec["L"] ** 3 / (3 * sec["E"] * sec["I_x"]) + force * sec["L"] / (sec["G"] * sec["A"])


def first_eigenfrequency(sec: dict) -> float:
    """omega_1 of the Euler-Bernoulli cantilever [rad/s]."""
    return 1.8751**2 * np.sqrt(sec["E"] * sec["I_x"] / (sec["rho"] * sec["A"] * sec["L"] ** 4))


if ea is not None:

    class Simulator(ea.BaseSystemCollection, ea.Constraints, ea.Forcing, ea.Damping):
        """A PyElastica simulator with the modules the cantilever uses."""


def element_length(sec: dict, n: int, half_element: bool) -> float:
    """dx: with the clamp at the centre of element 0 the free length L is (n - 1/2) dx."""
    return sec["L"] / (n - 0.5) if half_element else sec["L"] / n


def build(sec: dict, force: float, n: int, dt: float, gamma: float, half_element: bool = True):
    """A finalized PyElastica simulator of the cantilever, and its rod."""
    dx = element_length(sec, n, half_element)
    length = n * dx
    rod = ea.CosseratRod.straight_rod(
        n,
        start=np.array([0.0, 0.0, sec["L"] - length]),  # -dx/2 with the half element, else 0
        direction=np.array([0.0, 0.0, 1.0]),
        normal=np.array([0.0, 1.0, 0.0]),
        base_length=length,
        base_radius=np.sqrt(sec["A"] / np.pi),  # same area, so the same mass per length
        density=sec["rho"],
        youngs_modulus=sec["E"],
        shear_modulus=sec["G"],
    )
    # tdct_jax's stiffnesses exactly (PyElastica's defaults: 27/28 shear coefficient, disc I)
    rod.shear_matrix[:] = 0.0
    rod.bend_matrix[:] = 0.0
    for i, k in enumerate((sec["G"] * sec["A"], sec["G"] * sec["A"], sec["E"] * sec["A"])):
        rod.shear_matrix[i, i, :] = k
    for i, k in enumerate((sec["E"] * sec["I_x"], sec["E"] * sec["I_y"], sec["G"] * (sec["I_x"] + sec["I_y"]))):
        rod.bend_matrix[i, i, :] = k

    sim = Simulator()
    sim.append(rod)
    sim.constrain(rod).using(ea.OneEndFixedBC, constrained_position_idx=(0,), constrained_director_idx=(0,))
    sim.add_forcing_to(rod).using(ea.EndpointForces, np.zeros(3), np.array([0.0, -force, 0.0]), ramp_up_time=dt)
    sim.dampen(rod).using(ea.AnalyticalLinearDamper, uniform_damping_constant=gamma, time_step=dt)
    sim.finalize()
    return sim, rod


def settle(sec: dict, force: float, exact: float, n: int, dt: float, gamma: float, half_element: bool = True) -> dict:
    """One damped run of SIM_TIME: when the tip entered the tolerance for good, and the final error."""
    t = time.perf_counter()
    sim, rod = build(sec, force, n, dt, gamma, half_element)
    setup_s = time.perf_counter() - t

    stepper, sim_t, dt64 = ea.PositionVerlet(), np.float64(0.0), np.float64(dt)
    n_steps = int(np.ceil(SIM_TIME / dt / CHECK_EVERY)) * CHECK_EVERY
    checks, walls, tips = [], [], []
    t0 = time.perf_counter()
    for step in range(1, n_steps + 1):
        sim_t = stepper.step(sim, sim_t, dt64)
        if step % CHECK_EVERY == 0:
            walls.append(time.perf_counter() - t0)
            checks.append(step)
            tips.append(-rod.position_collection[1, -1])
    error = (np.array(tips) - exact) / exact
    outside = np.flatnonzero(~(np.abs(error) <= TOLERANCE))  # NaN counts as outside
    entry = outside[-1] + 1 if outside.size else 0
    settled = entry < len(checks)
    return dict(
        gamma_per_s=gamma,
        settled=bool(settled),
        steps_to_tolerance=int(checks[entry]) if settled else None,
        sim_time_to_tolerance_s=checks[entry] * dt if settled else None,
        time_to_tolerance_s=walls[entry] if settled else None,
        final_relative_error=float(error[-1]),
        final_tip_deflection_mm=float(tips[-1] * 1e3),
        total_steps=n_steps,
        us_per_step=walls[-1] / n_steps * 1e6,
        setup_s=setup_s,
    )


def run_pyelastica(sec: dict, exact: float, n: int, factors, repeats: int) -> dict:
    """Warm-up (numba), a damping scan with repeats, and the plain clamp once."""
    dt = CFL * element_length(sec, n, True) / np.sqrt(sec["E"] / sec["rho"])
    omega_1 = first_eigenfrequency(sec)

    t = time.perf_counter()
    sim, _ = build(sec, FORCE, n, dt, 2 * omega_1)
    stepper, sim_t = ea.PositionVerlet(), np.float64(0.0)
    for _ in range(10):
        sim_t = stepper.step(sim, sim_t, np.float64(dt))
    first_run_s = time.perf_counter() - t
    what = "numba compile into a fresh cache" if FRESH_NUMBA_CACHE else "numba compile or load from NUMBA_CACHE_DIR"
    print(f"PyElastica import {ELASTICA_IMPORT_S:.1f} s, first run ({what}) {first_run_s:.1f} s")

    scan = []
    for factor in factors:
        runs = [settle(sec, FORCE, exact, n, dt, factor * 2 * omega_1) for _ in range(repeats)]
        row = dict(runs[0], gamma_factor=factor)
        if row["settled"]:
            times = [r["time_to_tolerance_s"] for r in runs]
            row.update(time_to_tolerance_s=float(np.median(times)), time_to_tolerance_all_s=times)
        row.update(
            us_per_step=float(np.median([r["us_per_step"] for r in runs])), setup_s=float(np.median([r["setup_s"] for r in runs]))
        )
        scan.append(row)
        print(
            f"  gamma {factor:4.2f} x 2 omega_1 = {row['gamma_per_s']:5.1f} /s: "
            + (
                f"within 0.1% after {row['steps_to_tolerance']} steps ({row['sim_time_to_tolerance_s']:.3f} s simulated), "
                f"{row['time_to_tolerance_s'] * 1e3:.0f} ms wall"
                if row["settled"]
                else "not within 0.1% at the end"
            )
            + f"; final error {row['final_relative_error']:.1e}, {row['us_per_step']:.1f} us/step"
        )
    settled = [r for r in scan if r["settled"]]
    best = min(settled, key=lambda r: r["time_to_tolerance_s"]) if settled else None

    gamma = best["gamma_per_s"] if best else 2 * omega_1
    plain = settle(sec, FORCE, exact, n, CFL * sec["L"] / n / np.sqrt(sec["E"] / sec["rho"]), gamma, half_element=False)
    print(f"  plain clamp (rod from z = 0, no half element): settled error {plain['final_relative_error']:.2e}")
    return dict(
        version=importlib.metadata.version("pyelastica"),
        numba=importlib.metadata.version("numba"),
        n_elements=n,
        clamp="OneEndFixedBC at the centre of element 0 (rod L + dx/2 long, from z = -dx/2)",
        dt_s=dt,
        dt_over_axial_wave_limit=CFL,
        omega_1_rad_s=omega_1,
        sim_time_s=SIM_TIME,
        check_every_steps=CHECK_EVERY,
        repeats=repeats,
        import_s=ELASTICA_IMPORT_S,
        first_run_s=first_run_s,
        numba_cache="fresh (compiled in this run)" if FRESH_NUMBA_CACHE else "NUMBA_CACHE_DIR as set (may be a cache load)",
        scan=scan,
        best=best,
        plain_clamp=plain,
    )


def run_tdct(robot: tdct.Robot, exact: float, repeats: int) -> dict:
    """Compile + first solve, warm solve latency, and the tip error against the closed form."""
    act, load = tdct.Actuation(), tdct.Loads(tip_force=(0.0, -FORCE, 0.0))

    def solve():
        return tdct.solve(robot, act, load, gravity=None)

    t = time.perf_counter()
    sol = solve()
    jax.block_until_ready(sol.position)
    compile_s = time.perf_counter() - t
    tip = np.asarray(sol.tip_position)
    error = (-tip[1] - exact) / exact
    if not bool(sol.converged):
        raise RuntimeError(f"tdct_jax did not converge on the cantilever (residual {float(sol.residual_norm):.1e})")
    if not abs(error) <= NONLINEARITY_LIMIT:
        raise AssertionError(
            f"tdct_jax's tip deflection {-tip[1] * 1e3:.6f} mm differs from the closed form {exact * 1e3:.6f} mm by {error:.1e} "
            f"relative > {NONLINEARITY_LIMIT:g}: geometric nonlinearity, reduce FORCE"
        )
    times = timings(lambda: solve().position, repeats)
    return dict(
        steps_per_segment=STEPS,
        compile_and_first_solve_s=compile_s,
        repeats=repeats,
        median_ms=float(np.median(times) * 1e3),
        p90_ms=float(np.percentile(times, 90) * 1e3),
        newton_iterations=int(sol.iterations),
        residual_norm=float(sol.residual_norm),
        tip_deflection_mm=float(-tip[1] * 1e3),
        tip_position_mm=(tip * 1e3).round(6).tolist(),
        relative_error=float(error),
    )


def main(quick: bool, out: str | None = None) -> None:
    try:
        _main(quick, out)
    finally:
        if FRESH_NUMBA_CACHE:
            shutil.rmtree(os.environ["NUMBA_CACHE_DIR"], ignore_errors=True)


def _main(quick: bool, out: str | None) -> None:
    if ea is None:
        print(
            "peer_pyelastica: PyElastica is not installed (pip install pyelastica, or the 'peer' extra); skipped, nothing written."
        )
        return
    out = Path(out or Path(__file__).parent / "results" / ("peer_pyelastica_quick.json" if quick else "peer_pyelastica.json"))
    t_start = time.perf_counter()
    robot = tdct.Robot.paper()
    sec = section(robot)
    exact = exact_deflection(sec, FORCE)
    print(
        f"cantilever L = {sec['L'] * 1e3:.0f} mm, E I_x = {sec['E'] * sec['I_x']:.4e} N m^2, G A = {sec['G'] * sec['A']:.4e} N, "
        f"F = {FORCE * 1e3:g} mN along -y: exact tip deflection {exact * 1e3:.6f} mm"
    )

    jx = run_tdct(robot, exact, repeats=10 if quick else 50)
    print(f"tdct_jax compile + first solve {jx['compile_and_first_solve_s']:.1f} s, warm median {jx['median_ms']:.2f} ms")
    factors = (QUICK_GAMMA_FACTOR,) if quick else GAMMA_FACTORS
    pe = run_pyelastica(sec, exact, N_ELEMENTS, factors, repeats=2 if quick else 3)

    best = pe["best"]
    ratio = best["time_to_tolerance_s"] * 1e3 / jx["median_ms"] if best else None
    ratio_setup = (best["time_to_tolerance_s"] + best["setup_s"]) * 1e3 / jx["median_ms"] if best else None
    write_result(
        out,
        quick=quick,
        problem="default Robot, no tube, no tension, gravity off, clamped at s = 0, tip force along -y",
        force_N=FORCE,
        section=sec,
        exact_formula="F L^3 / (3 E I_x) + F L / (G A)",
        exact_tip_deflection_mm=exact * 1e3,
        tolerance=TOLERANCE,
        tdct_jax=jx,
        pyelastica=pe,
        ratio_time_to_tolerance_vs_warm_solve=ratio,
        ratio_with_pyelastica_setup=ratio_setup,
        total_s=time.perf_counter() - t_start,
    )

    print(f"\n{'solver':34s} {'to 0.1% [ms]':>12s} {'steps':>11s} {'tip error':>10s} {'first run [s]':>13s}")
    if best:
        name = f"PyElastica n={N_ELEMENTS}, gamma {best['gamma_per_s']:.1f}/s"
        print(
            f"{name:34s} {best['time_to_tolerance_s'] * 1e3:12.1f} {best['steps_to_tolerance']:11d} "
            f"{best['final_relative_error']:10.1e} {pe['first_run_s']:13.1f}"
        )
    else:
        print(f"{'PyElastica':34s} {'never':>12s}")
    print(
        f"{f'tdct_jax, {STEPS} RK4 steps/segment':34s} {jx['median_ms']:12.2f} {str(jx['newton_iterations']) + ' Newton':>11s} "
        f"{jx['relative_error']:10.1e} {jx['compile_and_first_solve_s']:13.1f}"
    )
    if ratio:
        print(f"ratio (PyElastica time to 0.1% / tdct_jax warm solve): {ratio:.0f}x ({ratio_setup:.0f}x with PyElastica's setup)")
    print(f"(wall-clock on a shared machine: noisy) total {time.perf_counter() - t_start:.0f} s; wrote {out}")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="one damping constant, fewer repeats")
    parser.add_argument("--out", default=None, help="results JSON (default benchmarks/results/peer_pyelastica[_quick].json)")
    args = parser.parse_args()
    main(args.quick, args.out)
