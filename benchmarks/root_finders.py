"""The shooting root: tdct_jax's damped Newton beside optimistix's Newton, Levenberg-Marquardt
and dogleg, on the same residual, side by side in one process.

Run: PYTHONPATH=<optimistix, lineax, equinox> python benchmarks/root_finders.py [--quick]
Writes benchmarks/results/root_finders.json. optimistix is not a dependency: this script is the
measurement behind the choice to keep the library's own loop (issue 46), run by hand.

Every solver starts from the straight rod (no load continuation, the guess ``solve`` gives Newton
first) and stops at the same tolerance on the scaled residual. Per solver: its compile time, the
warm median of one solve (the paper robot at Fig. 6's configuration), and a vmapped batch of
random configurations (tendon 1 and 4 at 0-10 N, insertion 0-L, tip mass 0-50 g): how many
converge from the straight rod, the median iterations, and the batch's warm median.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from _common import timings, write_result

import tdct_jax as tdct
from tdct_jax import shooting
from tdct_jax.inputs import gravity_vector
from tdct_jax.newton import newton
from tdct_jax.rod import force_scale, straight_rod

SOLVER = tdct.SolverOptions()
TOL = SOLVER.tol


def problem(robot, tensions, insertion, mass):
    """The scaled residual F(x) of single shooting and its straight-rod start."""
    act, load, g = tdct.Actuation(tensions, insertion), tdct.Loads.from_mass(mass), gravity_vector(tdct.STANDARD_GRAVITY)
    F_c = force_scale(robot, act, load, g)
    x0 = straight_rod(robot, act, load, g, F_c)
    return (lambda x: shooting.residual(robot, act, load, g, SOLVER, x)), x0


def ours(F, x0):
    x, r, _, it, code = newton(lambda x: (F(x), ()), x0, TOL, SOLVER.max_iter)
    return x, jnp.max(jnp.abs(r)), it, code == tdct.status.SUCCESS


def optimistix_solvers():
    import optimistix as optx

    kw = dict(rtol=0.0, atol=TOL)
    return {
        "optimistix Newton": ("root", optx.Newton(**kw)),
        "optimistix LevenbergMarquardt": ("lsq", optx.LevenbergMarquardt(**kw)),
        "optimistix Dogleg": ("lsq", optx.Dogleg(**kw)),
    }


def with_optimistix(kind, solver):
    import optimistix as optx

    def run(F, x0):
        f = lambda x, _: F(x)  # noqa: E731
        if kind == "root":
            sol = optx.root_find(f, solver, x0, max_steps=SOLVER.max_iter, throw=False)
        else:
            sol = optx.least_squares(f, solver, x0, max_steps=SOLVER.max_iter, throw=False)
        r = jnp.max(jnp.abs(F(sol.value)))
        return sol.value, r, sol.stats["num_steps"], (sol.result == optx.RESULTS.successful) & (r <= 10 * TOL)

    return run


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="20 repeats, a batch of 64")
    args = parser.parse_args()
    repeats, n = (20, 64) if args.quick else (100, 256)
    robot = tdct.Robot.paper()
    rng = np.random.default_rng(0)
    taus = np.zeros((n, 4))
    taus[:, 0], taus[:, 3] = rng.uniform(0, 10, n), rng.uniform(0, 10, n) * (rng.uniform(size=n) < 0.3)
    depths, masses = rng.uniform(0, float(robot.length), n), rng.uniform(0, 0.05, n)

    solvers = {"tdct_jax newton (damped, mu x10)": ours}
    solvers |= {name: with_optimistix(*s) for name, s in optimistix_solvers().items()}
    results = {}
    for name, run in solvers.items():
        one = jax.jit(lambda t, d, m, run=run: run(*problem(robot, t, d, m)))
        batch = jax.jit(jax.vmap(lambda t, d, m, run=run: run(*problem(robot, t, d, m))))
        args1 = (jnp.array([6.0, 0, 0, 0]), 0.08, 0.02)
        t = time.perf_counter()
        jax.block_until_ready(one(*args1))
        compile_one = time.perf_counter() - t
        t = time.perf_counter()
        x, r, it, ok = jax.block_until_ready(batch(taus, depths, masses))
        compile_batch = time.perf_counter() - t
        warm = timings(lambda one=one, a=args1: one(*a), repeats)
        warm_batch = timings(lambda batch=batch: batch(taus, depths, masses), max(3, repeats // 10))
        results[name] = dict(
            first_call_one_s=round(compile_one, 2),
            first_call_batch_s=round(compile_batch, 2),
            warm_one_ms=round(1e3 * float(np.median(warm)), 3),
            iterations_one=int(one(*args1)[2]),
            batch=n,
            batch_converged=int(np.sum(ok)),
            batch_median_iterations=float(np.median(np.asarray(it)[np.asarray(ok)])) if np.any(ok) else None,
            warm_batch_ms=round(1e3 * float(np.median(warm_batch)), 2),
        )
        print(name, results[name], flush=True)
    out = Path(__file__).parent / "results" / f"root_finders{'_quick' if args.quick else ''}.json"
    write_result(out, tolerance=TOL, steps=SOLVER.steps, results=results, note="first calls include compiling")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
