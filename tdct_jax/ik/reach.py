"""Phase 1, reach: bounded Levenberg-Marquardt on the task residual, "nested" (a converged forward
solve per step) or "augmented" (shooting unknowns and inputs iterated together)."""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax import lax

from .. import status
from ..qp import box_qp
from ..shooting import force_scale, scaled, shoot, unscaled
from .evaluation import Evaluation, evaluate, unset
from .problem import Plan, Problem, actuation_of, task_residual

MU_START = 1e-3
"""Initial Levenberg-Marquardt damping (relative to the diagonal of G^T G)."""
MU_WARM = 1e-10
"""Initial damping of a warm update (``reach_augmented`` with the last update's model): its model
is good, so Gauss-Newton's minimum-norm step; at MU_START the directions G barely moves (the
insertion) would converge linearly, a few steps per update."""
MU_GIVE_UP = 1e10
"""Damping at which a phase stops: no step it could take lowers its merit."""


STALLED = 1e-10
"""An accepted phase-1 step that lowers |e|^2 by less than this, relatively, ends phase 1."""
STATIONARY = 1e-7
"""Phase 1 ends above the tolerance (UNREACHABLE) when the projected gradient of |e|^2 / 2 is
below this, relative to |G| |e|: the nearest reachable pose, to about that relative precision."""


def _lm_step(G, e, mu, lo, hi):
    """The bounded Levenberg step on |e + G s|^2 + mu |G|^2 |s|^2: damping the same for every
    scaled input, so that inputs the task does not need (co-contraction) are left alone."""
    A = G.T @ G
    return box_qp(A + mu * jnp.trace(A) * jnp.eye(A.shape[0]), G.T @ e, lo, hi)[0]


def _damping(mu, nu, actual, predicted):
    """Nielsen's update of the damping from the gain ratio actual / predicted decrease: (mu, nu,
    accepted)."""
    rho = actual / jnp.where(predicted > 0, predicted, jnp.inf)
    accepted = (actual > 0) & jnp.isfinite(actual)
    mu_ok = mu * jnp.maximum(1 / 3, 1 - (2 * rho - 1) ** 3)
    return jnp.where(accepted, mu_ok, mu * nu), jnp.where(accepted, 2.0, 2 * nu), accepted


def _reach_status(e, G, v, mu, it, prob: Problem, tol, max_steps, stalled=False):
    """(status code, done) of phase 1 at a point: reached, stationary above tol (the projected
    gradient of |e|^2 / 2 vanishes, no step lowers it, or the last step lowered it by a relative
    STALLED or less), or out of steps."""
    g = G.T @ e
    free = jnp.where(v <= prob.lo, g < 0, jnp.where(v >= prob.hi, g > 0, True))
    projected = jnp.max(jnp.abs(jnp.where(free, g, 0.0)))
    scale = jnp.linalg.norm(G) * jnp.linalg.norm(e) + 1e-300
    reached = jnp.max(jnp.abs(e)) <= tol
    stationary = (projected <= STATIONARY * scale) | (mu >= MU_GIVE_UP) | stalled
    code = jnp.where(reached, status.SUCCESS, jnp.where(stationary, status.UNREACHABLE, status.OUTER_LIMIT))
    return code.astype(jnp.int32), reached | stationary | (it >= max_steps)


class Model(NamedTuple):
    """Phase 1's last linearisation, at its answer: the first step's model of the next warm
    update (``track``), which then needs no evaluation before its first step. NaN: none."""

    K: jax.Array  # d(shooting unknowns, unscaled) / dv, (n, k)
    G: jax.Array  # de / dv with the unknowns eliminated, (m, k)
    tip_position: jax.Array  # [m], of the forward solve at the answer
    tip_rotation: jax.Array


def no_model(prob: Problem, plan: Plan) -> Model:
    """A Model of NaNs, shaped for the problem: a cold start."""
    n, k = 6 + len(getattr(prob.base, "driven", ())), len(plan.tendons) + len(plan.tubes)
    return Model(
        jnp.full((n, k), jnp.nan), jnp.full((prob.target.size, k), jnp.nan), jnp.full(3, jnp.nan), jnp.full((3, 3), jnp.nan)
    )


def _usable(model: Model):
    return jnp.all(jnp.array([jnp.all(jnp.isfinite(a)) for a in model]))


class Reach(NamedTuple):
    v: jax.Array
    wrench: jax.Array
    e: jax.Array
    steps: jax.Array
    code: jax.Array  # SUCCESS (reached), UNREACHABLE (stationary above tol), or a failure code
    model: Model | None = None  # reach_augmented's last linearisation (tip NaN)


