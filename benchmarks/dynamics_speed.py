"""Speed of ``tdct.simulate`` at the accuracy the step allows (issue 49, acceptance 3): a tendon
pulled in 0.1 s, simulated for 0.3 s, on the paper robot and on a three-segment nine-tendon robot.

For each robot, the tip along time is computed at a fine reference step (0.25 ms) and at coarser
steps (0.5 to 10 ms, every one a multiple of the reference's, so the trajectories share their
times); the largest step whose tip stays within 0.1 mm of the reference at every common time is
the working step. Every run uses ``simulate``'s default solver (``dynamics.default_solver``:
four shooting intervals where they divide the RK4 steps). There: compile time (first call less a
warm one), the warm wall time per time step (median of warm calls of the whole ``simulate``, the
start's static solve included), the real-time factor (simulated time over wall time) and the
mean chord and Newton steps per time step (``Trajectory.iterations``); the same with 10 RK4 steps
per interval instead of 20, with its own distance to the reference, with Newton's tolerance
loosened from 1e-10 to 1e-6, and with single shooting (one interval); 40 RK4 steps at the working
step, for the spatial error of 20; and what bounds the speed: the cost of one time step's primal
shooting pass and of its Jacobian pass (``Problem.linearize``), each timed alone, against the
measured step (where chord steps suffice a step takes one Jacobian pass and ``iterations + 1``
primal passes: one a chord step, one for its nodes). Last, ``jax.vmap`` of ``simulate`` over
tension amplitudes (batches of 8 and 64, the paper robot at its working step): the summed
real-time factor of the batch.

The robots (no point masses):
- ``Robot.paper()``, the tube inserted 80 mm, its silicone given a Kelvin-Voigt retardation time
  of 10 ms; tendon 1 pulled from 0 to 3 N.
- three segments of 0.1 m (0.3 m in all) on a solid Nitinol backbone 1.4 mm across (E 54 GPa,
  6,450 kg/m^3: the shipped ``two_segment.toml``'s backbone), tendons through spacer disks 10 mm
  from the axis (the disks' mass left out), three tendons a segment anchored at its end, 120
  degrees apart, each segment's set turned 40 degrees from the one before (90/210/330,
  130/250/10, 170/290/50 degrees); retardation time 5 ms; tendon 1 (segment 1) pulled from 0 to
  3 N.
The pull: T(t) = 3 N (1 - cos(pi t / 0.1 s)) / 2 up to 0.1 s, then held; start: the static
equilibrium at zero tension (gravity on); BDF-alpha with alpha = -0.2.

Run: python benchmarks/dynamics_speed.py [--quick] [--repeats 5] [--batch 8,64]
``--quick`` (CI): the paper robot only, 5 ms steps for 0.1 s against 2.5 ms steps over the
first 0.05 s (the same number of rows, so one compiled program), no batch. Writes
benchmarks/results/dynamics_speed.json (dynamics_speed_quick.json with --quick).
"""

from __future__ import annotations

import argparse
import hashlib
import os
import subprocess
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from _common import timings, write_result
from jax import lax

import tdct_jax as tdct
from tdct_jax import dynamics, rod
from tdct_jax.inputs import STANDARD_GRAVITY, gravity_vector

DURATION, RAMP, AMPLITUDE = 0.3, 0.1, 3.0  # [s], [s], [N]
REFERENCE_MS = 0.25
STEPS_MS = (0.5, 1.0, 2.0, 3.0, 4.0, 5.0, 10.0)
LOOSE_TOL = 1e-6
"""Newton's tolerance loosened from 1e-10 (scaled residual): how many Newton steps it saves."""
TOLERANCE_M = 1e-4
"""Largest distance of the tip from the reference's, at any common time, for a step to count."""
PAPER_DAMPING, THREE_DAMPING = 0.010, 0.005  # Kelvin-Voigt retardation times [s]


