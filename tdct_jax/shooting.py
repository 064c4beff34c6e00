"""Single shooting: from the base unknowns to the tip residual, and its root with implicit derivatives.

The unknowns x are the total force and moment at the base, N(0) and M(0), scaled by a typical
force F_c (and F_c L), then any displacement-driven tendons' tensions and contact forces: the
robot is integrated from the base across its breakpoint intervals (rod.py), and the residual
is the mismatch with the tip load, scaled the same way (docs/model.md, "Shooting"). Multiple
shooting (multiple.py) builds on this module; roots.py chooses between the two.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from . import rod, status
from .contact import SMOOTHING
from .description import Robot
from .inputs import Actuation, Loads
from .newton import broyden, continuation, lazily, unset_root
from .options import SolverOptions
from .rod import force_scale, shoot, straight_rod
from .so3 import rotation_columns


def scaled(robot: Robot, wrench, F_c):
    """A base wrench (N(0) [N], M(0) [N m]) as scaled unknowns; entries beyond the sixth (a
    displacement-driven tensions [N] and contact forces) are scaled like forces."""
    return jnp.concatenate([wrench[:3] / F_c, wrench[3:6] / (F_c * robot.length), wrench[6:] / F_c])


def unscaled(robot: Robot, x, F_c):
    """The base wrench (N(0) [N], M(0) [N m]) of scaled unknowns x, followed by any
    displacement-driven tensions [N] (the inverse of ``scaled``)."""
    return jnp.concatenate([x[:3] * F_c, x[3:6] * (F_c * robot.length), x[6:] * F_c])


def residual(robot, act, load, gravity, solver, x):
    """The scaled tip residual at the scaled base unknowns x."""
    return shoot(robot, act, load, gravity, solver, x, force_scale(robot, act, load, gravity))[0]


class RootInfo(NamedTuple):
    """How the root was found: Newton steps, load stages of the last ramp, a ``status`` code, and
    Newton's last Jacobians at x: d residual / dx (6, 6) and d(tip p, tip R) / dx."""

    iterations: jax.Array
    stages: jax.Array
    result: jax.Array
    jacobians: tuple


def starts(robot: Robot, act: Actuation, load: Loads, gravity, guess, F_c, steps: int | None = None):
    """Newton's scaled start: ``guess`` (``root``) where finite, else the straight rod; and the
    straight rod's unknowns (``straight_rod``; any contact forces not guessed: zero)."""
    x_straight = straight_rod(robot, act, load, gravity, F_c, steps)
    finite = jnp.all(jnp.isfinite(guess))
    start = scaled(robot, guess, F_c)
    if x_straight.size > start.size:  # displacement-driven tensions and contact forces
        start = jnp.concatenate([start, x_straight[start.size :]])
    return jnp.where(finite, start, x_straight), x_straight


def loads_at(act: Actuation, load: Loads, gravity, lam):
    """Actuation, load and gravity with every load times lam (the load continuation's stage)."""
    return act.scaled(lam), load.scaled(lam), lam * gravity


@jax.custom_jvp
def root(robot: Robot, act: Actuation, load: Loads, gravity, guess, solver: SolverOptions):
    """The scaled unknowns x with a zero residual by single shooting, and RootInfo.

    Newton starts from ``guess`` (a base wrench, (6,), optionally followed by the displacement-driven
    tensions [N]) where it is finite, else from the straight rod. Derivatives of x with respect to
    every input come from the implicit function theorem."""
    found = _single(robot, act, load, gravity, guess, solver)
    return found.x, RootInfo(found.iterations, found.stages, found.result, found.jacobians)


def root_in_inputs(robot: Robot, actuation, v, load: Loads, gravity, guess, solver: SolverOptions):
    """``root`` by single shooting at the actuation ``actuation(v)`` of an array of inputs v, its
    Newton passes taken in v too (``newton``'s ``fixed``): (x, RootInfo, (Jacobians of the residual
    and of the tip p and R in (x, v), x's columns first; p, R)) at x. A caller that needs the
    root's derivatives in its inputs (the IK's phase 2) has them without a pass of its own. Not
    differentiable; no scene."""
    found = _single(robot, actuation(v), load, gravity, guess, solver, (actuation, v))
    (J_res, (J_p, J_R)), (p, R) = found.jacobians
    n = found.x.size
    info = RootInfo(found.iterations, found.stages, found.result, (J_res[:, :n], (J_p[:, :n], J_R[..., :n])))
    return found.x, info, ((J_res, J_p, J_R), p, R)


