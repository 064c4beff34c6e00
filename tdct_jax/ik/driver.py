"""The IK solve: phase 1 from each start until one reaches, phase 2 with an objective, the
implicit derivatives of the answer, and the compiled solve with the result's numbers."""

from __future__ import annotations

import dataclasses
import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from .. import status
from ..inputs import Actuation
from ..newton import lazily
from ..roots import root
from ..shooting import (
    RootInfo,
    at_root,
    force_scale,
    jacobians_at_root,
    root_in_inputs,
    scaled,
    tip_compliance,
    unscaled,
    unset_info,
)
from ..solve import solution_and_compliance, solution_at
from .evaluation import evaluate, evaluate_at
from .objectives import objective_value
from .optimise import SQPState, sqp_start, sqp_step
from .problem import IKResult, Plan, Problem, _wrench, actuation_of, pose_errors
from .reach import (
    START_TOL,
    Model,
    NestedState,
    Reach,
    _usable,
    _where,
    nested_start,
    nested_step,
    no_model,
    reach_augmented,
    refreshed,
)
from .starts import STARTS, nearest_on_grid, starts


class Found(NamedTuple):
    v: jax.Array
    wrench: jax.Array
    steps: jax.Array
    code: jax.Array
    model: Model  # phase 1's last linearisation (``Model``; tip NaN)
    chords: jax.Array  # how many of the steps were chord steps
    x: jax.Array  # the forward solve at v, scaled unknowns: the closing one, or phase 1's where it
    # reached (unset with multiple shooting)
    info: RootInfo  # and its RootInfo (phase 1's: no Jacobians, NaN)
    reached: jax.Array  # phase 1 reached the target (phase 2 ran where there is an objective): more
    # starts would give the same answer, since each is tried only after the one before fell short
    e: jax.Array  # phase 1's task residual at v (with ``code``, how the starts' ends are ranked)


class Ended(NamedTuple):
    """How phase 1 ended, for a batch that runs a target's starts side by side: whether it reached
    (``Found.reached``), its code and |e|^2 there (``Found.code``, ``Found.e``), by which ``find``
    ranks the ends of its starts (``rank``)."""

    reached: jax.Array
    code: jax.Array
    e2: jax.Array


def rank(code):
    """How ``find`` orders the ends of its starts, best first: reached, unreachable (the nearest
    pose), a failure; within a rank, the smaller |e|."""
    return jnp.where(code == status.SUCCESS, 0, jnp.where(code == status.UNREACHABLE, 1, 2))


REACH, OPTIMISE, CLOSE, DONE = range(4)
"""``find``'s passes: phase 1 from one start (nested: a step of it), a step of phase 2 (with an
objective), the closing forward solve at the answer, and the end."""


class Tried(NamedTuple):
    """``find``'s loop: its pass (REACH ...), how many starts were tried, the best end so far, the
    steps taken over all of them, the last forward solve (scaled unknowns, RootInfo), phase 2's
    state (None without an objective) and nested phase 1's."""

    phase: jax.Array
    k: jax.Array
    best: Reach
    steps: jax.Array
    x: jax.Array
    info: RootInfo
    sqp: SQPState | None
    nested: NestedState | None  # nested phase 1's state (None: augmented)
    i: jax.Array  # passes so far


