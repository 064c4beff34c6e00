"""Where phase 1 starts: the arc start from a target position alone, the grid start in the basin
of the nearest pose, and the fresh starts tried when one ends short of the target."""

from __future__ import annotations

import dataclasses
import itertools

import jax
import jax.numpy as jnp
from jax import lax

from .. import rod
from ..description import Robot, channelled_second_moments, section_area
from ..inputs import Actuation
from ..shooting import force_scale, shoot, straight_rod
from .problem import Plan, Problem, actuation_of, scaled_inputs, task_residual


def default_start(prob: Problem, plan: Plan, p, force):
    """A start from the target position p [m] alone: the circular arc from the base (tangent +z)
    through p, less the sag that the tip force [N] and the robot's weight would cause on their own
    (a linear cantilever estimate), fixes a bending angle; the tendons on that side pull with the
    tension whose moment bends the first section so far, no tube: its stiffness and density with
    the tendon channels (``_arc_parameters``), every tendon as if anchored at the tip; free
    displacement-driven tendons start at the displacement ``prob.base`` gives."""
    robot, base = prob.robot, prob.base
    L, (EI, rho, angles, offsets) = robot.length, _arc_parameters(robot)
    sag = (force * L**3 / 3 + rho * prob.gravity * L**4 / 8) / EI
    sag = sag * jnp.minimum(1.0, 0.5 * L / jnp.maximum(jnp.linalg.norm(sag[:2]), 1e-300))
    x, y = p[0] - sag[0], p[1] - sag[1]
    angle = 2 * jnp.arctan2(jnp.hypot(x, y), jnp.maximum(p[2], 0.0))
    share = jnp.maximum(jnp.cos(angles - jnp.arctan2(y, x)), 0.0)
    tensions = angle / L * EI * share / jnp.maximum(jnp.sum(share**2), 1e-12) / offsets
    k = len(plan.tendons)
    v = scaled_inputs(Actuation._rebuild(tensions, base.insertions, base.displacements, base.driven), prob, plan)
    v = v.at[k:].set(prob.lo[k:])
    return jnp.clip(v, prob.lo, prob.hi)


def _arc_parameters(robot: Robot):
    """(bending stiffness [N m^2], linear density [kg/m], tendon angles [rad], offsets [m]) for
    ``default_start``: the first section's about body x, every tendon's channel cut from it (as
    the shooting's first interval has them, without a tube: ``rod.interval_parameters``)."""
    sec, n_t = robot.sections[0], robot.n_tendons
    r, _ = rod.tendon_positions(robot, 0.0)
    I_x, _ = channelled_second_moments(sec.outer_diameter, sec.inner_diameter, sec.tendon_channel_diameter, r, 1.0)
    angles, offsets = (
        jnp.stack([jnp.asarray(getattr(t, k), float) for t in robot.tendons]) if n_t else jnp.zeros(0)
        for k in ("angle", "offset")
    )
    return sec.E * I_x, sec.density * section_area(sec, n_t), angles, jnp.maximum(offsets, 1e-300)


def starts(v0, prob: Problem, plan: Plan):
    """Where phase 1 starts: v0, then, should it end short of the target, fresh starts in turn:
    the grid start (``nearest_on_grid``; ``find`` puts it second, computed only when v0 falls
    short), no tension with the tube out and in, a quarter of the tension range everywhere with
    half the tube, and the arc start (``default_start``) with the tube in."""
    lo, hi = prob.lo, prob.hi
    k = len(plan.tendons)

    def with_insertion(v, where):
        return v.at[k:].set(lo[k:] + where * (hi[k:] - lo[k:])) if plan.tubes else v

    quarter = lo + 0.25 * (hi - lo)
    arc = default_start(prob, plan, prob.target.position, prob.load.tip_force)
    return jnp.stack(
        [v0, with_insertion(lo, 0.0), with_insertion(lo, 1.0), with_insertion(quarter, 0.5), with_insertion(arc, 1.0)]
    )


STARTS = 6
"""Phase 1's starts: the given one, the grid start, then four fresh ones (``starts``)."""
GRID_STEPS = 5
"""RK4 steps per segment of ``nearest_on_grid``'s coarse forward solves: enough to tell basins
apart (against 20 steps, the tips of its grid move by 0.07 mm at most on the paper robot, 1.4 mm
on the two-segment robot of tdct_jax/robots)."""
GRID_TOL = 1e-6
"""Tolerance on the scaled tip residual of those solves."""
GRID_NEWTON = 12
"""Newton steps those solves may take; a point that has not converged by then is left out."""
GRID_FD = 1e-7
"""Forward-difference step on the scaled unknowns for those solves' Jacobians."""


def nearest_on_grid(prob: Problem, plan: Plan):
    """The start in the basin of the nearest pose: every corner of the box of v (free tubes also
    at mid-depth: 2^k 3^t points for k tendons and t tubes), a coarse forward solve at each, and
    the point whose task residual |e| is least. Phase 1 from the nearest of a few symmetric starts
    stops at a co-contraction well away from it when the target lies behind the base; the least
    |e| there is usually at a corner.

    The solves run side by side, Newton with forward-difference Jacobians, so that the whole
    grid is one primal integration under ``vmap`` per step: one more copy of the integration in
    the compiled program, not the two of a Jacobian pass and a step."""
    levels = [(0.0, 1.0)] * len(plan.tendons) + [(0.0, 0.5, 1.0)] * len(plan.tubes)
    vs = prob.lo[None] + jnp.asarray(list(itertools.product(*levels))) * (prob.hi - prob.lo)[None]
    solver = dataclasses.replace(prob.solver, steps=GRID_STEPS, intervals=1)  # shoot ignores intervals
    robot, load, gravity = prob.robot, prob.load, prob.gravity
    acts = jax.vmap(lambda v: actuation_of(v, prob, plan))(vs)
    F_c = jax.vmap(lambda a: force_scale(robot, a, load, gravity))(acts)
    x0 = jax.vmap(lambda a, f: straight_rod(robot, a, load, gravity, f))(acts, F_c)
    offsets = jnp.concatenate([jnp.zeros((1, x0.shape[1])), GRID_FD * jnp.eye(x0.shape[1])])

    def at(a, f, x):
        r, tip = shoot(robot, a, load, gravity, solver, x, f)
        return r, tip.p, tip.R

    def body(c):
        x, _, _, _, it = c
        r, p, R = jax.vmap(jax.vmap(at, (None, None, 0)))(acts, F_c, x[:, None, :] + offsets[None])
        J = jnp.swapaxes(r[:, 1:] - r[:, :1], 1, 2) / GRID_FD
        r0 = r[:, 0]
        done = jnp.max(jnp.abs(r0), axis=1) <= GRID_TOL
        step = jnp.linalg.solve(J, r0[..., None])[..., 0]
        return jnp.where(done[:, None], x, x - step), r0, p[:, 0], R[:, 0], it + 1

    def cond(c):
        r, it = c[1], c[-1]
        return (it == 0) | ((it <= GRID_NEWTON) & jnp.any(~(jnp.max(jnp.abs(r), axis=1) <= GRID_TOL)))

    init = (x0, jnp.zeros_like(x0), jnp.zeros((len(vs), 3)), jnp.zeros((len(vs), 3, 3)), 0)
    _, r, p, R, _ = lax.while_loop(cond, body, init)
    e = jax.vmap(lambda p, R: task_residual(p, R, prob.target, robot.length))(p, R)
    misfit = jnp.where(jnp.max(jnp.abs(r), axis=1) <= GRID_TOL, jnp.sum(e**2, axis=1), jnp.inf)
    return vs[jnp.argmin(misfit)]
