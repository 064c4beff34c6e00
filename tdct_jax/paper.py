"""The paper's stiffness studies (Sec. IV.B) as functions: data for Figs. 10 and 11 and the headline.

Each function computes; ``plotting`` draws. The reproduce command calls these.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from .loads import Actuation, TipLoad
from .mechanics import compliance, compliance_ellipsoid
from .robot import Robot

FIG11_TENSIONS = (0.0, 2.0, 4.0, 6.0, 8.0)
"""Fig. 11 tensions on tendon 1 [N]."""
FIG11_INSERTIONS = tuple(0.01 * k for k in range(16))
"""Fig. 11 insertion depths [m]: 0 to 150 mm in 10 mm steps."""
PAPER_LAMBDA2_MM_PER_N = (203.5, 86.1)
"""The paper's lambda_2 at insertion 0 and 150 mm (Fig. 11): a 57.7% reduction."""


def fig10_compliances(robot: Robot, tension: float = 6.0, insertions=(0.0, 0.05, 0.10, 0.15), **solve_options) -> dict:
    """Fig. 10: CM [m/N] for several insertion depths [m] at one tension on tendon 1, no tip load."""
    tau = np.zeros(robot.n_tendons)
    tau[0] = tension
    return {f"insertion {1e3 * d:.0f} mm": compliance(robot, Actuation(tau, d), TipLoad(), **solve_options) for d in insertions}


def fig11_eigenvalues(robot: Robot, tensions=FIG11_TENSIONS, insertions=FIG11_INSERTIONS, **solve_options):
    """Fig. 11: eigenvalues lambda_1..3 [m/N] of CM on a tension x insertion grid, in one vmap call.

    Args:
        robot: the robot.
        tensions: tendon-1 tensions [N].
        insertions: insertion depths [m].
        **solve_options: for ``tdct.solve``.

    Returns:
        Array (len(tensions), len(insertions), 3), ascending; NaN where a solve did not converge.
    """
    T, D = np.meshgrid(np.asarray(tensions, float), np.asarray(insertions, float), indexing="ij")
    unit = np.zeros(robot.n_tendons)
    unit[0] = 1.0

    def eigenvalues(tau, d):
        CM = compliance(robot, Actuation(tau * jnp.asarray(unit), d), TipLoad(), throw=False, **solve_options)
        return compliance_ellipsoid(CM).eigenvalues

    lam = jax.jit(jax.vmap(eigenvalues))(T.ravel(), D.ravel())
    return np.asarray(lam).reshape(*T.shape, 3)


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