def three_segment() -> tdct.Robot:
    """The three-segment nine-tendon Nitinol-backbone robot of the module docstring."""
    seg = 0.1
    sections = tuple(
        tdct.Section(end=seg * (j + 1), outer_diameter=1.4e-3, E=54e9, nu=0.3, density=6450.0, damping=THREE_DAMPING)
        for j in range(3)
    )
    tendons = tuple(
        tdct.Tendon(offset=0.010, angle=np.deg2rad((90 + 40 * j + 120 * k) % 360), end=seg * (j + 1) if j < 2 else None)
        for j in range(3)
        for k in range(3)
    )
    return tdct.Robot(3 * seg, sections, tendons)


def robots(quick: bool) -> dict:
    """name -> (robot, tube insertions [m])."""
    paper = tdct.Robot.paper().replace({"sections[*].damping": PAPER_DAMPING})
    out = {"Robot.paper(), 80 mm insertion": (paper, [0.08])}
    if not quick:
        out["three segments, nine tendons"] = (three_segment(), None)
    return out


def pull(n_tendons: int, dt: float, rows: int, amplitude=AMPLITUDE):
    """Tensions (rows, n_tendons): tendon 1 ramped smoothly to ``amplitude`` over RAMP, then held."""
    t = np.arange(rows) * dt
    shape = 0.5 * (1 - np.cos(np.pi * np.clip(t / RAMP, 0.0, 1.0)))
    return jnp.zeros((rows, n_tendons)).at[:, 0].set(amplitude * shape)


def run(robot, insertions, dt, rows, solver, amplitude=AMPLITUDE):
    return tdct.simulate(
        robot, dt, tensions=pull(robot.n_tendons, dt, rows, amplitude), insertions=insertions, solver=solver, throw=False
    )


def timed(robot, insertions, dt, rows, solver, repeats):
    """(trajectory, compile+first call [s], warm call times [s])."""
    start = time.perf_counter()
    traj = jax.block_until_ready(run(robot, insertions, dt, rows, solver))
    first = time.perf_counter() - start
    return traj, first, warm_calls(robot, insertions, dt, rows, solver, repeats)


def warm_calls(robot, insertions, dt, rows, solver, repeats) -> np.ndarray:
    """Seconds of ``repeats`` warm calls of ``simulate``, each waited for."""
    return timings(lambda: run(robot, insertions, dt, rows, solver).position, repeats)


def distance(traj, dt, ref, ref_dt, until=None) -> float:
    """Largest distance [m] of traj's tip from the reference's at traj's times (up to ``until``
    [s], the reference's end by default), the reference interpolated linearly in time (exact
    where the times coincide, as they do here)."""
    t = np.arange(traj.tip_position.shape[0]) * dt
    t_ref = np.arange(ref.tip_position.shape[0]) * ref_dt
    keep = t <= (t_ref[-1] if until is None else until) + 1e-12
    p, p_ref = np.asarray(traj.tip_position)[keep], np.asarray(ref.tip_position)
    at = np.stack([np.interp(t[keep], t_ref, p_ref[:, k]) for k in range(3)], axis=-1)
    return float(np.max(np.linalg.norm(p - at, axis=-1)))


def row(name, dt, solver, traj, first, warm, error):
    rows = traj.tip_position.shape[0]
    wall = float(np.median(warm))
    it = np.asarray(traj.iterations[1:])
    out = dict(
        robot=name,
        dt_ms=1e3 * dt,
        rk4_steps=solver.steps,
        intervals=solver.intervals,
        newton_tol=float(solver.tol),
        time_steps=rows - 1,
        converged=bool(traj.converged),
        max_tip_error_um=None if error is None else 1e6 * error,
        compile_and_first_s=first,
        compile_s=first - wall,
        warm_call_s=wall,
        warm_calls=len(warm),
        ms_per_time_step=1e3 * wall / (rows - 1),
        real_time_factor=(rows - 1) * dt / wall,
        mean_newton_steps=float(np.mean(it)),
        max_newton_steps=int(np.max(it)),
    )
    err = "" if error is None else f", tip within {1e6 * error:8.1f} um"
    print(
        f"{name:32s} dt {1e3 * dt:5.2f} ms, {solver.steps} RK4, K {solver.intervals}, tol {float(solver.tol):.0e}: {out['ms_per_time_step']:6.2f} ms/step, "
        f"{out['real_time_factor']:.3f}x real time, {out['mean_newton_steps']:.2f} chord/Newton steps, "
        f"compile {out['compile_s']:.1f} s{err}{'' if out['converged'] else ', NOT CONVERGED'}",
        flush=True,
    )
    return out


