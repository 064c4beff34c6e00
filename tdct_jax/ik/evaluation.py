"""One IK evaluation: a converged forward solve at the scaled inputs v with the task residual, the
objective and their exact derivatives in v."""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax import lax

from .. import rod
from ..integrate import coupled
from ..roots import root
from ..shooting import RootInfo, at_root, force_scale, load_columns, scaled, shoot, tip_compliance, unscaled
from ..solve import solution_and_compliance
from .objectives import objective_value
from .problem import Plan, Problem, _wrench, actuation_of, task_residual


class Evaluation(NamedTuple):
    """A converged forward solve at v and what the IK needs of it."""

    e: jax.Array  # task residual
    G: jax.Array  # de/dv
    phi: jax.Array  # objective (0 without one)
    dphi: jax.Array  # d phi / dv
    wrench: jax.Array  # base wrench, the next solve's start
    code: jax.Array  # the forward solve's status code


def unset(v, wrench, prob: Problem) -> Evaluation:
    """An Evaluation of zeros at the base wrench ``wrench`` (no evaluation): a loop's state
    before its first, without tracing ``evaluate`` for the shapes."""
    m, k = prob.target.size, v.shape[0]
    return Evaluation(jnp.zeros(m), jnp.zeros((m, k)), jnp.zeros(()), jnp.zeros(k), wrench, jnp.zeros((), jnp.int32))


def evaluate(v, guess, prob: Problem, plan: Plan) -> Evaluation:
    """Forward solve at v (from ``guess``) with the task residual, the objective and their exact
    derivatives in v. A user's objective, which sees the whole Solution, goes through the
    implicitly differentiated solve (``_through_solution``); the others take one forward-mode
    pass over the shooting unknowns x and v together at the root (``_one_pass``)."""
    if callable(plan.objective):
        return _through_solution(v, guess, prob, plan)
    problem = (prob.robot, actuation_of(v, prob, plan), prob.load, prob.gravity)
    return evaluate_at(v, *root(*lax.stop_gradient(problem), guess, prob.solver), prob, plan)


def evaluate_at(v, x, info: RootInfo, prob: Problem, plan: Plan, taken=None) -> Evaluation:
    """``evaluate`` (not for a user's objective) at the root x at v that ``root`` found elsewhere
    (its RootInfo ``info``), e.g. by ``find``'s one forward solve; ``taken``: the Jacobians in
    (x, v) and the tip that ``root_in_inputs`` took with it (``_one_pass``)."""
    problem = (prob.robot, actuation_of(v, prob, plan), prob.load, prob.gravity)
    F_c = force_scale(*problem)
    # x with root's implicit derivatives, for the derivatives of this evaluation (``_find_jvp``)
    x = at_root(*problem, prob.solver, x, info.jacobians[0])
    e, G, phi, dphi = _one_pass(x, v, F_c, prob, plan, taken)
    return Evaluation(e, G, phi, dphi, unscaled(prob.robot, x, F_c), info.result)


