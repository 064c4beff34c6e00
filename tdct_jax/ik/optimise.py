"""Phase 2, optimise: sequential quadratic programming on min phi(v) subject to e(v) = 0 and the
bounds, once phase 1 has reached the target."""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from .. import status
from ..qp import box_qp
from .evaluation import Evaluation, unset
from .problem import Problem
from .reach import MU_GIVE_UP, MU_START, Reach, _lm_step, _where

KKT_TOL = 1e-7
"""Phase 2 has converged on the target when the projected gradient of the Lagrangian is below this
relative to the objective's gradient (``_kkt_residual``, scaled inputs)."""
DRIFT = 1e-3
"""Phase 2 takes no step whose task residual exceeds this (about 0.16 mm of position on the
default robot) unless it is already further away: the exact penalty alone lets a large step trade
the target for the objective where the reachable set is thin."""


class SQPState(NamedTuple):
    """Phase 2's state between steps (``sqp_start``, ``sqp_step``)."""

    v: jax.Array  # the last accepted inputs
    ev: Evaluation  # the evaluation there
    kkt: jax.Array  # its first-order optimality residual (``_kkt_residual``)
    H: jax.Array  # BFGS Hessian of the Lagrangian (phi / scale)
    s: jax.Array  # the step to try next: the next evaluation is at v + s, from ev.wrench
    lam: jax.Array  # multipliers of e = 0
    scale: jax.Array  # |phi| at the start
    rho: jax.Array  # penalty weight of |e|_1 in the merit
    mu: jax.Array  # damping added to H
    corrected: jax.Array  # whether s is a second-order correction
    it: jax.Array
    code: jax.Array
    done: jax.Array

    def result(self, steps) -> Reach:
        """Phase 2's answer as a Reach (its ``steps`` phase 1's)."""
        return Reach(self.v, self.ev.wrench, self.ev.e, steps, self.code)


def sqp_start(v0, wrench0, prob: Problem) -> SQPState:
    """Phase 2 from v0 (the converged base wrench there: wrench0): its first step evaluates v0."""
    n, m = v0.shape[0], prob.target.size
    zero = jnp.zeros_like(v0)
    return SQPState(
        v0,
        unset(v0, wrench0, prob),
        jnp.asarray(jnp.inf),
        jnp.eye(n),
        zero,
        jnp.zeros(m),
        jnp.asarray(1.0),
        jnp.asarray(1.0),
        jnp.asarray(0.0),
        jnp.asarray(False),
        jnp.asarray(0),
        jnp.int32(status.OUTER_LIMIT),
        jnp.asarray(False),
    )


