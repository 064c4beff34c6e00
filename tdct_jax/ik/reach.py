"""Phase 1, reach: bounded Levenberg-Marquardt on the task residual, "nested" (a converged forward
solve per step) or "augmented" (shooting unknowns and inputs iterated together)."""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from .. import status
from ..linalg import solve_spd
from ..newton import lazily
from ..qp import box_qp
from ..shooting import force_scale, scaled, shoot, unscaled
from .evaluation import Evaluation, unset
from .problem import Plan, Problem, actuation_of, task_residual

MU_START = 1e-3
"""Initial Levenberg-Marquardt damping (relative to the diagonal of G^T G)."""
MU_WARM = 1e-10
"""Initial damping of a warm update (``reach_augmented`` with the last update's model): its model
is good, so Gauss-Newton's minimum-norm step; at MU_START the directions G barely moves (the
insertion) would converge linearly, a few steps per update."""
MU_FALL = 1 / 30
"""The most an accepted step lowers the damping by (a factor). Cold IK starts far from its answer
and damped; at Nielsen's 1/3 it took 8 steps to the benchmark's target and 7.8 on average over
128 random reachable ones, at 1/30 6 and 6.5, the answers within the same tolerance."""
MU_GIVE_UP = 1e10
"""Damping at which a phase stops: no step it could take lowers its merit."""


CHORD = 0.5
"""A warm update's chord step (``reach_augmented``) is kept when it shrinks |(r, e)| at least this
much; the first that does not is tried again with its secant in J, the second ends the chord
steps."""

START_TOL = 1e-3
"""The forward solve at each of phase 1's starts stops at this scaled tip residual (or the solver's
tolerance, if looser): phase 1 converges the boundary residual along with the task (its answer's
residual is held to the solver's tolerance), so Newton's last quadratic steps at the start are
phase 1's first steps' work. A cold IK (benchmarks/ik.py's target) took 14.2 ms with the start
converged to 1e-10, 12.2-12.8 ms with 1e-3 (11.5-11.8 with 1e-2, but 8% more phase-1 steps over 24
random targets against 3%)."""

STALLED = 1e-10
"""An accepted phase-1 step that lowers |e|^2 by less than this, relatively, ends phase 1."""
STATIONARY = 1e-7
"""Phase 1 ends above the tolerance (UNREACHABLE) when the projected gradient of |e|^2 / 2 is
below this, relative to |G| |e|: the nearest reachable pose, to about that relative precision."""


def _lm_step(G, e, mu, lo, hi):
    """The bounded Levenberg step on |e + G s|^2 + mu |G|^2 |s|^2: damping the same for every
    scaled input, so that inputs the task does not need (co-contraction) are left alone. The
    unbounded step where it is inside the bounds (then the bounded one), else ``box_qp``'s, which
    costs about 20 times as much."""
    A = G.T @ G
    H, g = A + mu * jnp.trace(A) * jnp.eye(A.shape[0]), G.T @ e
    s = solve_spd(H, -g)
    inside = jnp.all(s >= lo) & jnp.all(s <= hi)
    return lazily(~inside, lambda H, g, lo, hi: box_qp(H, g, lo, hi)[0], s, H, g, lo, hi)


def _damping(mu, nu, actual, predicted):
    """Nielsen's update of the damping from the gain ratio actual / predicted decrease: (mu, nu,
    accepted); an accepted step lowers mu by up to MU_FALL, not Nielsen's 1/3."""
    rho = actual / jnp.where(predicted > 0, predicted, jnp.inf)
    accepted = (actual > 0) & jnp.isfinite(actual)
    mu_ok = mu * jnp.maximum(MU_FALL, 1 - (2 * rho - 1) ** 3)
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
    """Phase 1's last linearisation, at its answer: the next warm update (``track``) takes its first
    step from it, with no evaluation before, and chord steps with it. NaN: none."""

    J: jax.Array  # d(scaled boundary residual r, task residual e) / d(scaled shooting unknowns x, inputs v)
    tip_position: jax.Array  # [m], of the forward solve at the answer
    tip_rotation: jax.Array


def no_model(prob: Problem, plan: Plan) -> Model:
    """A Model of NaNs, shaped for the problem: a cold start."""
    n, k = 6 + len(getattr(prob.base, "driven", ())), len(plan.tendons) + len(plan.tubes)
    m = prob.target.size
    return Model(jnp.full((n + m, n + k), jnp.nan), jnp.full(3, jnp.nan), jnp.full((3, 3), jnp.nan))


