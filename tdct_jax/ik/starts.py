"""Where phase 1 starts: the arc start from a target position alone, and the fresh starts tried
when one ends short of the target."""

from __future__ import annotations

import jax.numpy as jnp

from ..inputs import GeneralActuation
from ..loads import Actuation
from ..robot import Robot
from .problem import Plan, Problem, _tip_force, scaled_inputs


def default_start(prob: Problem, plan: Plan, p, force):
    """A start from the target position p [m] alone: the circular arc from the base (tangent +z)
    through p, less the sag that the tip force [N] and the robot's weight would cause on their own
    (a linear cantilever estimate), fixes a bending angle; the tendons on that side pull with the
    tension whose moment bends the silicone so far, no tube. A GeneralRobot: its first section's
    stiffness and density, every tendon as if anchored at the tip; free displacement-driven tendons
    start at the displacement ``prob.base`` gives."""
    robot = prob.robot
    L, (EI, rho, angles, offsets) = robot.length, _arc_parameters(robot)
    sag = (force * L**3 / 3 + rho * prob.gravity * L**4 / 8) / EI
    sag = sag * jnp.minimum(1.0, 0.5 * L / jnp.maximum(jnp.linalg.norm(sag[:2]), 1e-300))
    x, y = p[0] - sag[0], p[1] - sag[1]
    angle = 2 * jnp.arctan2(jnp.hypot(x, y), jnp.maximum(p[2], 0.0))
    share = jnp.maximum(jnp.cos(angles - jnp.arctan2(y, x)), 0.0)
    tensions = angle / L * EI * share / jnp.maximum(jnp.sum(share**2), 1e-12) / offsets
    k = len(plan.tendons)
    if isinstance(prob.base, Actuation):
        v = [tensions[jnp.asarray(plan.tendons)] / prob.tension_scale] if plan.tendons else []
        if plan.tubes:
            v.append(jnp.reshape(prob.lo[-1], (1,)))
        v = jnp.concatenate(v)
    else:
        base = prob.base
        v = scaled_inputs(GeneralActuation._rebuild(tensions, base.insertions, base.displacements, base.driven), prob, plan)
        v = v.at[k:].set(prob.lo[k:])
    return jnp.clip(v, prob.lo, prob.hi)


def _arc_parameters(robot):
    """(bending stiffness [N m^2], linear density [kg/m], tendon angles [rad], offsets [m]) for
    ``default_start``: a Robot's silicone, a GeneralRobot's first section (no channels)."""
    if isinstance(robot, Robot):
        return (
            robot.bending_stiffness(False)[0],
            robot.linear_density(False),
            jnp.asarray(robot.tendon_angles),
            robot.tendon_offset,
        )
    sec = robot.sections[0]
    D, d = sec.outer_diameter, sec.inner_diameter
    angles, offsets = (jnp.stack([jnp.asarray(getattr(t, k), float) for t in robot.tendons]) for k in ("angle", "offset"))
    return sec.E * jnp.pi / 64 * (D**4 - d**4), sec.density * jnp.pi / 4 * (D**2 - d**2), angles, jnp.maximum(offsets, 1e-300)


def starts(v0, prob: Problem, plan: Plan):
    """Where phase 1 starts: v0, then, should it end short of the target, fresh starts in turn:
    no tension with the tube out and in, a quarter of the tension range everywhere with half the
    tube, and the arc start (``default_start``) with the tube in."""
    lo, hi = prob.lo, prob.hi
    k = len(plan.tendons)

    def with_insertion(v, where):
        return v.at[k:].set(lo[k:] + where * (hi[k:] - lo[k:])) if plan.tubes else v

    quarter = lo + 0.25 * (hi - lo)
    arc = default_start(prob, plan, prob.target.position, _tip_force(prob.load))
    return jnp.stack(
        [v0, with_insertion(lo, 0.0), with_insertion(lo, 1.0), with_insertion(quarter, 0.5), with_insertion(arc, 1.0)]
    )


STARTS = 5
"""Phase 1's starts: the given one, then four fresh ones (``starts``)."""