def _single(robot: Robot, act: Actuation, load: Loads, gravity, guess, solver: SolverOptions, inputs=None):
    """The ``newton.Root`` by single shooting; ``inputs``: (actuation, v) of ``root_in_inputs``."""
    F_c = force_scale(robot, act, load, gravity)
    x0, x_straight = starts(robot, act, load, gravity, guess, F_c, solver.steps)

    def F_at(lam, mu=0.0):
        # without displacement-driven tendons the plan does not depend on x: made once a load stage,
        # not once a Newton step
        staged = loads_at(act, load, gravity, lam)
        pl = None if act.driven or inputs is not None else rod.plan(robot, *staged)

        def F(x, v=None):
            act_lam, load_lam, gravity_lam = staged if v is None else loads_at(inputs[0](v), load, gravity, lam)
            res, tip = shoot(robot, act_lam, load_lam, gravity_lam, solver, x, F_c, mu=mu, pl=pl)
            return res, (tip.p, tip.R)

        return F

    if load.scene is None:
        return continuation(
            F_at, x0, x_straight, solver.tol, solver.max_iter, solver.stages, fixed=None if inputs is None else inputs[1]
        )
    return _contact_root(F_at, x0, x_straight, solver)


def _contact_root(F_at, x0, x_straight, solver: SolverOptions):
    """The root with contact rows: plain Newton from the contact-free start x0 (no contact: the
    contact-free solve's own steps); where it fails, the smoothed complementarity from x0, mu
    decreasing (contact.SMOOTHING), then the exact one, each from the last finite root, each with
    the load continuation. The Root of the last pass, with the Newton steps of all of them.

    The passes are those of one loop, mu and the ramps its data: the compiled program holds one
    copy of the shooting integration, not one per pass (a contact solve compiled in 3.6 s, not
    11 s). Each pass runs behind ``lazily``'s barrier; without it the same loop took 40% longer
    per Newton step on two cores (benchmarks/README.md, "One loop for the contact passes")."""
    passes = len(SMOOTHING) + 2
    mus = jnp.array((0.0, *SMOOTHING, 0.0))
    ramps = jnp.array([(1,) * len(solver.stages)] + [solver.stages] * (passes - 1), jnp.int32)
    counts = jnp.array((1,) + (len(solver.stages),) * (passes - 1), jnp.int32)

    def one(i, x, iterations):
        start = jnp.where(i <= 1, x0, x)
        found = continuation(
            lambda lam: F_at(lam, mus[i]), start, x_straight, solver.tol, solver.max_iter, ramps[i], count=counts[i]
        )
        x = jnp.where(jnp.all(jnp.isfinite(found.x)), found.x, start)
        go = (i > 0) | (found.result != status.SUCCESS)
        return x, iterations + found.iterations, found, go

    def body(i, c):
        x, iterations, found, go = c
        return lazily(go, one, c, i, x, iterations)

    init = (x0, jnp.zeros((), jnp.int32), unset_root(F_at(1.0), x0), True)
    _, iterations, found, _ = lax.fori_loop(0, passes, body, init)
    return found._replace(iterations=iterations)


QUICK_TOL = 0.1
"""``quick_root`` stops at this fraction of the solver's tolerance: Newton's last step lands far
below the tolerance, Broyden's superlinear one only just below it. With it the batch engine's
tips stay within 4e-10 m of the single solve's (1,024 envelope points; 7e-10 m at 1), no closer
than the two solutions' own distance from the exact root at that tolerance."""


class QuickRoot(NamedTuple):
    """What ``quick_root`` found: scaled unknowns x, the scaled tip residual there, the tip
    position and rotation, Broyden steps and a ``status`` code."""

    x: jax.Array
    residual: jax.Array
    tip_position: jax.Array
    tip_rotation: jax.Array
    iterations: jax.Array
    result: jax.Array


def quick_root(robot: Robot, act: Actuation, load: Loads, gravity, solver: SolverOptions, max_steps) -> QuickRoot:
    """The root by at most ``max_steps`` Broyden steps from the straight rod (``newton.broyden``):
    one Jacobian pass, then one integration per step, no load continuation. Not differentiable
    (``root`` is): the batch engine's first pass, whose unconverged lanes ``root`` solves again."""
    F_c = force_scale(robot, act, load, gravity)
    pl = None if act.driven else rod.plan(robot, act, load, gravity)  # once, not once a step (``root``)

    def F(x):
        res, tip = shoot(robot, act, load, gravity, solver, x, F_c, pl=pl)
        return res, (tip.p, tip.R)

    x, res, (p, R), steps, code = broyden(
        F, straight_rod(robot, act, load, gravity, F_c, solver.steps), QUICK_TOL * solver.tol, max_steps
    )
    return QuickRoot(x, res, p, R, steps, code)


@root.defjvp
def _root_jvp(primals, tangents):
    """Implicit differentiation: dx = -J^-1 (d residual / d inputs) d inputs, with Newton's J."""
    robot, act, load, gravity, guess, solver = primals
    x, info = root(*primals)
    dx = _implicit(robot, act, load, gravity, solver, x, info.jacobians[0], tangents[:4], taken=True)
    return (x, info), (dx, jax.tree.map(zero_tangent, info))