def refreshed(model: Model, J_res, J_p, J_R, prob: Problem) -> Model:
    """The model with its columns in x exact at its tip: the closing forward solve's d r / dx there
    and d e / dx through its tip Jacobians J_p, J_R (``RootInfo``), in that solve's scaling, which
    is the next update's. Its columns in v stay those of phase 1's last linearisation; without a
    closing solve (its Jacobians NaN), all of them."""
    n = J_res.shape[0]
    if n + prob.target.size != model.J.shape[0]:  # a root with unknowns phase 1 does not have
        return model

    def e(dx):
        return task_residual(model.tip_position + J_p @ dx, model.tip_rotation + J_R @ dx, prob.target, prob.robot.length)

    fresh = model._replace(J=model.J.at[:n, :n].set(J_res).at[n:, :n].set(jax.jacfwd(e)(jnp.zeros(n))))
    return _where(jnp.all(jnp.isfinite(J_res)), fresh, model)


def _usable(model: Model):
    return jnp.all(jnp.array([jnp.all(jnp.isfinite(a)) for a in model]))


class Reach(NamedTuple):
    v: jax.Array
    wrench: jax.Array
    e: jax.Array
    steps: jax.Array
    code: jax.Array  # SUCCESS (reached), UNREACHABLE (stationary above tol), or a failure code
    model: Model | None = None  # reach_augmented's last linearisation (tip NaN)
    chords: jax.Array = np.int32(0)  # how many of the steps were chord steps (``reach_augmented``)


def _where(keep, new, old):
    return jax.tree.map(lambda a, b: jnp.where(keep, a, b), new, old)


class NestedState(NamedTuple):
    """Phase 1 with a converged forward solve at every step ("nested"), between steps
    (``nested_start``, ``nested_step``)."""

    v: jax.Array  # the last accepted inputs
    ev: Evaluation  # the evaluation there
    s: jax.Array  # the step to try next: the next evaluation is at v + s, from ev.wrench
    mu: jax.Array  # damping
    nu: jax.Array  # its growth factor
    it: jax.Array  # steps so far (the first evaluates the start)
    code: jax.Array
    done: jax.Array

    def result(self) -> Reach:
        """Where phase 1 from this start stands, as a Reach."""
        return Reach(self.v, self.ev.wrench, self.ev.e, self.it - 1, self.code)


def nested_start(v0, wrench0, prob: Problem) -> NestedState:
    """Nested phase 1 from v0 (``wrench0``: the base wrench there or near it, or NaN): its first
    step evaluates v0."""
    return NestedState(
        v0,
        unset(v0, wrench0, prob),
        jnp.zeros_like(v0),
        jnp.asarray(MU_START),
        jnp.asarray(2.0),
        0,
        jnp.int32(status.OUTER_LIMIT),
        False,
    )


def nested_step(c: NestedState, trial: Evaluation, prob: Problem) -> NestedState:
    """Nested phase 1's step given ``trial``, the evaluation (converged forward solve, implicitly
    differentiated) at v + s. ``find`` runs the steps in its own loop, so that they share its
    forward solve in the compiled program."""
    v, ev, s, mu, nu, it = c.v, c.ev, c.s, c.mu, c.nu, c.it
    first = it == 0
    linear = ev.e + ev.G @ s
    actual = jnp.where(trial.code == status.SUCCESS, ev.e @ ev.e - trial.e @ trial.e, -jnp.inf)
    damped = _damping(mu, nu, actual, ev.e @ ev.e - linear @ linear)
    mu, nu = jnp.where(first, mu, damped[0]), jnp.where(first, nu, damped[1])
    better = first | damped[2]
    stalled = ~first & better & (actual <= STALLED * (ev.e @ ev.e))
    v, ev = _where(better, (v + s, trial), (v, ev))
    code, done = _reach_status(ev.e, ev.G, v, mu, it, prob, prob.options.tol, prob.options.max_steps, stalled)
    solved = ev.code == status.SUCCESS
    s = _lm_step(ev.G, ev.e, mu, prob.lo - v, prob.hi - v)
    return NestedState(v, ev, s, mu, nu, it + 1, jnp.where(solved, code, ev.code), done | ~solved)


class Linearisation(NamedTuple):
    """``reach_augmented``'s linearisation at z = (x, v): Newton's dx = dx0 + K dv, and the
    reduced task Jacobian G and residual e after that step."""

    dx0: jax.Array
    K: jax.Array
    G: jax.Array
    e: jax.Array