@functools.partial(jax.custom_jvp, nondiff_argnums=(5,))
def find(prob: Problem, v0, wrench0, tries, model: Model | None, plan: Plan) -> Found:
    """The IK solution in scaled inputs (see the module docstring), from v0 (and the converged or
    NaN base wrench there; with a usable ``model`` at v0, a warm update from it; None: no warm
    update compiled), then from the grid start (``nearest_on_grid``) and ``starts`` until one
    reaches (the nearest pose of them all otherwise; nested phase 1 a step a pass), then phase 2 a
    step a pass, then the forward solve at the answer unless phase 1 reached at a converged one:
    one loop whose passes share one forward solve in the compiled program. ``tries`` = (first,
    stop): the starts tried are first, ..., stop - 1 in that order (0 is v0, 1 the grid start, then
    ``starts``' others). Its derivatives by implicit differentiation (``_find_jvp``)."""
    first_start, n_starts = tries
    candidates = starts(v0, prob, plan)
    cold = no_model(prob, plan)
    nested = plan.method == "nested"  # phase 1 a step a pass, through this loop's forward solve
    warm = False if model is None or nested else _usable(model)
    closing = prob.solver.intervals == 1  # multiple shooting: ``_solve_ik`` solves at the answer itself
    shared = not callable(plan.objective)  # a user's objective: phase 2 solves through the Solution
    # phase 2 (and nested phase 1) read their task Jacobian from the forward solve's Newton pass,
    # taken in v as well (``root_in_inputs``), not from a pass of their own: one copy of the
    # Jacobian pass fewer in the program
    in_inputs = closing and (nested or (shared and plan.objective is not None))
    bare = plan._replace(objective=None)  # phase 1 evaluates the task alone

    def kept(r, best):  # the nearer of a start's end and the best so far
        closer = (rank(r.code) < rank(best.code)) | ((rank(r.code) == rank(best.code)) & (r.e @ r.e < best.e @ best.e))
        return jax.tree.map(lambda a, b: jnp.where(closer, a, b), r, best)

    def after_reach(k, best):
        more = (k < n_starts) & (best.code != status.SUCCESS)
        # phase 1 reaches at a converged forward solve: without an objective, the answer
        ends = OPTIMISE if plan.objective is not None else DONE
        return jnp.where(more, REACH, jnp.where(best.code == status.SUCCESS, ends, CLOSE))

    def step(c):
        phase, k, best, sqp, ns = c.phase, c.k, c.best, c.sqp, c.nested
        reaching, optimising = phase == REACH, phase == OPTIMISE
        fresh = reaching if ns is None else reaching & (ns.it == 0)  # this pass begins start k
        grid = lazily(fresh & (k == 1), lambda prob: nearest_on_grid(prob, plan), v0, prob)
        v = jnp.where(k == 1, grid, candidates[jnp.clip(k - 1, 0, len(candidates) - 1)])
        guess = jnp.where(k == 0, wrench0, jnp.nan)
        if ns is not None:  # nested phase 1's trial point
            ns = _where(fresh, nested_start(v, guess, prob), ns)
            v, guess = jnp.where(reaching, ns.v + ns.s, v), jnp.where(reaching, ns.ev.wrench, guess)
        if sqp is not None:  # phase 2's trial point
            v, guess = jnp.where(optimising, sqp.v + sqp.s, v), jnp.where(optimising, sqp.ev.wrench, guess)
        v, guess = jnp.where(phase == CLOSE, best.v, v), jnp.where(phase == CLOSE, best.wrench, guess)
        problem = (prob.robot, actuation_of(v, prob, plan), prob.load, prob.gravity)
        # a warm update's wrench0 is the converged solve at v0
        skip = warm & (k == 0) & reaching
        solving = (reaching & ~skip) | (phase == CLOSE) | (optimising & shared)
        # augmented phase 1 converges the boundary residual along with the task: a start's forward
        # solve need only come near it (START_TOL)
        tol = prob.solver.tol if nested else jnp.where(reaching, jnp.maximum(START_TOL, prob.solver.tol), prob.solver.tol)
        solver = dataclasses.replace(prob.solver, tol=tol)

        def forward(problem, v, guess):  # (x, RootInfo, and with ``in_inputs`` what ``root_in_inputs`` took)
            if in_inputs:
                actuation = functools.partial(actuation_of, prob=prob, plan=plan)
                return root_in_inputs(problem[0], actuation, v, *problem[2:], guess, solver)
            return (*root(*problem, guess, solver), None)

        x, info, taken = lazily(solving, forward, (c.x, c.info, untaken), problem, v, guess)
        wrench = jnp.where(skip, wrench0, unscaled(prob.robot, x, force_scale(*problem)))
        code = jnp.where(skip, status.SUCCESS, info.result).astype(jnp.int32)

        if ns is None:

            def reached(v, wrench):
                r = reach_augmented(v, wrench, prob, plan, None if model is None else _where(k == 0, model, cold))
                r = r._replace(code=jnp.where(code == status.SUCCESS, r.code, code))
                return kept(r, best), c.steps + r.steps

            best, steps = lazily(reaching, reached, (best, c.steps), v, wrench)
            ended = reaching
        else:

            def stepped(v, x, info, taken):
                return nested_step(ns, evaluate_at(v, x, info, prob, bare, taken), prob)

            ns = lazily(reaching, stepped, ns, v, x, info, taken)
            ended = reaching & ns.done
            r = ns.result()._replace(model=cold)
            best, steps = _where(ended, (kept(r, best), c.steps + r.steps), (best, c.steps))
            ns = ns._replace(it=jnp.where(ended, 0, ns.it))  # the next pass begins the next start
        k = jnp.where(ended, k + 1, k)
        phase = jnp.where(ended, after_reach(k, best), jnp.where(phase == CLOSE, DONE, phase))
        if sqp is not None:

            def optimised(v, x, info, guess, taken):
                trial = evaluate_at(v, x, info, prob, plan, taken) if shared else evaluate(v, guess, prob, plan)
                return sqp_step(sqp, trial, prob)

            sqp = lazily(optimising, optimised, sqp, v, x, info, guess, taken)
            # phase 2 starts where phase 1 reached the target
            sqp = _where(reaching & (phase == OPTIMISE), sqp_start(best.v, best.wrench, prob), sqp)
            ended = optimising & sqp.done
            best = _where(ended, sqp.result(best.steps)._replace(model=best.model, chords=best.chords), best)
            steps = jnp.where(ended, steps + sqp.it - 1, steps)
            phase = jnp.where(ended, CLOSE, phase)
        if not closing:
            phase = jnp.where(phase == CLOSE, DONE, phase)
        return Tried(phase, k, best, steps, x, info, sqp, ns, c.i)

    def body(c):  # a pass once DONE costs one test
        return lazily(c.phase != DONE, step, c, c)._replace(i=c.i + 1)

    n = jnp.shape(wrench0)[0]
    if in_inputs:
        nk = n + v0.shape[0]
        untaken = (jnp.zeros((n, nk)), jnp.zeros((3, nk)), jnp.zeros((3, 3, nk))), jnp.zeros(3), jnp.zeros((3, 3))
    else:
        untaken = None
    none = Reach(v0, jnp.full(n, jnp.nan), jnp.full(prob.target.size, jnp.inf), 0, jnp.int32(status.OUTER_LIMIT), cold)
    first = after_reach(first_start, none)
    sqp = None if plan.objective is None else sqp_start(v0, jnp.full(n, jnp.nan), prob)
    ns = nested_start(v0, jnp.full(n, jnp.nan), prob) if nested else None
    init = Tried(
        jnp.where(closing | (first != CLOSE), first, DONE), first_start, none, 0, jnp.zeros(n), unset_info(n), sqp, ns, 0
    )
    # the loop runs a pass for every start (nested: for each of its steps), phase 2's steps and the
    # closing solve, the last ones no-ops once the phases are DONE: a bound that XLA finds without
    # tracing the passes' data through the body (which it does for a loop whose condition reads the
    # body's results, at a cost that grows with the body's size)
    per_start = prob.options.max_steps + 1 if nested else 1
    passes = (n_starts - first_start) * per_start + 1 + (0 if plan.objective is None else prob.options.max_steps + 1)
    tried = lax.while_loop(lambda c: c.i < passes, body, init)
    r, x, info = tried.best, tried.x, tried.info
    if closing and plan.objective is None:  # reached: its root, no closing solve (``at_root`` takes J)
        F_c = force_scale(prob.robot, actuation_of(r.v, prob, plan), prob.load, prob.gravity)
        nan = jnp.full((n, n), jnp.nan), (jnp.full((3, n), jnp.nan), jnp.full((3, 3, n), jnp.nan))
        reached = (scaled(prob.robot, r.wrench, F_c), RootInfo(0, 1, jnp.int32(status.SUCCESS), nan))
        x, info = _where(r.code == status.SUCCESS, reached, (x, info))
    phase_1_reached = r.code == status.SUCCESS if sqp is None else tried.sqp.it > 0
    return Found(r.v, r.wrench, tried.steps, r.code, r.model, r.chords, x, info, phase_1_reached, r.e)


