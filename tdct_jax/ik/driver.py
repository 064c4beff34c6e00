"""The IK solve: phase 1 from each start until one reaches, phase 2 with an objective, the
implicit derivatives of the answer, and the compiled solve with the result's numbers."""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from .. import status
from ..inputs import GeneralActuation
from ..shooting import force_scale, root, unscaled
from ..solve import solution_and_compliance
from .evaluation import evaluate
from .objectives import objective_value
from .optimise import optimise
from .problem import IKResult, Plan, Problem, _wrench, actuation_of, pose_errors
from .reach import Model, Reach, _usable, _where, no_model, reach_augmented, reach_nested
from .starts import STARTS, nearest_on_grid, starts


class Found(NamedTuple):
    v: jax.Array
    wrench: jax.Array
    steps: jax.Array
    code: jax.Array
    model: Model  # phase 1's last linearisation (``Model``; tip NaN)


class Tried(NamedTuple):
    """``find``'s loop over the starts: how many were tried, the best phase-1 end so far, the
    steps taken over all of them."""

    k: jax.Array
    best: Reach
    steps: jax.Array


def _lazily(needed, f, otherwise):
    """f() where ``needed``, else ``otherwise``: a while loop of at most one pass rather than
    ``lax.cond``, so that under ``vmap`` f runs only when some lane needs it."""
    return lax.while_loop(lambda c: c[0], lambda c: (jnp.zeros_like(c[0]), f()), (needed, otherwise))[1]


@functools.partial(jax.custom_jvp, nondiff_argnums=(5,))
def find(prob: Problem, v0, wrench0, n_starts, model: Model, plan: Plan) -> Found:
    """The IK solution in scaled inputs (see the module docstring), from v0 (and the converged or
    NaN base wrench there; with a usable ``model`` at v0, a warm update from it), then from the
    grid start (``nearest_on_grid``) and ``starts`` until one reaches (the nearest pose of them
    all otherwise); its derivatives by implicit differentiation (``_find_jvp``)."""
    candidates = starts(v0, prob, plan)
    cold = no_model(prob, plan)
    warm = _usable(model)

    def reach(v, wrench, first):
        if plan.method == "nested":
            return reach_nested(v, wrench, prob, plan)._replace(model=cold)
        return reach_augmented(v, wrench, prob, plan, _where(first, model, cold))

    def cond(c):
        return (c.k < n_starts) & (c.best.code != status.SUCCESS)

    def body(c):
        k, best, steps = c
        grid = _lazily(cond(c) & (k == 1), lambda: nearest_on_grid(prob, plan), v0)
        v = jnp.where(k == 1, grid, candidates[jnp.maximum(k - 1, 0)])
        guess = jnp.where(k == 0, wrench0, jnp.nan)
        problem = (prob.robot, actuation_of(v, prob, plan), prob.load, prob.gravity)

        def solved():
            x, info = root(*problem, guess, prob.solver)
            return unscaled(prob.robot, x, force_scale(*problem)), info.result.astype(jnp.int32)

        # a warm update's wrench0 is the converged solve at v0
        wrench, code = lax.cond(warm & (k == 0), lambda: (wrench0, jnp.int32(status.SUCCESS)), solved)
        r = reach(v, wrench, k == 0)
        r = r._replace(code=jnp.where(code == status.SUCCESS, r.code, code))
        rank, best_rank = (
            jnp.where(x.code == status.SUCCESS, 0, jnp.where(x.code == status.UNREACHABLE, 1, 2)) for x in (r, best)
        )
        closer = (rank < best_rank) | ((rank == best_rank) & (r.e @ r.e < best.e @ best.e))
        return Tried(k + 1, jax.tree.map(lambda a, b: jnp.where(closer, a, b), r, best), steps + r.steps)

    none = Reach(
        v0, jnp.full(jnp.shape(wrench0), jnp.nan), jnp.full(prob.target.size, jnp.inf), 0, jnp.int32(status.OUTER_LIMIT), cold
    )
    tried = lax.while_loop(cond, body, Tried(0, none, 0))
    r = tried.best._replace(steps=tried.steps)
    if plan.objective is not None:
        o = optimise(r.v, r.wrench, prob, plan)
        use = r.code == status.SUCCESS
        r = jax.tree.map(lambda a, b: jnp.where(use, a, b), Reach(o.v, o.wrench, o.e, r.steps + o.steps, o.code, r.model), r)
    return Found(r.v, r.wrench, r.steps, r.code, r.model)