def _reduced(F, J, n: int) -> Linearisation:
    """x eliminated from the residuals F = (r, e) with their Jacobian J in z = (x, v) (n unknowns
    x): Newton's dx = dx0 + K dv takes r to 0, leaving e + Ex dx0 + G dv."""
    r, e = F[:n], F[n:]
    Jx, Jv, Ex, Ev = J[:n, :n], J[:n, n:], J[n:, :n], J[n:, n:]
    M = jnp.linalg.solve(Jx, jnp.concatenate([r[:, None], Jv], axis=1))
    dx0, K = -M[:, 0], -M[:, 1:]
    return Linearisation(dx0, K, Ev + Ex @ K, e + Ex @ dx0)


class AugmentedState(NamedTuple):
    """``reach_augmented``'s loop state."""

    z: jax.Array  # the last accepted (scaled shooting unknowns, inputs)
    F: jax.Array  # the boundary and task residuals there
    J: jax.Array  # their Jacobian: there, or an earlier one while chord steps
    lin: Linearisation  # and the linearisation there (``_reduced``)
    s: jax.Array  # the step in v to try next
    mu: jax.Array
    nu: jax.Array
    it: jax.Array
    code: jax.Array
    first: jax.Array  # this pass's trial is z itself, taken as is (the start, or after a warm miss)
    chord: jax.Array  # this pass evaluates F alone and keeps J (a warm update until a step misses)
    chords: jax.Array  # chord passes so far
    misses: jax.Array  # chord steps that missed
    done: jax.Array


