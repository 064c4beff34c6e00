"""The paper's simulation studies (Secs. III.B, IV and V.A) as functions that return data.

Each function computes; ``plotting`` draws; ``reproduce`` runs them all and writes the summary.
Grids default to the paper's; the constants below hold the numbers the paper reports.
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .calibrate import levenberg_marquardt
from .loads import Actuation, TipLoad
from .manipulation import capacity, load_capacity, optimal_insertion
from .mechanics import compliance, compliance_ellipsoid
from .options import DEFAULT_SOLVER
from .robot import Robot
from .sweep import sweep

MM = 1e-3
G = 1e-3

FIG8A_TENSION = 10.0
"""Fig. 8A: tension on tendon 1 [N] while the tube goes in (no tip load)."""
FIG8A_INSERTIONS = tuple(MM * d for d in (0, 30, 60, 90, 120, 150))
FIG9_TENSIONS = tuple(float(t) for t in range(11))
"""Figs. 8B and 9: tendon-1 tensions [N], 0 to 10 N in 1 N steps."""
FIG9_INSERTIONS = tuple(MM * d for d in range(0, 151, 10))
"""Figs. 8B, 9 and 11: insertion depths [m], 0 to 150 mm in 10 mm steps."""
FIG10_TENSION = 6.0
"""Fig. 10: tension on tendon 1 [N] (the paper says only "constant"; 6 N is ours)."""
FIG11_TENSIONS = (0.0, 2.0, 4.0, 6.0, 8.0)
FIG11_INSERTIONS = FIG9_INSERTIONS
PAPER_LAMBDA2_MM_PER_N = (203.5, 86.1)
"""The paper's lambda_2 at insertion 0 and 150 mm (Fig. 11): a 57.7% reduction."""
FIG13_TENSIONS = (10.0, 5.0)
"""Fig. 13A and B: tendon-1 tension [N]."""
FIG13_MASSES = tuple(G * m for m in (0, 10, 20, 30, 40, 50))
"""Fig. 13: tip masses [kg] (the paper does not list its curves' masses; 50 g is the one it quotes)."""
PAPER_OPTIMUM = dict(tension_N=10.0, mass_g=50.0, insertion_mm=70.0)
"""Sec. V.A: 50 g at 10 N is lifted highest with about 70 mm of tube (Fig. 13A, 10 mm grid)."""
CAPACITY_TENSIONS = (6.0, 7.0, 8.0, 9.0, 10.0)
CAPACITY_INSERTIONS = (0.0, 0.07)
PAPER_CAPACITIES_G = ((7.20, 13.74, 20.35, 27.04, 33.82), (18.44, 26.15, 33.97, 41.91, 49.98))
"""Sec. V.A: load capacities [g] at 6..10 N, without the tube (first row) and with 70 mm of it."""
TABLE3_TENSIONS = (0.0, 3.0, 6.0, 8.0, 10.0)
TABLE3_INSERTIONS = tuple(MM * d for d in (0, 40, 80, 120))
TABLE3_MASSES = tuple(G * m for m in (0, 20, 50))
PAPER_BENDING_RANGE_DEG = (-57.1, 61.4)
"""Sec. III.B: tip bending angles over the Table III conditions."""
CALIBRATION_TENSIONS = (2.0, 4.0, 6.0, 8.0, 10.0)
"""Sec. III.B calibrates on "five distinct tendon forces" on one tendon without listing them: ours."""


def tendon1(robot: Robot, tensions) -> np.ndarray:
    """Tension vectors [N] that pull tendon 1 only, one row per tension."""
    t = np.zeros((len(tensions), robot.n_tendons))
    t[:, 0] = tensions
    return t


def fig8a_shapes(robot: Robot, tension=FIG8A_TENSION, insertions=FIG8A_INSERTIONS, **options):
    """Fig. 8A: full shapes as the tube goes in, at one tendon-1 tension (SweepResult with shapes)."""
    return sweep(robot, grid={"insertion": np.asarray(insertions), "tensions": tendon1(robot, [tension])}, shapes=True, **options)


def tip_pose_grid(robot: Robot, tensions=FIG9_TENSIONS, insertions=FIG9_INSERTIONS, **options):
    """Figs. 8B and 9: tip poses on a tendon-1 tension x insertion grid, no tip load (SweepResult)."""
    return sweep(robot, grid={"tensions": tendon1(robot, tensions), "insertion": np.asarray(insertions)}, **options)


def fig10_compliances(robot: Robot, tension: float = FIG10_TENSION, insertions=(0.0, 0.05, 0.10, 0.15), **solve_options) -> dict:
    """Fig. 10: CM [m/N] for several insertion depths [m] at one tension on tendon 1, no tip load."""
    (tau,) = tendon1(robot, [tension])
    return {f"insertion {1e3 * d:.0f} mm": compliance(robot, Actuation(tau, d), TipLoad(), **solve_options) for d in insertions}


def fig11_eigenvalues(robot: Robot, tensions=FIG11_TENSIONS, insertions=FIG11_INSERTIONS, **options):
    """Fig. 11: eigenvalues lambda_1..3 [m/N] of CM on a tendon-1 tension x insertion grid.

    Returns:
        Array (len(tensions), len(insertions), 3), ascending; NaN where a solve did not converge.
    """
    res = sweep(
        robot, grid={"tensions": tendon1(robot, tensions), "insertion": np.asarray(insertions)}, compliance=True, **options
    )
    return np.asarray(compliance_ellipsoid(res.compliance).eigenvalues)