@find.defjvp
def _find_jvp(plan, primals, tangents):
    """Implicit differentiation of the optimality conditions at the solution: inputs at a bound
    follow the bound; the others keep e = 0 (the minimum-norm change when the task does not fix
    them) or, with an objective, the KKT conditions grad phi + G^T lam = 0, e = 0."""
    prob, v0, wrench0, n_starts, model = primals
    dprob = tangents[0]
    found = find(prob, v0, wrench0, n_starts, model, plan)
    v, wrench = found.v, found.wrench

    def at(prob, v):
        return evaluate(v, wrench, prob, plan)

    ev, dev = jax.jvp(lambda prob: at(prob, v), (prob,), (dprob,))
    lo_active, hi_active = v <= prob.lo, v >= prob.hi
    dv_bound = jnp.where(lo_active, dprob.lo, jnp.where(hi_active, dprob.hi, 0.0))
    free = ~(lo_active | hi_active)
    G = ev.G * free[None, :]
    rhs_e = dev.e + ev.G @ dv_bound
    if plan.objective is None:
        dv = -jnp.linalg.pinv(G) @ rhs_e
    else:
        scale = jnp.maximum(jnp.abs(ev.phi), 1e-300)
        lam = -jnp.linalg.pinv(G.T) @ (ev.dphi * free / scale)

        def lagrangian_gradient(prob, v):
            e = at(prob, v)
            return e.dphi / scale + e.G.T @ lam

        W, dL = (
            jax.jacfwd(lambda v: lagrangian_gradient(prob, v))(v),
            jax.jvp(lambda p: lagrangian_gradient(p, v), (prob,), (dprob,))[1],
        )
        n, m = v.shape[0], ev.e.shape[0]
        F = free.astype(v.dtype)
        K = jnp.block([[W * F[:, None] * F[None, :] + jnp.diag(1 - F), G.T], [G, -1e-14 * jnp.eye(m)]])
        rhs = jnp.concatenate([-(dL + W @ dv_bound) * F, -rhs_e])
        dv = jnp.linalg.solve(K, rhs)[:n]
    dv = jnp.where(free, dv, dv_bound)
    zero = jax.tree.map(_zero_like, (wrench, found.steps, found.code, found.model))
    return found, Found(dv, *zero)


def _zero_like(x):
    x = jnp.asarray(x)
    return jnp.zeros_like(x) if jnp.issubdtype(x.dtype, jnp.inexact) else np.zeros(x.shape, jax.dtypes.float0)


@functools.partial(jax.jit, static_argnames=("plan",))
def _solve_ik(prob: Problem, v0, wrench0, plan: Plan, *, n_starts=STARTS, model=None):
    """``find`` (warm from ``model``, a Model at v0, when given), then the forward solve there and
    the result's numbers; (IKResult, wrench, the Model for the next warm update)."""
    model = no_model(prob, plan) if model is None else model
    found = find(prob, v0, wrench0, n_starts, model, plan)
    act = actuation_of(found.v, prob, plan)
    sol, C = solution_and_compliance(prob.robot, act, prob.load, prob.gravity, found.wrench, prob.solver)
    if isinstance(act, GeneralActuation):  # the driven tendons' tensions as found
        act = GeneralActuation._rebuild(sol.tensions, act.insertions, act.displacements, act.driven)
    position, orientation = pose_errors(sol.tip_position, sol.tip_rotation, prob.target)
    phi = jnp.nan if plan.objective is None else objective_value(sol, C, act, prob, plan)
    code = jnp.where(sol.result == status.SUCCESS, found.code, sol.result).astype(jnp.int32)
    result = IKResult(act, sol, position, orientation, jnp.asarray(phi, float), found.steps, code)
    return result, _wrench(sol, act), found.model._replace(tip_position=sol.tip_position, tip_rotation=sol.tip_rotation)