def reach_augmented(v0, wrench0, prob: Problem, plan: Plan, model: Model | None = None) -> Reach:
    """Phase 1 on the shooting unknowns x and the inputs v together: each step is Newton on the
    tip boundary residual r(x, v) = 0 with Gauss-Newton on e for v, from one forward-mode
    Jacobian pass of (r, e) in (x, v); x is eliminated, so the bounded step is taken in v alone.
    ``wrench0`` is the base wrench at v0, converged or near it (START_TOL): the steps converge the
    boundary residual too. The loop's first pass linearises at the start, so the Jacobian pass is
    compiled once.

    With a usable ``model`` (the last update's, at v0) a warm update: its first step from that
    model (the first-order predictor of the answer, damping MU_WARM), then chord steps, each one
    evaluation of (r, e) without a Jacobian pass (a quarter of its cost), with the model's
    Jacobian and Broyden's rank-one update of it after each, for as long as each shrinks |(r, e)|
    by CHORD; the first that does not is tried again from where it started (its secant now in J:
    in the weak directions of a nearly singular task, where the old Jacobian is least right), the
    second ends the chord steps, and the update linearises where it stands. With ``model`` None
    (static) no chord code is compiled."""
    robot, L = prob.robot, prob.robot.length
    tol, max_steps = prob.options.tol, prob.options.max_steps
    F_s = force_scale(robot, actuation_of(v0, prob, plan), prob.load, prob.gravity)
    n = 6 + len(getattr(prob.base, "driven", ()))  # shooting unknowns: the base wrench, driven tensions

    def residuals(z):
        x, v = z[:n], z[n:]
        r, tip = shoot(robot, actuation_of(v, prob, plan), prob.load, prob.gravity, prob.solver, x, F_s)
        F = jnp.concatenate([r, task_residual(tip.p, tip.R, prob.target, L)])
        return F, F

    def linearise(z, J):
        J, F = jax.jacfwd(residuals, has_aux=True)(z)
        return F, J

    def evaluate(z, chord, J):
        """(F, J) at z: a Jacobian pass, or with ``chord`` F alone and J kept."""
        if model is None:
            return linearise(z, J)
        return lax.cond(chord, lambda z, J: (residuals(z)[0], J), linearise, z, J)

    def merit(F):
        return jnp.where(jnp.all(jnp.isfinite(F)), F @ F, jnp.inf)

    def cond(c):
        return ~c.done

    def body(c):
        z, F, lin, s, mu, nu, it, first, chord = c.z, c.F, c.lin, c.s, c.mu, c.nu, c.it, c.first, c.chord
        dx0, K, G, e = lin
        trial = jnp.where(first, z, z + jnp.concatenate([dx0 + K @ s, s]))
        F_t, J_t = evaluate(trial, chord, c.J)
        if model is not None:  # a chord step updates the J it kept by its secant (Broyden)
            dz = trial - z
            J_t = jnp.where(chord, J_t + jnp.outer(F_t - F - J_t @ dz, dz) / jnp.maximum(dz @ dz, 1e-300), J_t)
        lin_t = _reduced(F_t, J_t, n)
        linear = e + G @ s  # the model: Newton takes r to 0, Gauss-Newton e to this
        damped = _damping(mu, nu, merit(F) - merit(F_t), merit(F) - linear @ linear)
        mu, nu = jnp.where(first | chord, mu, damped[0]), jnp.where(first | chord, nu, damped[1])
        # while the boundary residual is off, e is not yet the task error: a step that halves r is
        # taken even where it moves e the wrong way
        restores = (jnp.max(jnp.abs(F[:n])) > prob.solver.tol) & (jnp.linalg.norm(F_t[:n]) <= 0.5 * jnp.linalg.norm(F[:n]))
        better = jnp.where(chord, merit(F_t) <= CHORD**2 * merit(F), first | damped[2] | restores)
        stalled = ~first & ~chord & damped[2] & (merit(F) - merit(F_t) <= STALLED * merit(F))
        retry = chord & ~better & (c.misses == 0)
        kept = (z, F, c.J, lin)
        if model is not None:  # a chord step that misses still updates J, and the next tries again from z
            kept = _where(retry, (z, F, J_t, _reduced(F, J_t, n)), kept)
        z, F, J, lin = _where(better, (trial, F_t, J_t, lin_t), kept)
        code, done = _reach_status(F[n:], lin.G, z[n:], mu, it, prob, tol, max_steps, stalled)
        # reached only with the boundary residual converged too; stationary (UNREACHABLE) once it is
        # near enough for the closing forward solve to converge from here
        r = jnp.max(jnp.abs(F[:n]))
        # in the scaling of a forward solve at v, which takes this root as its own (``find``)
        r_v = r * F_s / force_scale(robot, actuation_of(z[n:], prob, plan), prob.load, prob.gravity)
        code = jnp.where((code == status.SUCCESS) & (r_v > prob.solver.tol), jnp.int32(status.OUTER_LIMIT), code)
        code = jnp.where((code == status.UNREACHABLE) & (r > jnp.sqrt(prob.solver.tol)), jnp.int32(status.OUTER_LIMIT), code)
        done = done & ((code != status.OUTER_LIMIT) | (it >= max_steps) | (mu >= MU_GIVE_UP))
        # chord steps judge no stationarity (their G is old): they end at the target, or miss twice
        # and the update linearises where it stands next
        done = jnp.where(chord, (code == status.SUCCESS) | (it >= max_steps), done)
        fresh = chord & ~better & ~retry
        s = _lm_step(lin.G, lin.e, mu, prob.lo - z[n:], prob.hi - z[n:])
        return AugmentedState(
            z,
            F,
            J,
            lin,
            s,
            mu,
            nu,
            it + 1,
            code,
            fresh,
            chord & (better | retry),
            c.chords + chord,
            c.misses + (chord & ~better),
            done & ~fresh,
        )

    z0 = jnp.concatenate([scaled(robot, wrench0, F_s), v0])
    m, k = prob.target.size, v0.shape[0]
    F0, J0 = jnp.zeros(n + m), jnp.zeros((n + m, n + k))  # unset
    lin0 = Linearisation(jnp.zeros(n), jnp.zeros((n, k)), jnp.zeros((m, k)), jnp.zeros(m))
    s0, mu0, warm = jnp.zeros_like(v0), jnp.asarray(MU_START), jnp.asarray(False)
    if model is not None:
        # the boundary residual is converged at v0; e there from the tip, for the new target
        warm = _usable(model)
        F_w = jnp.concatenate([jnp.zeros(n), task_residual(model.tip_position, model.tip_rotation, prob.target, L)])
        lin_w = _reduced(F_w, model.J, n)
        F0, J0, lin0 = _where(warm, (F_w, model.J, lin_w), (F0, J0, lin0))
        mu0 = jnp.where(warm, MU_WARM, MU_START)
        s0 = jnp.where(warm, _lm_step(lin_w.G, lin_w.e, MU_WARM, prob.lo - v0, prob.hi - v0), s0)
    init = AugmentedState(
        z0,
        F0,
        J0,
        lin0,
        s0,
        mu0,
        jnp.asarray(2.0),
        0,
        jnp.int32(status.OUTER_LIMIT),
        ~warm,
        warm,
        jnp.int32(0),
        jnp.int32(0),
        False,
    )
    c = lax.while_loop(cond, body, init)
    last = Model(c.J, jnp.full(3, jnp.nan), jnp.full((3, 3), jnp.nan))
    return Reach(c.z[n:], unscaled(robot, c.z[:n], F_s), c.F[n:], c.it - 1 + warm, c.code, last, c.chords)
