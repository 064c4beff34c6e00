"""The objectives that choose among redundant IK solutions (paper Sec. V.B)."""

from __future__ import annotations

import jax.numpy as jnp

from ..loads import Actuation
from ..solve import Solution
from .problem import Plan, Problem


def objective_value(sol: Solution, C, act: Actuation, prob: Problem, plan: Plan):
    """phi in its physical unit: compliance along the direction [m/N] (or the largest eigenvalue of
    its symmetric part), total squared tension [N^2], squared distance from the preferred
    insertion [m^2], or the user's callable of (Solution, Actuation)."""
    if plan.objective == "stiffness":
        CM = C[:3, :3]
        d = prob.direction
        along = d @ CM @ d
        largest = jnp.linalg.eigvalsh((CM + CM.T) / 2)[-1]
        return jnp.where(jnp.all(jnp.isfinite(d)), along, largest)
    if plan.objective == "tension":
        return jnp.sum(jnp.asarray(act.tensions) ** 2)
    if plan.objective == "insertion":
        insertion = act.insertion if isinstance(act, Actuation) else act.insertions[0]  # one tube (checked)
        return (insertion - prob.preferred_insertion) ** 2
    return plan.objective(sol, act)