@find.defjvp
def _find_jvp(plan, primals, tangents):
    """Implicit differentiation of the optimality conditions at the solution: inputs at a bound
    follow the bound; the others keep e = 0 (the minimum-norm change when the task does not fix
    them) or, with an objective, the KKT conditions grad phi + G^T lam = 0, e = 0."""
    prob, v0, wrench0, tries, model = primals
    dprob = tangents[0]
    found = find(prob, v0, wrench0, tries, model, plan)
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
    return found, Found(dv, *jax.tree.map(_zero_like, tuple(found[1:])))


def _zero_like(x):
    x = jnp.asarray(x)
    return jnp.zeros_like(x) if jnp.issubdtype(x.dtype, jnp.inexact) else np.zeros(x.shape, jax.dtypes.float0)


@functools.partial(jax.jit, static_argnames=("plan",))
def _solve_ik(prob: Problem, v0, wrench0, plan: Plan, *, tries=(0, STARTS), model=None):
    """``find`` (warm from ``model``, a Model at v0, when given; the starts ``tries``), then the
    forward solve there and the result's numbers; (IKResult, wrench, the Model for the next warm
    update, ``Ended``: how phase 1 ended)."""
    found = find(prob, v0, wrench0, tries, model, plan)
    act = actuation_of(found.v, prob, plan)
    problem = (prob.robot, act, prob.load, prob.gravity)
    if prob.solver.intervals > 1:
        sol, C = solution_and_compliance(*problem, found.wrench, prob.solver)
    else:  # the closing solve of ``find``, differentiable
        jacobians = found.info.jacobians
        x = at_root(*problem, prob.solver, found.x, jacobians[0])
        sol = solution_at(*problem, prob.solver, x, found.info)
        if plan.objective == "stiffness":  # its value differentiable too (other plans: no second-order pass)
            jacobians = jacobians_at_root(*problem, prob.solver, x, jacobians)
        J_res, (J_p, J_R) = jacobians
        C = tip_compliance(prob.robot, sol.tip_rotation, J_res, J_p, J_R, force_scale(*problem))
    act = Actuation._rebuild(sol.tensions, act.insertions, act.displacements, act.driven)  # the driven tensions found
    position, orientation = pose_errors(sol.tip_position, sol.tip_rotation, prob.target)
    phi = jnp.nan if plan.objective is None else objective_value(sol, C, act, prob, plan)
    code = jnp.where(sol.result == status.SUCCESS, found.code, sol.result).astype(jnp.int32)
    result = IKResult(act, sol, position, orientation, jnp.asarray(phi, float), found.steps, found.chords, code)
    model = found.model._replace(tip_position=sol.tip_position, tip_rotation=sol.tip_rotation)
    if prob.solver.intervals == 1:
        model = refreshed(model, J_res, J_p, J_R, prob)
    return result, _wrench(sol, act), model, Ended(found.reached, found.code, found.e @ found.e)