PASSES = 20
"""Shooting passes per compiled call in ``anatomy``: a loop, so that the call's dispatch (the
robot's and the layout's pytrees flattened in Python) is not timed as the pass's."""


def anatomy(robot, insertions, dt, solver, newton_steps, ms_per_step, repeats=20) -> dict:
    """One time step's shooting passes timed alone, mid-pull (half the amplitude on tendon 1):
    the primal pass (base to tip, the residual) and the Jacobian pass (``Problem.linearize``: one
    ``jacfwd`` pass in the six base unknowns, or with K > 1 intervals in each start's 15), each
    run PASSES times in a compiled loop, each pass's unknowns
    depending on the last pass's output so that none is hoisted, with ``dynamics.Problem``'s
    arguments as the loop's arguments (as in ``simulate``'s scan); and a warm static
    ``tdct.solve`` for scale. The time step they predict where chord steps suffice: one Jacobian
    pass and ``newton_steps + 1`` primal passes (a step that needs Newton takes more), against the
    measured ``ms_per_step``."""
    T = pull(robot.n_tendons, dt, 1, AMPLITUDE / 2)[0]
    act = tdct.Actuation(T, jnp.zeros(robot.n_tubes) if insertions is None else insertions)
    load = tdct.Loads()
    g = jnp.asarray(gravity_vector(STANDARD_GRAVITY))
    c = dynamics.scheme(dt)
    n = rod.n_intervals(robot, load) * solver.steps
    history = (jnp.zeros((n, 4, 12)), jnp.zeros(6))  # a robot at rest: no strain rate, no velocity
    F_c = rod.force_scale(robot, act, load, g)
    base = tdct.solve(robot, act, solver=solver).base_wrench
    x = jnp.concatenate([base[:3], base[3:] / robot.length]) / F_c
    K = solver.intervals

    def problem(robot, act, load, c, history, F_c):
        return dynamics.Problem(
            robot, act, load, g, c, history, None, F_c, dynamics._scale(F_c, robot.length, dt), K, solver.steps
        )

    def unknowns(x):  # the interior starts' values do not change a pass's cost
        return dynamics.Unknowns(x, jnp.broadcast_to(jnp.eye(3), (K - 1, 3, 3)), jnp.zeros((K - 1, 12)))

    def residual(x, *args):
        return problem(*args).residual(unknowns(x))[0]

    def linearized(x, *args):
        return problem(*args).linearize(unknowns(x))[1]

    def looped(f):
        @jax.jit
        def passes(x, *args):
            return lax.fori_loop(0, PASSES, lambda i, x: x + 1e-300 * f(x, *args).reshape(-1)[: x.size], x)

        return passes

    args = (x, robot, act, load, c, history, F_c)
    primal, jacobian = looped(residual), looped(linearized)
    out = {}
    for name, f, k in (
        ("primal_pass", lambda: primal(*args), PASSES),
        ("jacobian_pass", lambda: jacobian(*args), PASSES),
        ("static_solve", lambda: tdct.solve(robot, act, solver=solver).position, 1),
    ):
        jax.block_until_ready(f())
        out[f"{name}_ms"] = 1e3 * float(np.median(timings(f, repeats))) / k
    out["jacobian_over_primal"] = out["jacobian_pass_ms"] / out["primal_pass_ms"]
    out["predicted_ms_per_time_step"] = out["jacobian_pass_ms"] + (newton_steps + 1) * out["primal_pass_ms"]
    out["measured_ms_per_time_step"] = ms_per_step
    print(", ".join(f"{k} {v:.3g}" for k, v in out.items()), flush=True)
    return out


