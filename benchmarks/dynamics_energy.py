"""The scheme's own dissipation over 100 periods (issue 49, acceptance 1): the total energy of a
freely vibrating cantilever without material damping, at 50 and 100 steps per first period, for
BDF-alpha's alpha = -0.2 (the default), -0.4 and 0 (BDF2).

The rod is the test cantilever of tests/test_dynamics.py (steel, 0.3 m long, 2 mm across, 20 RK4
steps, no gravity), released at t = 0 from its static shape under a 1 mN tip force: mostly its
first mode. Its energy at each time is integrated over the nodes (trapezoid in s) from the
trajectory alone:

    elastic  (n . K_se^-1 n + m . K_bt^-1 m) / 2,   n = R^T N, m = R^T M (no tendon tension),
    kinetic  (rho A |p_t|^2 + w . rho J w) / 2,     w = R^T omega,

and the loss per period is 1 - (E(t_end) / E(t_0))^(1 / periods) over periods 10 to 100 (the
higher modes the release excites, damped fastest by the scheme, are gone by then). The ratio of
the losses at 50 and 100 steps a period gives the order. The trapezoidal setting (alpha = -0.5),
the scheme's non-dissipative one, is unstable on the rod (docs/dynamics.md, Limits): it runs 16
periods at 50 steps a period, short of its failure, for the energy it gains.

Run: python benchmarks/dynamics_energy.py [--periods 100]
Writes benchmarks/results/dynamics_energy.json and dynamics_energy.png.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import matplotlib
import numpy as np
from _common import STEEL_PERIOD, steel_cantilever, write_result
from tqdm import tqdm

import tdct_jax as tdct
from tdct_jax import rod

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

T1 = STEEL_PERIOD
SOLVER = tdct.SolverOptions(steps=20, intervals=4)
ALPHAS = (-0.2, -0.4, 0.0)
STEPS_PER_PERIOD = (50, 100)
FROM_PERIOD = 10
TRAPEZOID_PERIODS = 16
"""alpha = -0.5 is run at 50 steps a period for this many periods only: it fails by about 18."""


def energy(robot: tdct.Robot, traj) -> np.ndarray:
    """Elastic plus kinetic energy [J] at each time (module docstring)."""
    P = rod.plan(robot, tdct.Actuation([0.0]), tdct.Loads(), jnp.zeros(3)).intervals
    K_se, K_bt, rho, rhoJ = (np.asarray(a[0]) for a in (P.K_se, P.K_bt, P.rho, P.rhoJ))
    R = np.asarray(traj.rotation)
    n = np.einsum("...ji,...j->...i", R, np.asarray(traj.force))
    m = np.einsum("...ji,...j->...i", R, np.asarray(traj.moment))
    w = np.einsum("...ji,...j->...i", R, np.asarray(traj.angular_velocity))
    density = 0.5 * (np.sum(n**2 / K_se + m**2 / K_bt, -1) + rho * np.sum(np.asarray(traj.velocity) ** 2, -1))
    density = density + 0.5 * np.sum(rhoJ * w**2, -1)
    return np.trapezoid(density, np.asarray(traj.s[0]), axis=1)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--periods", type=int, default=100, help="periods of the first mode simulated (default 100)")
    args = parser.parse_args()
    load_start = os.getloadavg()
    robot = steel_cantilever()
    rows, curves = [], {}
    runs = [(a, n, args.periods) for a in ALPHAS for n in STEPS_PER_PERIOD] + [(-0.5, 50, TRAPEZOID_PERIODS)]
    for alpha, n, periods in tqdm(runs, desc="simulating", unit="run"):
        steps = periods * n
        push = np.zeros((steps + 1, 3))
        push[0, 1] = 1e-3
        start = time.perf_counter()
        traj = tdct.simulate(robot, T1 / n, tip_force=push, tensions=[0.0], gravity=None, alpha=alpha, solver=SOLVER, throw=False)
        traj = jax.block_until_ready(traj)
        seconds = time.perf_counter() - start
        result = np.asarray(traj.result)
        failed = np.flatnonzero(result != 0)
        good = int(failed[0]) if failed.size else steps + 1
        e = energy(robot, traj)[1:good]  # from row 1: the tip force is gone
        t = np.arange(1, good) * T1 / n
        curves[alpha, n] = (t / T1, e / e[0])
        row = dict(alpha=alpha, steps_per_period=n, periods=periods, seconds=seconds)
        row["first_failed_row"] = good if failed.size else None
        if not failed.size:
            i0 = FROM_PERIOD * n - 1
            row["loss_per_period"] = float(1 - (e[-1] / e[i0]) ** (1 / (periods - FROM_PERIOD)))
            row["energy_kept"] = float(e[-1] / e[0])
        rows.append(row)
        tqdm.write(str(row))
    for alpha in ALPHAS:
        lost = [r.get("loss_per_period") for r in rows if r["alpha"] == alpha and r["periods"] == args.periods]
        if None not in lost and lost[1] > 0:
            tqdm.write(f"alpha {alpha}: loss per period {lost[0]:.3e} at 50, {lost[1]:.3e} at 100: ratio {lost[0] / lost[1]:.2f}")
    out = Path(__file__).parent / "results"
    fig, ax = plt.subplots(figsize=(7, 4.2))
    for (alpha, n), (x, y) in curves.items():
        ax.plot(x, y, lw=1, ls="-" if n == 100 else "--", label=f"alpha {alpha:g}, {n} steps a period")
    ax.set_xlabel("time [first periods]")
    ax.set_ylabel("energy / energy at release")
    ax.set_ylim(0.9, 1.1)
    ax.set_title("Undamped cantilever, free vibration: the scheme's own dissipation", fontsize=10)
    ax.legend(fontsize=7)
    ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(out / "dynamics_energy.png", dpi=120)
    write_result(
        out / "dynamics_energy.json",
        load_average=load_start,
        load_average_end=os.getloadavg(),
        periods=args.periods,
        from_period=FROM_PERIOD,
        first_period_s=T1,
        rk4_steps=SOLVER.steps,
        intervals=SOLVER.intervals,
        rows=rows,
    )


if __name__ == "__main__":
    main()
