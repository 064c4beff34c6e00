"""The objectives that choose among redundant IK solutions (paper Sec. V.B)."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from ..checks import as_array, is_concrete
from ..inputs import Actuation
from ..solve import Solution
from ..tree import pytree, set_fields
from .problem import Plan, Problem


@pytree
class Stiffness:
    """The stiffest solution: the least tip compliance along ``direction`` [m/N] (world frame,
    (3,), nonzero; normalised), or without a direction the largest eigenvalue of the positional
    compliance's symmetric part (eq. 41)."""

    direction: object = None

    def __post_init__(self):
        if self.direction is not None:
            direction = as_array("Stiffness.direction", self.direction, (3,))
            if is_concrete(direction) and not np.linalg.norm(direction) > 0:
                raise ValueError("Stiffness.direction = [0, 0, 0]: the stiffness direction must be a nonzero vector")
            set_fields(self, direction=direction)


@pytree
class LeastTension:
    """The solution of least total squared tension [N^2]: no needless co-contraction."""


@pytree
class PreferredInsertion:
    """The solution whose insertion is nearest ``depth`` [m] (in [0, L]; None: L / 2), squared
    distance [m^2]; needs exactly one free tube."""

    depth: object = None

    def __post_init__(self):
        if self.depth is not None:
            set_fields(self, depth=as_array("PreferredInsertion.depth", self.depth, (), unit=" m"))


SHORTHANDS = {"stiffness": Stiffness, "tension": LeastTension, "insertion": PreferredInsertion}
"""``objective=`` may name an objective with its defaults."""
KINDS = {cls: name for name, cls in SHORTHANDS.items()}


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
        return (act.insertions[plan.tubes[0]] - prob.preferred_insertion) ** 2  # one free tube (checked)
    return plan.objective(sol, act)