def batch(robot, insertions, dt, rows, solver, sizes, repeats, single) -> list[dict]:
    """``jax.vmap`` of ``simulate`` over tension amplitudes AMPLITUDE k / B, k = 1..B, in one
    compiled call per batch size; the lane k = B against the single run ``single``."""
    out = []
    for B in sizes:
        amplitudes = AMPLITUDE * jnp.arange(1, B + 1) / B
        f = jax.jit(jax.vmap(lambda a: run(robot, insertions, dt, rows, solver, a)))
        start = time.perf_counter()
        traj = jax.block_until_ready(f(amplitudes))
        first = time.perf_counter() - start
        warm = timings(lambda f=f, a=amplitudes: f(a).position, repeats)
        wall = float(np.median(warm))
        it = np.asarray(traj.iterations[:, 1:])
        out.append(
            dict(
                batch=B,
                dt_ms=1e3 * dt,
                rk4_steps=solver.steps,
                compile_s=first - wall,
                warm_call_s=wall,
                warm_calls=repeats,
                ms_per_time_step_per_lane=1e3 * wall / ((rows - 1) * B),
                summed_real_time_factor=B * (rows - 1) * dt / wall,
                mean_newton_steps=float(np.mean(it)),
                mean_slowest_lane_newton_steps=float(np.mean(np.max(it, axis=0))),
                converged_lanes=int(np.sum(np.all(np.asarray(traj.result) == 0, axis=1))),
                last_lane_vs_single_m=float(np.max(np.abs(np.asarray(traj.tip_position[-1] - single.tip_position)))),
            )
        )
        r = out[-1]
        print(
            f"vmap batch {B:3d}: {wall:.2f} s a call, {r['ms_per_time_step_per_lane']:.2f} ms per time step and lane, "
            f"summed {r['summed_real_time_factor']:.3f}x real time, compile {r['compile_s']:.1f} s, "
            f"{r['converged_lanes']}/{B} converged, last lane vs single {r['last_lane_vs_single_m']:.1e} m",
            flush=True,
        )
    return out


DYNAMICS_SHA1 = hashlib.sha1(Path(dynamics.__file__).read_bytes()).hexdigest()[:12]
"""The simulator's source as imported (the library may change while this runs)."""


