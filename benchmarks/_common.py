"""Shared by the benchmark scripts: timing with block_until_ready, results files that say when,
where and with which JAX they were measured, and the dynamics benchmarks' steel cantilever."""

from __future__ import annotations

import json
import platform
import resource
import time
from pathlib import Path

import jax
import numpy as np

import tdct_jax as tdct


def timings(f, repeats: int) -> np.ndarray:
    """Wall-clock seconds of ``repeats`` warm calls of f (each waited for with block_until_ready)."""
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        jax.block_until_ready(f())
        times.append(time.perf_counter() - t)
    return np.array(times)


def peak_rss_mb() -> float:
    """This process's peak resident memory so far [MB] (Linux reports ru_maxrss in KiB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def write_result(path: str | Path, **fields) -> None:
    """Writes fields as JSON, after the date, the machine and the JAX version."""
    result = dict(
        date=time.strftime("%Y-%m-%d"),
        machine=f"{platform.processor() or platform.machine()}, {jax.device_count()} x {jax.devices()[0].platform}",
        jax=jax.__version__,
        **fields,
    )
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    Path(path).write_text(json.dumps(result, indent=2) + "\n")


def paper_section(robot) -> dict:
    """The section of a one-section robot (``tdct.Robot.paper()``) as numpy floats (SI): E, G, the
    body's area A and second moments I_x, I_y (tendon channels removed, each by the parallel-axis
    theorem), its density rho, the tendons' body-frame positions r (n_tendons, 3) at the base and,
    with a tube, the tube's bending stiffness EI_tube [N m^2] and mass per length rho_tube [kg/m]."""
    from tdct_jax.description import channelled_second_moments, section_area

    if len(robot.sections) != 1:
        raise ValueError(f"a robot of one section expected, got {len(robot.sections)}")
    sec = robot.sections[0]
    r = np.array([np.asarray(t.position(0.0)[0], dtype=float) for t in robot.tendons]).reshape(-1, 3)
    I_x, I_y = channelled_second_moments(sec.outer_diameter, sec.inner_diameter, sec.tendon_channel_diameter, r, 1.0)
    E, nu = float(sec.E), float(sec.nu)
    tube = robot.tubes[0] if robot.tubes else None
    return dict(
        L=float(robot.length),
        E=E,
        G=E / (2 * (1 + nu)),
        A=float(section_area(sec, robot.n_tendons)),
        I_x=float(I_x),
        I_y=float(I_y),
        rho=float(sec.density),
        r=r,
        EI_tube=0.0 if tube is None else float(tube.E * tube.second_moment),
        rho_tube=0.0 if tube is None else float(tube.density * tube.area),
    )


STEEL = dict(length=0.3, diameter=2e-3, E=200e9, density=7800.0)
"""The slender steel cantilever of tests/test_dynamics.py [m, m, Pa, kg/m^3], for the dynamics
benchmarks."""
STEEL_PERIOD = (
    2 * np.pi * STEEL["length"] ** 2 / (1.8751**2 * np.sqrt(STEEL["E"] * STEEL["diameter"] ** 2 / 16 / STEEL["density"]))
)
"""Its Euler-Bernoulli first period [s] (EI / (rho A) = E D^2 / 16)."""


def steel_cantilever(E: float = STEEL["E"], damping: float = 0.0):
    """``STEEL`` as a tdct.Robot with one tendon 5 mm from the axis at body +y, and its modulus
    and Kelvin-Voigt retardation time [s] given."""
    L = STEEL["length"]
    section = tdct.Section(end=L, outer_diameter=STEEL["diameter"], E=E, nu=0.3, density=STEEL["density"], damping=damping)
    return tdct.Robot(L, (section,), (tdct.Tendon(offset=5e-3, angle=np.pi / 2),))
