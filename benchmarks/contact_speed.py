"""Contact solve against the contact-free solve of the same robot (issue 26), warm (compiled), side
by side in one process, for several candidate spacings ``every``; and the line-contact convergence
of a rod lying on a plane as ``every`` is refined.

Run: python benchmarks/contact_speed.py [--line]
Writes benchmarks/results/contact_speed.json.
"""

import os
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from _common import write_result

import tdct_jax as tdct

ROBOT = tdct.Robot.paper()
ACT = tdct.Actuation([2.0, 0.0, 0.0, 0.0], [0.05])
REPEATS = 30


def act_at(t):
    return ACT._rebuild(jnp.asarray(ACT.tensions).at[0].set(t), ACT.insertions, ACT.displacements, ACT.driven)


def timed(f, x):
    t = time.perf_counter()
    jax.block_until_ready(f(x))
    return time.perf_counter() - t


def speed() -> list:
    rows = []
    free = jax.jit(lambda t: tdct.solve(ROBOT, act_at(t), throw=False))
    tip = np.asarray(free(np.float64(2.0)).tip_position)
    print(f"contact-free tip {tip} m")
    obstacles = {
        "wall (tip contact)": tdct.Plane((0.0, 0.0, tip[2] - 2e-3), (0.0, 0.0, -1.0)),
        "table (body contact)": tdct.Plane((0.0, 0.8 * tip[1], 0.0), (0.0, 1.0, 0.0)),
    }
    print(os.popen("uptime").read().strip())
    for name, plane in obstacles.items():
        for every in (1, 2, 4, 10):
            scene = tdct.Scene((plane,), every=every)
            touch = jax.jit(lambda t, scene=scene: tdct.solve(ROBOT, act_at(t), scene=scene, throw=False))
            sol = touch(np.float64(2.0))
            a, b = [], []
            for i in range(REPEATS):  # alternated; tensions varied slightly
                t = np.float64(2.0 + 1e-3 * i)
                a.append(timed(free, t))
                b.append(timed(touch, t))
            ra, rb = np.median(a), np.median(b)
            c = sol.contact
            where = np.asarray(c.s)[np.asarray(c.active[:, 0])]
            rows.append(
                dict(
                    case=name,
                    every=every,
                    candidates=int(c.force.shape[0]),
                    result=int(sol.result),
                    newton_steps=int(sol.iterations),
                    contact_force_N=float(c.force.sum()),
                    free_ms=1e3 * ra,
                    contact_ms=1e3 * rb,
                    ratio=rb / ra,
                )
            )
            print(
                f"{name}, every {every:2d}: {c.force.shape[0]:2d} candidates, result {int(sol.result)}, "
                f"Newton {int(sol.iterations)} steps, contact force {float(c.force.sum()):.5f} N at s = {where}, "
                f"tip {np.asarray(sol.tip_position)}; median free {1e3 * ra:.2f} ms, contact {1e3 * rb:.2f} ms, "
                f"ratio {rb / ra:.2f}"
            )
    print(os.popen("uptime").read().strip())
    return rows


def line_contact() -> list:
    """A weightless rod under a uniform load w over a plane parallel to it 1 mm below its surface:
    it bends down and lies along the plane from some s0 on; the total contact force and the tip
    converge as the candidates are refined. Newton from the contact-free start (the rod 5 mm
    into the plane) needs up to ~140 steps to find the contact set: max_iter = 300."""
    L, D = 0.3, 2e-3
    section = tdct.Section(end=L, outer_diameter=D, E=1e9, nu=0.3, density=0.0)
    rod = tdct.Robot(L, (section,))
    w = 0.02  # N/m along -y; free tip deflection 26 mm
    load = tdct.Loads(distributed_force=(0.0, -w, 0.0))
    plane = tdct.Plane((0.0, -D / 2 - 1e-3, 0.0), (0.0, 1.0, 0.0))
    rows = []
    for steps, every in ((20, 8), (20, 4), (20, 2), (20, 1), (40, 1), (80, 1), (160, 1)):
        scene = tdct.Scene((plane,), every=every)
        sol = tdct.solve(
            rod,
            None,
            load,
            gravity=(0.0, 0.0, 0.0),
            scene=scene,
            solver=tdct.SolverOptions(steps=steps, max_iter=300),
            throw=False,
        )
        c = sol.contact
        F = float(np.sum(np.asarray(c.force)[..., 0] * np.asarray(c.normal)[..., 0, 1]))
        s0 = float(np.asarray(c.s)[np.asarray(c.active[:, 0])].min())
        rows.append(
            dict(
                steps=steps,
                every=every,
                result=int(sol.result),
                touching_from_m=s0,
                base_force_N=float(sol.total_force[0, 1]),
                newton_steps=int(sol.iterations),
            )
        )
        print(
            f"steps {steps}, every {every}: result {int(sol.result)}, {c.force.shape[0]} candidates, "
            f"{int(np.count_nonzero(c.active))} touching from s = {s0:.4f} m, contact force {F:.6f} N "
            f"(load {w * L:.6f} N), base force {float(sol.total_force[0, 1]):.6f} N, tip {np.asarray(sol.tip_position)} m, "
            f"Newton {int(sol.iterations)} steps"
        )
    return rows


if __name__ == "__main__":
    import sys

    load = os.getloadavg()
    rows = [] if "--line" in sys.argv else speed()
    write_result(
        Path(__file__).parent / "results" / "contact_speed.json",
        load_average_before=load,
        speed=rows,
        line_contact=line_contact(),
        load_average_after=os.getloadavg(),
    )
