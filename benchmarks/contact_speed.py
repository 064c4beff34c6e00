"""Contact solve against the contact-free solve of the same robot (issue 26), warm (compiled), side
by side in one process, for several candidate spacings ``every``; and the line-contact convergence
of a rod lying on a plane as ``every`` is refined.

    PYTHONPATH=. python benchmarks/contact_speed.py
"""

import os
import time

import jax
import jax.numpy as jnp
import numpy as np

import tdct_jax as tdct

ROBOT = tdct.Robot().to_general()
ACT = tdct.GeneralActuation([2.0, 0.0, 0.0, 0.0], [0.05])
REPEATS = 30


def act_at(t):
    return ACT._rebuild(jnp.asarray(ACT.tensions).at[0].set(t), ACT.insertions, ACT.displacements, ())


def timed(f, x):
    t = time.perf_counter()
    jax.block_until_ready(f(x))
    return time.perf_counter() - t


def speed():
    free = jax.jit(lambda t: tdct.solve(ROBOT, act_at(t), throw=False))
    tip = free(np.float64(2.0)).tip_position
    plane = tdct.Plane((0.0, 0.8 * float(tip[1]), 0.0), (0.0, 1.0, 0.0), name="table")
    print(f"contact-free tip {np.asarray(tip)} m; plane y = {0.8 * float(tip[1]):.4f} m, normal +y")
    print(os.popen("uptime").read().strip())
    for every in (1, 2, 4, 5, 10, 20):
        scene = tdct.Scene((plane,), every=every)

        def touch(t, scene=scene):
            return tdct.solve(ROBOT, act_at(t), scene=scene, throw=False)

        touch = jax.jit(touch)
        sol = touch(np.float64(2.0))
        a, b = [], []
        for i in range(REPEATS):  # alternated, tensions varied slightly so that nothing is cached
            t = np.float64(2.0 + 1e-3 * i)
            a.append(timed(free, t))
            b.append(timed(touch, t))
        ra, rb = np.median(a), np.median(b)
        n_c = sol.contact.force.shape[0]
        print(
            f"every {every:2d}: {n_c:2d} candidates, result {int(sol.result)}, Newton {int(sol.iterations)} steps, "
            f"contact force {float(sol.contact.force.sum()):.4f} N at s = {np.asarray(sol.contact.s)[np.asarray(sol.contact.active[:, 0])]}; "
            f"median free {1e3 * ra:.2f} ms, contact {1e3 * rb:.2f} ms, ratio {rb / ra:.2f}"
        )
    print(os.popen("uptime").read().strip())


def line_contact():
    """A weightless rod under a uniform load lying on a plane (its own height: every candidate
    touches from the start) clamped at a slope: the total contact force converges to the load."""
    L = 0.3
    section = tdct.Section(end=L, outer_diameter=2e-3, E=1e9, nu=0.3, density=0.0)
    rod = tdct.GeneralRobot(L, (section,), ())
    w = 0.02  # N/m along -y
    load = tdct.Loads(distributed_force=(0.0, -w, 0.0))
    # a plane tilted by 0.05 rad under the rod: the rod bends down onto it and lies along it
    n = np.array([0.0, np.cos(0.05), np.sin(0.05)])
    plane = tdct.Plane((0.0, -1e-3 / n[1], 0.0), n)
    for steps in (20, 40):
        for every in (8, 4, 2, 1):
            if steps * 1 < every:
                continue
            sol = tdct.solve(
                rod,
                None,
                load,
                gravity=(0.0, 0.0, 0.0),
                scene=tdct.Scene((plane,), every=every),
                solver=tdct.SolverOptions(steps=steps),
                throw=False,
            )
            c = sol.contact
            F = np.sum(np.asarray(c.force)[..., None] * np.asarray(c.normal), axis=(0, 1))
            print(
                f"steps {steps} every {every}: result {int(sol.result)}, {c.force.shape[0]} candidates, "
                f"{int(np.count_nonzero(c.active))} touching, contact force {F} N (load {w * L} N), "
                f"tip {np.asarray(sol.tip_position)} m, Newton {int(sol.iterations)} steps"
            )


if __name__ == "__main__":
    speed()
    line_contact()