def _one_pass(x, v, F_c, prob: Problem, plan: Plan, taken=None):
    """(e, G, phi, dphi) at the root x at v from one forward-mode pass of the shooting residual r
    and the tip pose over z = (x, v), with x eliminated by the implicit function theorem:
    dz/dv = (-(dr/dx)^-1 dr/dv, I). ``taken``: ((J_r, J_p, J_R), p, R), that pass's Jacobians and
    tip, taken already (``root_in_inputs``'s Newton pass; primal only): no pass here. The
    stiffness objective's compliance (eq. 41) comes from the pass's columns in x, its derivative
    in v from one more pass (``_compliance_change``)."""
    n, k = x.shape[0], v.shape[0]

    def tip(z):
        r, y = shoot(prob.robot, actuation_of(z[n:], prob, plan), prob.load, prob.gravity, prob.solver, z[:n], F_c)
        return r, y.p, y.R

    z = jnp.concatenate([x, v])
    if taken is not None:
        (J_r, J_p, J_R), p, R = taken
    else:
        (J_r, J_p, J_R), (_, p, R) = jax.jacfwd(lambda z: (lambda o: (o, o))(tip(z)), has_aux=True)(z)
    D = jnp.concatenate([-jnp.linalg.solve(J_r[:, :n], J_r[:, n:]), jnp.eye(k)])

    def task(p, R):
        return task_residual(p, R, prob.target, prob.robot.length)

    e, G = task(p, R), _along(task, (p, R), (J_p @ D, J_R @ D), (1, 2))
    if plan.objective is None:
        return e, G, jnp.zeros(()), jnp.zeros(k)
    if plan.objective == "stiffness":
        C = tip_compliance(prob.robot, R, J_r[:, :n], J_p[:, :n], J_R[..., :n], F_c)
        dC = jnp.zeros((6, 6, k)).at[:3, :3].set(_compliance_change(z, D, J_r[:, :n], J_p[:, :n], F_c, prob, plan))

        def stiffness(C):  # of the positional compliance alone
            return objective_value(None, C, None, prob, plan)

        return e, G, stiffness(C), _along(stiffness, (C,), (dC,), (2,))

    def objective(z):
        act = rod.with_driven(actuation_of(z[n:], prob, plan), z[:n], F_c)  # the driven tensions found
        return objective_value(None, None, act, prob, plan)

    return e, G, objective(z), _along(objective, (z,), (D,), (1,))


def _along(f, primals, tangents, axes):
    """f's derivative along every column of the tangents (their axes ``axes``), last axis."""
    return jax.vmap(lambda t: jax.jvp(f, primals, t)[1], in_axes=(axes,), out_axes=-1)(tangents)


def _compliance_change(z, D, M, P, F_c, prob: Problem, plan: Plan):
    """dC/dv (3, 3, k) of the positional compliance C = P U (eq. 41) at the root z = (x, v):
    U = M^-1 B, with M = dr/dx, P = d tip p / dx and B the tip force's columns of dr/dF_e
    (``load_columns``). Along dz/dv (D's columns) C changes by dP U - P M^-1 dM U, and (dM U, dP U)
    come from one forward pass along D of the pass along U's three columns in x: 3 k second-order
    directions, where the whole second-order Jacobian of (r, p) in x and z takes 6 (n + k)."""
    n = M.shape[0]
    U = jnp.linalg.solve(M, load_columns(prob.robot, n, F_c)[:, :3])

    def along_U(z):  # (dr/dx U, dp/dx U) at z
        def rp(x):
            r, y = shoot(prob.robot, actuation_of(z[n:], prob, plan), prob.load, prob.gravity, prob.solver, x, F_c)
            return r, y.p

        # U coupled to z: the second-order tangents start batched along D and nonzero, as one
        # step makes them
        return _along(rp, (z[:n],), (coupled(U, z),), (1,))

    dMU, dPU = _along(along_U, (z,), (D,), (1,))  # (n, 3, k), (3, 3, k)
    k = D.shape[1]
    return dPU - jnp.einsum("ij,jbk->ibk", P, jnp.linalg.solve(M, dMU.reshape(n, 3 * k)).reshape(n, 3, k))


def _through_solution(v, guess, prob: Problem, plan: Plan) -> Evaluation:
    """``evaluate`` for a user's objective: forward mode through the implicitly differentiated
    root and one integration to the tip, and the whole Solution for the objective."""

    def f(v):
        act = actuation_of(v, prob, plan)
        problem = (prob.robot, act, prob.load, prob.gravity)
        F_c = force_scale(*problem)
        sol = solution_and_compliance(*problem, guess, prob.solver)[0]
        x, code = scaled(prob.robot, _wrench(sol, act), F_c), sol.result
        e = task_residual(sol.tip_position, sol.tip_rotation, prob.target, prob.robot.length)
        pulled = rod.with_driven(act, x, F_c)  # the driven tensions found
        phi = objective_value(sol, None, pulled, prob, plan)
        return (e, phi), (e, phi, unscaled(prob.robot, x, F_c), code)

    (G, dphi), (e, phi, wrench, code) = jax.jacfwd(f, has_aux=True)(v)
    return Evaluation(e, G, phi, dphi, wrench, code)