def _where(keep, new, old):
    return jax.tree.map(lambda a, b: jnp.where(keep, a, b), new, old)


class NestedState(NamedTuple):
    """``reach_nested``'s loop state."""

    v: jax.Array  # the last accepted inputs
    ev: Evaluation  # the evaluation there
    s: jax.Array  # the step to try next
    mu: jax.Array  # damping
    nu: jax.Array  # its growth factor
    it: jax.Array  # passes so far (the first evaluates the start)
    code: jax.Array
    done: jax.Array


def reach_nested(v0, wrench0, prob: Problem, plan: Plan) -> Reach:
    """Phase 1 with a converged forward solve (implicitly differentiated) at every trial. The
    loop's first pass evaluates the start, so the evaluation is compiled once."""
    tol, max_steps = prob.options.tol, prob.options.max_steps

    def cond(c):
        return ~c.done

    def body(c):
        v, ev, s, mu, nu, it = c.v, c.ev, c.s, c.mu, c.nu, c.it
        first = it == 0
        trial = evaluate(v + s, ev.wrench, prob, plan)
        linear = ev.e + ev.G @ s
        actual = jnp.where(trial.code == status.SUCCESS, ev.e @ ev.e - trial.e @ trial.e, -jnp.inf)
        damped = _damping(mu, nu, actual, ev.e @ ev.e - linear @ linear)
        mu, nu = jnp.where(first, mu, damped[0]), jnp.where(first, nu, damped[1])
        better = first | damped[2]
        stalled = ~first & better & (actual <= STALLED * (ev.e @ ev.e))
        v, ev = _where(better, (v + s, trial), (v, ev))
        code, done = _reach_status(ev.e, ev.G, v, mu, it, prob, tol, max_steps, stalled)
        solved = ev.code == status.SUCCESS
        s = _lm_step(ev.G, ev.e, mu, prob.lo - v, prob.hi - v)
        return NestedState(v, ev, s, mu, nu, it + 1, jnp.where(solved, code, ev.code), done | ~solved)

    start = unset(v0, wrench0, prob)
    init = NestedState(
        v0, start, jnp.zeros_like(v0), jnp.asarray(MU_START), jnp.asarray(2.0), 0, jnp.int32(status.OUTER_LIMIT), False
    )
    c = lax.while_loop(cond, body, init)
    return Reach(c.v, c.ev.wrench, c.ev.e, c.it - 1, c.code)


class Linearisation(NamedTuple):
    """``reach_augmented``'s linearisation at z = (x, v): Newton's dx = dx0 + K dv, and the
    reduced task Jacobian G and residual e after that step."""

    dx0: jax.Array
    K: jax.Array
    G: jax.Array
    e: jax.Array


class AugmentedState(NamedTuple):
    """``reach_augmented``'s loop state."""

    z: jax.Array  # the last accepted (scaled shooting unknowns, inputs)
    F: jax.Array  # the boundary and task residuals there
    lin: Linearisation  # and the linearisation there
    s: jax.Array  # the step in v to try next
    mu: jax.Array
    nu: jax.Array
    it: jax.Array
    code: jax.Array
    first: jax.Array  # this pass's trial is z itself, taken as is (the start, or after a warm miss)
    done: jax.Array


