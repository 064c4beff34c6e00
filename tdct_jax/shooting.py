"""Shooting: from the six base unknowns to the tip residual, and its root with implicit derivatives.

The unknowns x are the total force and moment at the base, N(0) and M(0), scaled by a typical
force F_c (and F_c L): both segments are integrated from the base, and the residual is the
mismatch with the tip load, scaled the same way (docs/model.md, "Shooting").
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from . import general, multiple, status
from .contact import SMOOTHING
from .description import GeneralRobot
from .integrate import rk4
from .loads import Actuation, TipLoad
from .newton import broyden, continuation, lazily, unset_root
from .options import SolverOptions
from .robot import Robot
from .segments import E3, Segment, State, carried, paper_transition, uncarried, vector_field
from .so3 import rotation_columns


def segments(robot: Robot, act: Actuation, solver: SolverOptions) -> tuple[Segment, Segment]:
    """The backbone [0, d] and silicone-only [d, L] segments."""
    tau = jnp.asarray(act.tensions)
    r = robot.tendon_positions
    K_se = robot.shear_stiffness()
    exact = solver.tendon_model == "exact"
    back = Segment(K_se, robot.bending_stiffness(True), robot.linear_density(True), tau, r, jnp.ones(()), exact)
    sil = Segment(K_se, robot.bending_stiffness(False), robot.linear_density(False), tau, r, jnp.zeros(()))
    return back, sil


def force_scale(robot: Robot, act: Actuation, load: TipLoad, gravity):
    """A typical force F_c [N] that scales unknowns and residual: tensions, tip load and weight.

    A constant for differentiation: it only reparametrises the unknowns.
    """
    if isinstance(robot, GeneralRobot):
        return general.force_scale(robot, act, load, gravity)
    robot, act, load, gravity = lax.stop_gradient((robot, act, load, gravity))
    weight = jnp.linalg.norm(gravity) * (robot.linear_density(False) * robot.length + robot.tube_linear_density * act.insertion)
    F = jnp.sum(act.tensions) + jnp.linalg.norm(load.force) + jnp.linalg.norm(load.moment) / robot.length + weight
    return jnp.maximum(F, 1e-3)


def straight_rod(robot: Robot, act: Actuation, load: TipLoad, gravity, F_c, steps: int | None = None):
    """Scaled base unknowns of the straight rod: exact in force, first-order in moment (with a
    scene, ``steps`` given: no contact force, ``general.straight_rod``)."""
    if isinstance(robot, GeneralRobot):
        return general.straight_rod(robot, act, load, gravity, F_c, steps)
    L, d = robot.length, act.insertion
    rho1, rho2 = robot.linear_density(False), robot.tube_linear_density
    N0 = load.force + gravity * (rho1 * L + rho2 * d)
    M0 = load.moment + jnp.cross(L * E3, load.force) + jnp.cross(E3, gravity) * (rho1 * L**2 + rho2 * d**2) / 2
    return jnp.concatenate([N0 / F_c, M0 / (F_c * L)])


def scaled(robot: Robot, wrench, F_c):
    """A base wrench (N(0) [N], M(0) [N m]) as scaled unknowns; entries beyond the sixth (a
    GeneralRobot's displacement-driven tensions [N]) are scaled like forces."""
    return jnp.concatenate([wrench[:3] / F_c, wrench[3:6] / (F_c * robot.length), wrench[6:] / F_c])


def unscaled(robot: Robot, x, F_c):
    """The base wrench (N(0) [N], M(0) [N m]) of scaled unknowns x, followed by any
    displacement-driven tensions [N] (the inverse of ``scaled``)."""
    return jnp.concatenate([x[:3] * F_c, x[3:6] * (F_c * robot.length), x[6:] * F_c])


def per_piece(seg: Segment, length, n: int):
    """A segment as one RK4 piece of n steps (``integrate``'s ``steps``): its parameters and step
    length with a leading axis of 1."""
    return jax.tree.map(lambda a: jnp.asarray(a)[None], seg), jnp.reshape(length / n, (1,))


def integrate(segs: Segment, y: State, h, gravity, path: bool = False, steps: int = 1, rotation=None):
    """RK4 from the State y over pieces of ``steps`` steps of length h[j] with segments ``segs``
    (``per_piece``), R carried as ``rotation`` says (``SolverOptions.rotation``) and projected back
    onto SO(3) after each step; with ``path`` also the States at every node."""
    y = carried(y, rotation)
    out = rk4(lambda seg, y: vector_field(seg, gravity)(y), y, h, segs, steps, lambda y: y.orthonormalized(), path)
    return tuple(map(uncarried, out)) if path else uncarried(out)


def shoot(robot: Robot, act: Actuation, load: TipLoad, gravity, solver: SolverOptions, x, F_c, path: bool = False, mu=0.0):
    """Integrates both segments from the scaled base unknowns x to the tip.

    Returns:
        The scaled tip residual (6,) and the tip State (with ``path``: the States at all
        2 * steps + 1 nodes, s = d once). A GeneralRobot goes to ``general.shoot`` (mu: the
        contact rows' smoothing there).
    """
    if isinstance(robot, GeneralRobot):
        return general.shoot(robot, act, load, gravity, solver, x, F_c, path, mu)
    back, sil = segments(robot, act, solver)
    L, d, n = robot.length, act.insertion, solver.steps
    y0 = State(jnp.zeros(3), jnp.eye(3), x[:3] * F_c, x[3:] * F_c * L)
    (seg_b, h_b), (seg_s, h_s) = per_piece(back, d, n), per_piece(sil, L - d, n)
    if solver.transition == "balanced" and back.tilt == sil.tilt:
        # one scan over both segments: the state is continuous at s = d, and both segments share
        # the vector field's code, compiled once
        segs, h = jax.tree.map(lambda a, b: jnp.concatenate([a, b]), (seg_b, h_b), (seg_s, h_s))
        out = integrate(segs, y0, h, gravity, path, n, solver.rotation)
        y_L, ys = out if path else (out, None)
    else:
        out_b = integrate(seg_b, y0, h_b, gravity, path, n, solver.rotation)
        y_d = out_b[0] if path else out_b
        if solver.transition == "paper":
            jumped = paper_transition(back, sil, y_d)
            inside = (d > 0) & (d < L)
            y_d = jax.tree.map(lambda a, b: jnp.where(inside, a, b), jumped, y_d)
        out_s = integrate(seg_s, y_d, h_s, gravity, path, n, solver.rotation)
        y_L = out_s[0] if path else out_s
        ys = jax.tree.map(lambda a, b: jnp.concatenate([a, b[1:]]), out_b[1], out_s[1]) if path else None
    res = jnp.concatenate([(y_L.N - load.force) / F_c, (y_L.M - load.moment) / (F_c * L)])
    return (res, ys) if path else (res, y_L)


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


def starts(robot: Robot, act: Actuation, load: TipLoad, gravity, guess, F_c, steps: int | None = None):
    """Newton's scaled start: ``guess`` (``root``) where finite, else the straight rod; and the
    straight rod's unknowns (``straight_rod``; any contact forces not guessed: zero)."""
    x_straight = straight_rod(robot, act, load, gravity, F_c, steps)
    finite = jnp.all(jnp.isfinite(guess))
    start = scaled(robot, guess, F_c)
    if x_straight.size > start.size:  # a GeneralRobot's displacement-driven tensions and contact forces
        start = jnp.concatenate([start, x_straight[start.size :]])
    return jnp.where(finite, start, x_straight), x_straight


def loads_at(robot: Robot, act: Actuation, load: TipLoad, gravity, lam):
    """Actuation, load and gravity with every load times lam (the load continuation's stage)."""
    act_lam = act.scaled(lam) if isinstance(robot, GeneralRobot) else dataclasses.replace(act, tensions=lam * act.tensions)
    load_lam = TipLoad(lam * load.force, lam * load.moment) if isinstance(load, TipLoad) else load.scaled(lam)
    return act_lam, load_lam, lam * gravity


def root(robot: Robot, act: Actuation, load: TipLoad, gravity, guess, solver: SolverOptions):
    """The scaled base unknowns x with a zero tip residual, and RootInfo.

    Newton starts from ``guess`` (a base wrench, (6,), optionally followed by the displacement-driven
    tensions [N]) where it is finite, else from the straight rod. Derivatives of x with respect to
    every input come from the implicit function theorem. With ``solver.intervals`` > 1 by multiple
    shooting (``multiple.root``): the same root, and RootInfo's Jacobians single shooting's.
    """
    if solver.intervals > 1:
        u, info = multiple.root(robot, act, load, gravity, guess, solver)
        return u.x, info
    return _root(robot, act, load, gravity, guess, solver)


@jax.custom_jvp
def _root(robot: Robot, act: Actuation, load: TipLoad, gravity, guess, solver: SolverOptions):
    """``root`` by single shooting."""
    found = _single(robot, act, load, gravity, guess, solver)
    return found.x, RootInfo(found.iterations, found.stages, found.result, found.jacobians)


def root_in_inputs(robot: Robot, actuation, v, load: TipLoad, gravity, guess, solver: SolverOptions):
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


def _single(robot: Robot, act: Actuation, load: TipLoad, gravity, guess, solver: SolverOptions, inputs=None):
    """The ``newton.Root`` by single shooting; ``inputs``: (actuation, v) of ``root_in_inputs``."""
    F_c = force_scale(robot, act, load, gravity)
    x0, x_straight = starts(robot, act, load, gravity, guess, F_c, solver.steps)

    def F_at(lam, mu=0.0):
        def F(x, v=None):
            act_lam, load_lam, gravity_lam = loads_at(robot, act if v is None else inputs[0](v), load, gravity, lam)
            res, tip = shoot(robot, act_lam, load_lam, gravity_lam, solver, x, F_c, mu=mu)
            return res, (tip.p, tip.R)

        return F

    if getattr(load, "scene", None) is None:
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


def quick_root(robot: Robot, act: Actuation, load: TipLoad, gravity, solver: SolverOptions, max_steps) -> QuickRoot:
    """The root by at most ``max_steps`` Broyden steps from the straight rod (``newton.broyden``):
    one Jacobian pass, then one integration per step, no load continuation. Not differentiable
    (``root`` is): the batch engine's first pass, whose unconverged lanes ``root`` solves again."""
    F_c = force_scale(robot, act, load, gravity)

    def F(x):
        res, tip = shoot(robot, act, load, gravity, solver, x, F_c)
        return res, (tip.p, tip.R)

    x, res, (p, R), steps, code = broyden(
        F, straight_rod(robot, act, load, gravity, F_c, solver.steps), QUICK_TOL * solver.tol, max_steps
    )
    return QuickRoot(x, res, p, R, steps, code)


@_root.defjvp
def _root_jvp(primals, tangents):
    """Implicit differentiation: dx = -J^-1 (d residual / d inputs) d inputs, with Newton's J."""
    robot, act, load, gravity, guess, solver = primals
    x, info = _root(*primals)
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
def at_root(robot: Robot, act: Actuation, load: TipLoad, gravity, solver: SolverOptions, x, J):
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


def compliance_at(robot: Robot, act: Actuation, load: TipLoad, gravity, solver: SolverOptions, x):
    """``tip_compliance`` at the scaled unknowns x (a root), its Jacobians taken here by forward
    mode: an ordinary differentiable function of every input and of x."""
    F_c = force_scale(robot, act, load, gravity)

    def pose(x):
        res, tip = shoot(robot, act, load, gravity, solver, x, F_c)
        return (res, (tip.p, tip.R)), tip.R

    (J_res, (J_p, J_R)), R = jax.jacfwd(pose, has_aux=True)(x)
    return tip_compliance(robot, R, J_res, J_p, J_R, F_c)