def sqp_step(state: SQPState, trial: Evaluation, prob: Problem) -> SQPState:
    """Phase 2's step: min phi(v) subject to e(v) = 0 and the bounds, by SQP (damped BFGS Hessian
    of the Lagrangian, exact active-set subproblems, l1 merit phi / phi_0 + rho |e|_1, and no step
    that leaves the task further than ``DRIFT``), given ``trial``, the evaluation at v + s. The
    first step's trial is the start itself (phi_0 there). ``find`` runs the steps in its own loop,
    so that they share its forward solve in the compiled program."""
    n, tol, max_steps = state.v.shape[0], prob.options.tol, prob.options.max_steps

    def merit(ev, scale, rho):
        ok = jnp.all(jnp.isfinite(ev.e)) & (ev.code == status.SUCCESS)
        return jnp.where(ok, ev.phi / scale + rho * jnp.sum(jnp.abs(ev.e)), jnp.inf)

    v, ev, kkt, H, s, lam, scale, rho, mu, corrected, it, *_ = state
    first = it == 0
    kkt_trial = _kkt_residual(trial.dphi, trial.G, v + s, prob)  # unscaled: compared with its own kind
    scale = jnp.where(first, jnp.maximum(jnp.abs(trial.phi), 1e-300), scale)
    m, m_t = merit(ev, scale, rho), merit(trial, scale, rho)
    # with the task met to its tolerance before and after, the merit's penalty term measures the
    # forward solve's round-off, not progress: there a step is taken when it lowers the
    # objective or the first-order optimality residual
    settled = (jnp.max(jnp.abs(trial.e)) <= tol) & (jnp.max(jnp.abs(ev.e)) <= tol)
    progress = (trial.phi <= ev.phi) | (kkt_trial < kkt)
    near = jnp.max(jnp.abs(trial.e)) <= jnp.maximum(jnp.max(jnp.abs(ev.e)), DRIFT)
    better = first | (near & ((m_t <= m - 1e-15 * jnp.abs(m)) | (settled & progress)))
    y = (trial.dphi - ev.dphi) / scale + (trial.G - ev.G).T @ lam
    H = jnp.where(better & ~first, _damped_bfgs(H, s, y), H)  # s: the whole step, corrected or not
    # the first Hessian: a multiple of the identity whose first step moves the inputs by about a tenth
    H = jnp.where(first, jnp.maximum(1.0, 10 * jnp.max(jnp.abs(trial.dphi)) / scale) * jnp.eye(n), H)
    # a rejected step is tried once more with a second-order correction back onto the task
    # manifold, c = least-squares solution of e(v + s) + G(v + s) c = 0 (the Maratos effect:
    # on a curved manifold the l1 merit rejects good SQP steps)
    correct = ~better & ~corrected & (trial.code == status.SUCCESS)
    c = box_qp(trial.G.T @ trial.G + 1e-12 * jnp.eye(n), trial.G.T @ trial.e, prob.lo - v - s, prob.hi - v - s)[0]
    v, ev, kkt = _where(better, (v + s, trial, kkt_trial), (v, ev, kkt))
    mu = jnp.where(first | correct, mu, jnp.where(better, jnp.where(mu < 1e-10, 0.0, mu / 10), jnp.maximum(10 * mu, 1e-6)))
    # the next step, from the QP at the current point
    s_qp, lam_qp, ok = box_qp(H + mu * jnp.eye(n), ev.dphi / scale, prob.lo - v, prob.hi - v, J=ev.G, c=-ev.e)
    s_qp = jnp.where(ok, s_qp, _lm_step(ev.G, ev.e, jnp.maximum(mu, MU_START), prob.lo - v, prob.hi - v))
    lam = jnp.where(correct, lam, jnp.where(ok, lam_qp, 0.0))
    s = jnp.where(correct, s + c, s_qp)
    rho = jnp.maximum(rho, 2 * jnp.max(jnp.abs(lam), initial=0.0) + 1e-6)
    converged = ~correct & (kkt <= KKT_TOL * jnp.max(jnp.abs(ev.dphi))) & (jnp.max(jnp.abs(ev.e)) <= tol)
    failed = ev.code != status.SUCCESS
    code = jnp.where(converged, status.SUCCESS, jnp.where(mu >= MU_GIVE_UP, status.CONTINUATION_EXHAUSTED, status.OUTER_LIMIT))
    done = converged | failed | (it >= max_steps) | (mu >= MU_GIVE_UP)
    code = jnp.where(failed, ev.code, code).astype(jnp.int32)
    return SQPState(v, ev, kkt, H, s, lam, scale, rho, mu, correct, it + 1, code, done)


def _kkt_residual(g, G, v, prob: Problem):
    """First-order optimality of min phi s.t. e = 0 and the bounds, at v: the Lagrangian's gradient
    g + G^T lam (lam least squares on the inputs off their bounds), on the inputs it could move:
    off their bounds, or at one with the gradient pointing into the box."""
    inside = (v > prob.lo) & (v < prob.hi)
    G_in = G * inside[None, :]
    A = G_in @ G_in.T
    lam = -jnp.linalg.solve(A + (1e-14 * jnp.trace(A) + 1e-300) * jnp.eye(A.shape[0]), G_in @ g)
    r = g + G.T @ lam
    movable = jnp.where(v <= prob.lo, r < 0, jnp.where(v >= prob.hi, r > 0, True))
    return jnp.max(jnp.abs(jnp.where(movable, r, 0.0)))


def _damped_bfgs(H, s, y):
    """Powell's damped BFGS update: stays positive definite whatever the curvature along s."""
    Hs = H @ s
    sHs = s @ Hs
    sy = s @ y
    theta = jnp.where(sy >= 0.2 * sHs, 1.0, 0.8 * sHs / jnp.where(sHs - sy == 0, 1.0, sHs - sy))
    r = theta * y + (1 - theta) * Hs
    sr = s @ r
    update = H - jnp.outer(Hs, Hs) / jnp.where(sHs > 0, sHs, 1.0) + jnp.outer(r, r) / jnp.where(sr > 0, sr, 1.0)
    return jnp.where((sHs > 1e-300) & (sr > 1e-300), update, H)
