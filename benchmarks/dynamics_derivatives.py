"""Derivatives of a trajectory loss by forward mode (``jax.jacfwd``) against reverse mode
(``jax.grad``), for few parameters (the modulus and the damping) and for many (every entry of a
tension history), on a damped steel cantilever pulled by its tendon (issue 49).

Forward mode carries one tangent per parameter through every time step's implicit solve;
reverse mode runs the steps back once, whatever the number of parameters, storing each step's
state, or with ``simulate(checkpoint=True)`` only each step's carry, the step run again on the way
back. Compile time (first call less a warm one), warm median over ``--repeats`` calls, and the
compiled program's temporary memory (XLA's memory analysis).

Run: python benchmarks/dynamics_derivatives.py [--steps 100] [--repeats 5]
Writes benchmarks/results/dynamics_derivatives.json.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from _common import STEEL, STEEL_PERIOD, steel_cantilever, write_result

import tdct_jax as tdct

E = STEEL["E"]
PERIOD = STEEL_PERIOD
SOLVER = tdct.SolverOptions(steps=20)


def timed(f, args, repeats):
    t = time.perf_counter()
    jax.block_until_ready(f(*args))
    first = time.perf_counter() - t
    warm = []
    for _ in range(repeats):
        t = time.perf_counter()
        jax.block_until_ready(f(*args))
        warm.append(time.perf_counter() - t)
    return first - float(np.median(warm)), float(np.median(warm))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=100, help="time steps (default 100)")
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    n, dt = args.steps, PERIOD / 50
    t = np.arange(n + 1) * dt
    pull = jnp.asarray((np.sin(np.pi * np.minimum(t / PERIOD, 0.5)) ** 2)[:, None])

    def loss(E, damping, tensions, checkpoint=False):
        traj = tdct.simulate(
            steel_cantilever(E, damping), dt, tensions=tensions, gravity=None, solver=SOLVER, throw=False, checkpoint=checkpoint
        )
        return jnp.sum(traj.tip_position[:, 1] ** 2)

    def checkpointed(E, damping, tensions):
        return loss(E, damping, tensions, checkpoint=True)

    load = os.getloadavg()
    rows = {}
    cases = {
        "simulation alone": (jax.jit(loss), (E, 2e-4, pull)),
        "2 parameters (E, damping), forward": (jax.jit(jax.jacfwd(loss, argnums=(0, 1))), (E, 2e-4, pull)),
        "2 parameters (E, damping), reverse": (jax.jit(jax.grad(loss, argnums=(0, 1))), (E, 2e-4, pull)),
        f"{n + 1} parameters (the tension history), forward": (jax.jit(jax.jacfwd(loss, argnums=2)), (E, 2e-4, pull)),
        f"{n + 1} parameters (the tension history), reverse": (jax.jit(jax.grad(loss, argnums=2)), (E, 2e-4, pull)),
        f"{n + 1} parameters, reverse, checkpointed": (jax.jit(jax.grad(checkpointed, argnums=2)), (E, 2e-4, pull)),
    }
    for name, (f, a) in cases.items():
        compile_s, warm_s = timed(f, a, args.repeats)
        memory = f.lower(*a).compile().memory_analysis()
        temp_mb = None if memory is None else memory.temp_size_in_bytes / 2**20
        rows[name] = {"compile_s": compile_s, "warm_s": warm_s, "temp_mb": temp_mb}
        print(f"{name:48s} compile {compile_s:6.1f} s, warm {1e3 * warm_s:8.1f} ms, XLA temporaries {temp_mb} MB")
    out = Path(__file__).parent / "results" / "dynamics_derivatives.json"
    write_result(out, steps=n, dt_s=dt, load_average_before=load, load_average_after=os.getloadavg(), rows=rows)


if __name__ == "__main__":
    main()