def reach_augmented(v0, wrench0, prob: Problem, plan: Plan, model: Model | None = None) -> Reach:
    """Phase 1 on the shooting unknowns x and the inputs v together: each step is Newton on the
    tip boundary residual r(x, v) = 0 with Gauss-Newton on e for v, from one forward-mode
    Jacobian pass of (r, e) in (x, v); x is eliminated, so the bounded step is taken in v alone.
    ``wrench0`` must be the converged base wrench at v0. The loop's first pass linearises at the
    start, so the Jacobian pass is compiled once; with a usable ``model`` (the last update's, at
    v0) it takes a step from that model instead, the first-order predictor of the answer, with
    the damping MU_WARM."""
    robot, L = prob.robot, prob.robot.length
    tol, max_steps = prob.options.tol, prob.options.max_steps
    F_s = force_scale(robot, actuation_of(v0, prob, plan), prob.load, prob.gravity)
    n = 6 + len(getattr(prob.base, "driven", ()))  # shooting unknowns: the base wrench, driven tensions

    def residuals(z):
        x, v = z[:n], z[n:]
        r, tip = shoot(robot, actuation_of(v, prob, plan), prob.load, prob.gravity, prob.solver, x, F_s)
        F = jnp.concatenate([r, task_residual(tip.p, tip.R, prob.target, L)])
        return F, F

    def linearise(z):
        """Residuals, and x eliminated by Newton: dx = dx0 + K dv; the reduced G and e there."""
        Jz, F = jax.jacfwd(residuals, has_aux=True)(z)
        r, e = F[:n], F[n:]
        Jx, Jv, Ex, Ev = Jz[:n, :n], Jz[:n, n:], Jz[n:, :n], Jz[n:, n:]
        M = jnp.linalg.solve(Jx, jnp.concatenate([r[:, None], Jv], axis=1))
        dx0, K = -M[:, 0], -M[:, 1:]
        return F, Linearisation(dx0, K, Ev + Ex @ K, e + Ex @ dx0)

    def merit(F):
        return jnp.where(jnp.all(jnp.isfinite(F)), F @ F, jnp.inf)

    def cond(c):
        return ~c.done

    def body(c):
        z, F, lin, s, mu, nu, it, first = c.z, c.F, c.lin, c.s, c.mu, c.nu, c.it, c.first
        dx0, K, G, e = lin
        trial = z + jnp.concatenate([dx0 + K @ s, s])
        F_t, lin_t = linearise(trial)
        linear = e + G @ s  # the model: Newton takes r to 0, Gauss-Newton e to this
        damped = _damping(mu, nu, merit(F) - merit(F_t), merit(F) - linear @ linear)
        mu, nu = jnp.where(first, mu, damped[0]), jnp.where(first, nu, damped[1])
        # while the boundary residual is off, e is not yet the task error: a step that halves r is
        # taken even where it moves e the wrong way
        restores = (jnp.max(jnp.abs(F[:n])) > prob.solver.tol) & (jnp.linalg.norm(F_t[:n]) <= 0.5 * jnp.linalg.norm(F[:n]))
        better = first | damped[2] | restores
        stalled = ~first & damped[2] & (merit(F) - merit(F_t) <= STALLED * merit(F))
        z, F, lin = _where(better, (trial, F_t, lin_t), (z, F, lin))
        code, done = _reach_status(F[n:], lin.G, z[n:], mu, it, prob, tol, max_steps, stalled)
        # reached only with the boundary residual converged too; stationary (UNREACHABLE) once it is
        # near enough for the closing forward solve to converge from here
        r = jnp.max(jnp.abs(F[:n]))
        code = jnp.where((code == status.SUCCESS) & (r > prob.solver.tol), jnp.int32(status.OUTER_LIMIT), code)
        code = jnp.where((code == status.UNREACHABLE) & (r > jnp.sqrt(prob.solver.tol)), jnp.int32(status.OUTER_LIMIT), code)
        done = done & ((code != status.OUTER_LIMIT) | (it >= max_steps) | (mu >= MU_GIVE_UP))
        # a warm update whose first step the old model got wrong linearises at the start next
        fresh = warm & (it == 0) & ~better
        s = jnp.where(fresh, 0.0, _lm_step(lin.G, lin.e, mu, prob.lo - z[n:], prob.hi - z[n:]))
        return AugmentedState(z, F, lin, s, mu, nu, it + 1, code, fresh, done & ~fresh)

    z0 = jnp.concatenate([scaled(robot, wrench0, F_s), v0])
    m, k = prob.target.size, v0.shape[0]
    F0, lin0 = jnp.zeros(n + m), Linearisation(jnp.zeros(n), jnp.zeros((n, k)), jnp.zeros((m, k)), jnp.zeros(m))  # unset
    s0, mu0, warm = jnp.zeros_like(v0), jnp.asarray(MU_START), jnp.asarray(False)
    if model is not None:
        # the boundary residual is converged at v0; e there from the tip, for the new target
        warm = _usable(model)
        e0 = task_residual(model.tip_position, model.tip_rotation, prob.target, L)
        K0 = jax.vmap(lambda k: scaled(robot, k, F_s), 1, 1)(model.K)
        F0, lin0 = _where(warm, (jnp.concatenate([jnp.zeros(n), e0]), Linearisation(jnp.zeros(n), K0, model.G, e0)), (F0, lin0))
        mu0 = jnp.where(warm, MU_WARM, MU_START)
        s0 = jnp.where(warm, _lm_step(model.G, e0, MU_WARM, prob.lo - v0, prob.hi - v0), s0)
    init = AugmentedState(z0, F0, lin0, s0, mu0, jnp.asarray(2.0), 0, jnp.int32(status.OUTER_LIMIT), ~warm, False)
    c = lax.while_loop(cond, body, init)
    last = Model(
        jax.vmap(lambda k: unscaled(robot, k, F_s), 1, 1)(c.lin.K), c.lin.G, jnp.full(3, jnp.nan), jnp.full((3, 3), jnp.nan)
    )
    return Reach(c.z[n:], unscaled(robot, c.z[:n], F_s), c.F[n:], c.it - 1 + warm, c.code, last)