def source() -> dict:
    """The commit measured, whether tdct_jax/ differed from it (None outside a git checkout), and
    the hash of tdct_jax/dynamics.py as imported."""

    def git(*a):
        done = subprocess.run(["git", *a], cwd=Path(__file__).parent, capture_output=True, text=True)
        return done.stdout.strip() if done.returncode == 0 else None

    changed = git("status", "--porcelain", "--", "../tdct_jax")
    return dict(
        commit=git("rev-parse", "--short", "HEAD"),
        tdct_jax_modified=None if changed is None else bool(changed),
        dynamics_py_sha1=DYNAMICS_SHA1,
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="paper robot, 20 steps of 5 ms against 2.5 ms, no batch")
    parser.add_argument("--repeats", type=int, default=5, help="warm calls at the working step (2 at the others)")
    parser.add_argument("--batch", default="8,64", help="vmapped batch sizes")
    args = parser.parse_args()
    load_start = os.getloadavg()
    print(f"load average {load_start}", flush=True)
    rows_out, summary, batches, anatomies = [], {}, [], {}
    for name, (robot, ins) in robots(args.quick).items():
        fine, coarse = (dynamics.default_solver(robot, tdct.Loads(), steps=k) for k in (20, 10))
        loose = dynamics.default_solver(robot, tdct.Loads(), tol=LOOSE_TOL)
        if args.quick:  # one compiled program: 21 rows at 5 ms, then the same 21 rows at 2.5 ms
            dt, rows = 5e-3, 21
            traj, first, warm = timed(robot, ins, dt, rows, fine, 3)
            ref = run(robot, ins, dt / 2, rows, fine)
            r = row(name, dt, fine, traj, first, warm, distance(traj, dt, ref, dt / 2))
            rows_out.append(r)
            summary[name] = dict(working_dt_ms=5.0, reference="2.5 ms steps, the first 0.05 s")
            anatomies[name] = anatomy(robot, ins, dt, fine, r["mean_newton_steps"], r["ms_per_time_step"], repeats=10)
            continue
        ref_dt = 1e-3 * REFERENCE_MS
        ref, first, warm = timed(robot, ins, ref_dt, round(DURATION / ref_dt) + 1, fine, 1)
        if not bool(ref.converged):
            raise SystemExit(f"{name}: the {REFERENCE_MS} ms reference did not converge at every step")
        rows_out.append(row(name, ref_dt, fine, ref, first, warm, None))
        runs = {}
        for ms in STEPS_MS:
            dt = 1e-3 * ms
            traj, first, warm = timed(robot, ins, dt, round(DURATION / dt) + 1, fine, 2)
            rows_out.append(row(name, dt, fine, traj, first, warm, distance(traj, dt, ref, ref_dt)))
            runs[ms] = (traj, first, warm, rows_out[-1])
        ok = [ms for ms, (*_, r) in runs.items() if r["converged"] and r["max_tip_error_um"] <= 1e6 * TOLERANCE_M]
        if not ok:
            raise SystemExit(f"{name}: no step within {1e3 * TOLERANCE_M} mm of the reference")
        best = max(ok)
        dt, rows = 1e-3 * best, round(DURATION / (1e-3 * best)) + 1
        traj, first, warm, _ = runs[best]  # more warm calls at the working step
        warm = np.concatenate([warm, warm_calls(robot, ins, dt, rows, fine, args.repeats)])
        at_best = row(name, dt, fine, traj, first, warm, distance(traj, dt, ref, ref_dt))
        runs[best][3].update(at_best, working=True)  # its row, now with every warm call
        other = {}  # option -> (trajectory, its row)
        options = (("10", coarse), ("40", dynamics.default_solver(robot, tdct.Loads(), steps=40)), ("tol", loose))
        for key, solver in (*options, ("single", tdct.SolverOptions(steps=20))):
            t, first, w = timed(robot, ins, dt, rows, solver, 2 if key == "40" else args.repeats)
            other[key] = t, row(name, dt, solver, t, first, w, distance(t, dt, ref, ref_dt))
            rows_out.append(other[key][1])
        anatomies[name] = anatomy(robot, ins, dt, fine, at_best["mean_newton_steps"], at_best["ms_per_time_step"])
        summary[name] = dict(
            working_dt_ms=best,
            reference=f"{REFERENCE_MS} ms steps, 20 RK4 steps per interval",
            reference_own_error_um=runs[STEPS_MS[0]][3]["max_tip_error_um"] / 3,  # second order: |p(2h) - p(h)| / 3
            rk4_20_vs_40_at_working_dt_um=1e6 * distance(traj, dt, other["40"][0], dt),
            rk4_10_meets_tolerance=other["10"][1]["converged"] and other["10"][1]["max_tip_error_um"] <= 1e6 * TOLERANCE_M,
            loose_tol_vs_default_at_working_dt_um=1e6 * distance(other["tol"][0], dt, traj, dt),
            intervals=fine.intervals,
            single_shooting_ms_per_time_step=other["single"][1]["ms_per_time_step"],
            single_shooting_converged=other["single"][1]["converged"],
        )
        if name.startswith("Robot.paper()") and not args.quick:
            sizes = [int(b) for b in args.batch.split(",") if b]
            batches = batch(robot, ins, dt, rows, fine, sizes, 2, traj)
    out = Path(__file__).parent / "results" / f"dynamics_speed{'_quick' if args.quick else ''}.json"
    write_result(
        out,
        quick=args.quick,
        **source(),
        load_average=load_start,
        load_average_end=os.getloadavg(),
        duration_s=DURATION if not args.quick else 0.1,
        pull=f"tendon 1 from 0 to {AMPLITUDE} N, (1 - cos(pi t / {RAMP} s)) / 2, then held",
        damping_s={"Robot.paper()": PAPER_DAMPING, "three segments": THREE_DAMPING},
        tolerance_um=1e6 * TOLERANCE_M,
        alpha=dynamics.ALPHA,
        summary=summary,
        rows=rows_out,
        anatomy=anatomies,
        batch=batches,
    )


if __name__ == "__main__":
    main()