def compliance_headline(tensions, insertions, lam) -> list[dict]:
    """lambda_2 at the smallest and largest insertion for each tension, beside the paper's values."""
    paper0, paper1 = PAPER_LAMBDA2_MM_PER_N
    rows = []
    for i, tau in enumerate(tensions):
        first, last = 1e3 * lam[i, 0, 1], 1e3 * lam[i, -1, 1]
        rows.append(
            dict(
                tension_N=float(tau),
                insertion_mm=(1e3 * float(insertions[0]), 1e3 * float(insertions[-1])),
                lambda2_mm_per_N=(float(first), float(last)),
                reduction_percent=float(100 * (1 - last / first)),
                paper_lambda2_mm_per_N=(paper0, paper1),
                paper_reduction_percent=100 * (1 - paper1 / paper0),
            )
        )
    return rows


def fig13_optima(robot: Robot, tension: float, masses=FIG13_MASSES, n_curve: int = 33, **options):
    """Fig. 13: y_tip vs insertion for several tip masses at one tendon-1 tension, optimum of each."""
    (tau,) = tendon1(robot, [tension])
    return optimal_insertion(robot, Actuation(tau), grid={"tip_mass": np.asarray(masses)}, n_curve=n_curve, **options)


def fig14_capacities(robot: Robot, tensions=CAPACITY_TENSIONS, insertions=FIG9_INSERTIONS, **options):
    """Fig. 14: load capacity [kg] (tip brought to y = 0) on a tendon-1 tension x insertion grid."""
    return load_capacity(robot, grid={"tensions": tendon1(robot, tensions), "insertion": np.asarray(insertions)}, **options)


def ten_capacities(robot: Robot, **options):
    """The ten load capacities the paper reports (Sec. V.A): insertion (0, 70 mm) x tendon 1 at 6..10 N."""
    grid = {"insertion": np.asarray(CAPACITY_INSERTIONS), "tensions": tendon1(robot, CAPACITY_TENSIONS)}
    return load_capacity(robot, grid=grid, **options)


def bending_range(robot: Robot, tensions=TABLE3_TENSIONS, insertions=TABLE3_INSERTIONS, masses=TABLE3_MASSES, **options):
    """Tip angles [rad] over the Table III conditions (tendon 1 x insertion x tip mass), SweepResult."""
    grid = {"tensions": tendon1(robot, tensions), "insertion": np.asarray(insertions), "tip_mass": np.asarray(masses)}
    return sweep(robot, grid=grid, **options)


class Fit(NamedTuple):
    """Least-squares fit of Robot fields to the paper's ten load capacities.

    values: fitted fields by name (SI). capacities_g, paper_g: model and paper, (2, 5): rows
    without tube and with 70 mm, columns 6..10 N. residual_percent: relative misfit [%].
    """

    values: dict
    capacities_g: np.ndarray
    paper_g: np.ndarray
    residual_percent: np.ndarray
    iterations: int
    converged: bool


def fit_load_capacities(
    robot: Robot, params=("tendon_offset",), *, max_steps: int = 12, xtol: float = 1e-8, progress=print, solver=DEFAULT_SOLVER
) -> Fit:
    """Fits Robot fields to the ten load capacities of Sec. V.A by Levenberg-Marquardt in log space.

    Residuals are relative misfits (model - paper) / paper; the Jacobian is exact (jacfwd through
    the implicitly differentiated capacity root, vmapped over the ten conditions). ``max_steps``
    and ``xtol`` are the fit's own limit and tolerance; ``solver`` goes to every solve.
    """
    tensions = jnp.asarray(np.tile(tendon1(robot, CAPACITY_TENSIONS), (2, 1)))
    depths = jnp.repeat(jnp.asarray(CAPACITY_INSERTIONS), len(CAPACITY_TENSIONS))
    target = G * np.asarray(PAPER_CAPACITIES_G).ravel()

    def residual(log_values):
        r = dataclasses.replace(robot, **{p: jnp.exp(log_values[i]) for i, p in enumerate(params)})
        c = jax.vmap(lambda t, d: capacity(r, Actuation(t, d), solver=solver, throw=False))(tensions, depths)
        misfit = (c.mass - target) / target
        return misfit, (misfit, c.result)

    jac_and_res = jax.jit(jax.jacfwd(residual, has_aux=True))

    def evaluate(x):
        J, (r, codes) = jac_and_res(x)
        return np.asarray(r), np.asarray(J), int(np.max(np.asarray(codes))), None

    def report(it, r, step):
        progress(f"  fit iteration {it}: rms misfit {100 * np.sqrt(np.mean(np.square(r))):.3f}%, step {np.abs(step).max():.2e}")

    x0 = np.log([float(getattr(robot, p)) for p in params])
    fit = levenberg_marquardt(evaluate, x0, max_steps=max_steps, xtol=xtol, callback=report if progress else None)
    mass = fit.residual * target + target
    return Fit(
        values={p: float(np.exp(fit.x[i])) for i, p in enumerate(params)},
        capacities_g=(mass / G).reshape(2, -1),
        paper_g=np.asarray(PAPER_CAPACITIES_G),
        residual_percent=100 * fit.residual.reshape(2, -1),
        iterations=fit.iterations,
        converged=fit.converged,
    )


def calibration_conditions(robot: Robot, tensions=CALIBRATION_TENSIONS) -> list[Actuation]:
    """Sec. III.B's calibration protocol: tendon 1 alone at five tensions, no tube, no tip load."""
    return [Actuation(t, 0.0) for t in tendon1(robot, tensions)]