def _implicit(robot, act, load, gravity, solver, x, J, tangents, taken=False):
    """The tangent of the root x (Newton's d residual / dx there: J, or NaN to take it here) for
    the inputs' tangents. ``taken`` (static): J is Newton's own, never NaN, so the program holds
    no second Jacobian pass for the NaN case (under ``vmap`` both branches of a cond run)."""
    if taken:
        J = jacobians_at_root(robot, act, load, gravity, solver, x, J)
    else:
        J = lax.cond(
            jnp.all(jnp.isfinite(J)),
            lambda x, J: jacobians_at_root(robot, act, load, gravity, solver, x, J),
            lambda x, J: jax.jacfwd(lambda x: residual(robot, act, load, gravity, solver, x))(x),
            x,
            J,
        )
    _, dF = jax.jvp(lambda r, a, l, g: residual(r, a, l, g, solver, x), (robot, act, load, gravity), tangents)
    return -jnp.linalg.solve(J, dF)


@jax.custom_jvp
def at_root(robot: Robot, act: Actuation, load: Loads, gravity, solver: SolverOptions, x, J):
    """x, a root that ``root`` found elsewhere (its RootInfo's d residual / dx: J; NaN where none
    was taken there: then taken when differentiated), with ``root``'s implicit derivatives in the
    inputs: a root found inside another loop is differentiable."""
    return x


@at_root.defjvp
def _at_root_jvp(primals, tangents):
    robot, act, load, gravity, solver, x, J = primals
    return x, _implicit(robot, act, load, gravity, solver, x, J, tangents[:4])


def unset_info(n: int) -> RootInfo:
    """A RootInfo of zeros for n unknowns, shaped like ``root``'s (a loop's state before a root)."""
    zero = jnp.zeros((), jnp.int32)
    return RootInfo(zero, zero, zero, (jnp.zeros((n, n)), (jnp.zeros((3, n)), jnp.zeros((3, 3, n)))))


def zero_tangent(x):
    """The zero tangent of x (float0 for integers): for outputs that carry no derivative."""
    x = jnp.asarray(x)
    return jnp.zeros_like(x) if jnp.issubdtype(x.dtype, jnp.inexact) else np.zeros(x.shape, jax.dtypes.float0)


@jax.custom_jvp
def jacobians_at_root(robot, act, load, gravity, solver, x, jacobians):
    """Newton's Jacobians at x, free: d residual / dx alone, or with the tip's as RootInfo holds
    them, (d residual / dx, (d tip p / dx, d tip R / dx)). Their own derivatives (second order) by
    autodiff: the implicit derivatives' J, and a compliance taken from them (``tip_compliance``),
    are differentiable."""
    return jacobians


@jacobians_at_root.defjvp
def _jacobians_at_root_jvp(primals, tangents):
    robot, act, load, gravity, solver, x, jacobians = primals
    with_tip = isinstance(jacobians, tuple)

    def taken(robot, act, load, gravity, x):
        F_c = force_scale(robot, act, load, gravity)

        def pose(x):
            res, tip = shoot(robot, act, load, gravity, solver, x, F_c)
            return (res, (tip.p, tip.R)) if with_tip else res

        return jax.jacfwd(pose)(x)

    return jacobians, jax.jvp(taken, (robot, act, load, gravity, x), (*tangents[:4], tangents[5]))[1]


def tip_compliance(robot: Robot, R_tip, J_res, J_p, J_R, F_c):
    """The 6x6 tip compliance d(tip position, tip rotation vector) / d(F_e, M_e) (eq. 41) from the
    Jacobians of the residual and of the tip pose (p, R) with respect to the scaled unknowns at
    the root: the tip load enters only the residual, d res / d(F_e, M_e) = -diag(1 / F_c, 1 / (F_c L)).
    With displacement-driven tendons the displacements are held: their tensions adjust."""
    dx_dw = jnp.linalg.solve(J_res, load_columns(robot, J_res.shape[0], F_c))
    return jnp.concatenate([J_p @ dx_dw, rotation_columns(J_R @ dx_dw, R_tip)])


def load_columns(robot: Robot, n: int, F_c):
    """d residual / d(F_e, M_e) up to sign, (n, 6): diag(1 / F_c, 1 / (F_c L)) for the base
    wrench's rows. Rows beyond the sixth (displacement-driven tensions) hold the displacements,
    which the tip load does not enter: zero."""
    dres_dw = jnp.diag(jnp.repeat(jnp.stack([1 / F_c, 1 / (F_c * robot.length)]), 3))
    return jnp.concatenate([dres_dw, jnp.zeros((n - 6, 6))]) if n > 6 else dres_dw


def compliance_at(robot: Robot, act: Actuation, load: Loads, gravity, solver: SolverOptions, x):
    """``tip_compliance`` at the scaled unknowns x (a root), its Jacobians taken here by forward
    mode: an ordinary differentiable function of every input and of x."""
    F_c = force_scale(robot, act, load, gravity)

    def pose(x):
        res, tip = shoot(robot, act, load, gravity, solver, x, F_c)
        return (res, (tip.p, tip.R)), tip.R

    (J_res, (J_p, J_R)), R = jax.jacfwd(pose, has_aux=True)(x)
    return tip_compliance(robot, R, J_res, J_p, J_R, F_c)
