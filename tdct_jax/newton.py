"""Damped Newton with load continuation, for any F(x) -> (residual, outputs): no physics."""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax import lax

from . import status

MU_START = 1e-5
"""Initial Levenberg-Marquardt damping."""
MU_STALL = 1e6
"""Damping at which Newton gives up on a stage: 11 rejected steps in a row from the start value;
the steps it would still take are too short to matter."""
_STALLED = -1  # Newton's own code for a stall; continuation reports it as CONTINUATION_EXHAUSTED


class Root(NamedTuple):
    """What ``continuation`` found.

    x: the last accepted point (the root when ``result`` is SUCCESS).
    residual: F's residual there. jacobians: d(residual, outputs) / dx there, from the same pass.
    iterations: Newton steps over all stages. stages: the number of load stages of the last ramp.
    result: a ``status`` code.
    """

    x: jax.Array
    residual: jax.Array
    jacobians: object
    iterations: jax.Array
    stages: jax.Array
    result: jax.Array


def newton(F, x0, tol, max_iter, fixed=None):
    """Levenberg-Marquardt-damped Newton on F(x)[0] = 0 with exact ``jax.jacfwd`` Jacobians.

    F returns (residual, outputs); Newton also carries the Jacobian of the outputs, taken in the
    same forward pass. The damping mu shrinks tenfold after each step that lowers |F| and grows
    tenfold after each that does not, so the iteration is Newton's (quadratic) near the root and a
    short gradient step far from it; it stops when mu reaches MU_STALL. The first pass evaluates
    x0 itself, so the Jacobian code appears once in the compiled loop and the last Jacobians are
    at the returned point.

    ``fixed``: an array of inputs that F also takes, F(x, fixed), held fixed. The Jacobians are
    then in (x, fixed), x's columns first, and come with F's outputs at x: (Jacobians, outputs).
    One pass then gives the derivatives in those inputs along with the root's.

    Returns:
        (x, residual, jacobians, Newton steps taken, code): SUCCESS, NEWTON_LIMIT, NONFINITE or
        a stall.
    """
    n = x0.size

    def linearize(x):
        def fr(z):
            out = F(z) if fixed is None else F(z[:n], z[n:])
            return out, out

        J, out = jax.jacfwd(fr, has_aux=True)(x if fixed is None else jnp.concatenate([x, fixed]))
        return out[0], J if fixed is None else (J, out[1])

    def step(x, r, J, mu):
        J_r = (J if fixed is None else J[0])[0][:, :n]
        return x - jnp.linalg.solve(J_r.T @ J_r + mu * jnp.eye(n), J_r.T @ r)

    return damped(linearize, step, x0, tol, max_iter, _jacobian_shapes(F, x0, fixed))


def _jacobian_shapes(F, x, fixed=None):
    """The shapes of ``newton``'s (residual, J) from one primal trace of F (J of a flat x: each
    output's shape followed by x's, and ``fixed``'s), rather than a trace of its Jacobian pass."""
    out = jax.eval_shape(F, x) if fixed is None else jax.eval_shape(F, x, fixed)
    k = 0 if fixed is None else fixed.size
    J = jax.tree.map(lambda o: jax.ShapeDtypeStruct(o.shape + (x.size + k,), o.dtype), out)
    return out[0], J if fixed is None else (J, out[1])


def damped(linearize, step, x0, tol, max_iter, shapes=None, natural=False):
    """The Levenberg-Marquardt loop of ``newton`` for any linearisation: ``linearize(x)`` gives
    (residual, J), ``step(x, residual, J, mu)`` the next point to try with damping mu; x may be a
    pytree (e.g. with rotations, updated on SO(3) by ``step``). ``shapes``: those of (residual, J)
    when known, else from a trace of ``linearize``. A step is taken where it lowers |r|^2; with
    ``natural`` (J a matrix), an undamped one (mu <= MU_START, as ``step`` makes it) also where it
    lowers Deuflhard's natural level |J^-1 r|^2 at the last point's J, which no scaling of the
    rows changes (either suffices: where J changes abruptly, as where a contact closes, the
    level at the last J can rise on a step that lowers |r| and leads to the root). Returns what
    ``newton`` returns."""

    def not_done(c):
        x, r, J, mu, it, x_try = c
        return (it == 0) | ((it <= max_iter) & (jnp.max(jnp.abs(r)) > tol) & (mu < MU_STALL))

    def body(c):
        x, r, J, mu, it, x_try = c
        r_try, J_try = linearize(x_try)
        lower = jnp.sum(r_try**2) < jnp.sum(r**2)
        if natural:
            d = jnp.linalg.solve(J, jnp.stack([r_try, r], -1))  # one factorisation for both
            level = jnp.sum(d[:, 0] ** 2) < jnp.sum(d[:, 1] ** 2)
            lower = jnp.where((it > 0) & (mu <= MU_START), level | lower, lower)
        ok = jnp.all(jnp.isfinite(r_try)) & lower
        x, r, J = jax.tree.map(lambda new, old: jnp.where(ok, new, old), (x_try, r_try, J_try), (x, r, J))
        mu = jnp.where(ok, mu / 10, mu * 10)
        return x, r, J, mu, it + 1, step(x, r, J, mu)

    r0, J0 = jax.tree.map(lambda o: jnp.zeros(o.shape, o.dtype), shapes or jax.eval_shape(linearize, x0))
    init = (x0, jnp.full(r0.size, jnp.inf), J0, jnp.asarray(MU_START), 0, x0)
    x, r, J, mu, it, _ = lax.while_loop(not_done, body, init)
    code = jnp.where(
        jnp.max(jnp.abs(r)) <= tol,
        status.SUCCESS,
        jnp.where(~jnp.all(jnp.isfinite(r)), status.NONFINITE, jnp.where(mu >= MU_STALL, _STALLED, status.NEWTON_LIMIT)),
    )
    return x, r, J, it - 1, code


def broyden(F, x0, tol, max_iter):
    """Quasi-Newton on F(x)[0] = 0 for batches: the exact ``jax.jacfwd`` Jacobian at x0, then
    Broyden's rank-one ("good") updates, so each step costs one evaluation of F instead of a
    Jacobian pass. Undamped and without continuation: it is a first try, and whoever calls it
    solves what it leaves unconverged again with ``continuation``.

    Returns:
        (x, residual, outputs, steps taken, code): SUCCESS, NEWTON_LIMIT or NONFINITE. The
        outputs are F's at the returned x.
    """

    def fr(x):
        r, out = F(x)
        return r, (r, out)

    J, (r0, out0) = jax.jacfwd(fr, has_aux=True)(x0)

    def not_done(c):
        x, r, out, J, it = c
        return (it < max_iter) & (jnp.max(jnp.abs(r)) > tol) & jnp.all(jnp.isfinite(r))

    def body(c):
        x, r, out, J, it = c
        dx = -jnp.linalg.solve(J, r)
        r_new, out_new = F(x + dx)
        J = J + jnp.outer(r_new - r - J @ dx, dx) / (dx @ dx)
        return x + dx, r_new, out_new, J, it + 1

    x, r, out, _, it = lax.while_loop(not_done, body, (x0, r0, out0, J, 0))
    norm = jnp.max(jnp.abs(r))
    code = jnp.where(norm <= tol, status.SUCCESS, jnp.where(jnp.isfinite(norm), status.NEWTON_LIMIT, status.NONFINITE))
    return x, r, out, it, code.astype(jnp.int32)


def continuation(F_at, x0, x_ramp, tol, max_iter, stages=(1, 4, 16), solve=newton, count=None, fixed=None) -> Root:
    """Solves F_at(1)(x)[0] = 0 from x0, ramping the loads in stages when plain Newton fails.

    F_at(lam) gives the residual (and outputs, see ``newton``) with every load scaled by lam. The
    ramps of ``stages`` are tried in turn: K equal stages lam = 1/K, ..., 1, each started from the
    last root, the first from lam * x_ramp (a start that is linear in the loads, e.g. the straight
    rod), or from x0 when K is the first ramp's 1. ``stages`` may be traced (its length static),
    and ``count`` (default all; may be traced) says how many of them to try. ``solve(F_at(lam),
    guess, tol, max_iter)`` is ``newton`` or one with its returns; x0 may then be a pytree and
    x_ramp a function of lam. ``fixed``: ``newton``'s, inputs F_at(lam) also takes.
    """
    ramps = jnp.asarray(stages, jnp.int32)
    count = len(stages) if count is None else count
    if solve is newton:
        shapes = _jacobian_shapes(lambda *a: F_at(1.0)(*a), x0, fixed)  # F_at's own work traced inside too

        def solve(F, x, tol, max_iter):
            return newton(F, x, tol, max_iter, fixed)

    else:
        shapes = jax.eval_shape(lambda: solve(F_at(1.0), x0, tol, max_iter))[1:3]
    r0, J0 = jax.tree.map(lambda o: jnp.zeros(o.shape, o.dtype), shapes)
    ramp_at = x_ramp if callable(x_ramp) else (lambda lam: lam * x_ramp)

    def not_done(c):
        return ~c[-2]

    def body(c):
        x, r, it, J, ramp, stage, _, _ = c
        K = ramps[ramp]
        lam = stage / K
        first = jax.tree.map(lambda a, b: jnp.where(K == 1, a, b), x0, ramp_at(lam))
        guess = jax.tree.map(lambda a, b: jnp.where(stage == 1, a, b), first, x)
        x_new, r_new, J_new, it_new, code = solve(F_at(lam), guess, tol, max_iter)
        ok = code == status.SUCCESS
        ramp_next = jnp.where(ok, ramp, ramp + 1)
        stage_next = jnp.where(ok, stage + 1, 1)
        done = (ok & (stage == K)) | (ramp_next == count)
        return x_new, r_new, it + it_new, J_new, jnp.where(done, ramp, ramp_next), stage_next, done, code

    init = (x0, jnp.full(r0.size, jnp.inf), jnp.zeros((), jnp.int32), J0, 0, 1, False, status.SUCCESS)
    x, r, it, J, ramp, _, _, code = lax.while_loop(not_done, body, init)
    code = jnp.where(code == _STALLED, status.CONTINUATION_EXHAUSTED, code).astype(jnp.int32)
    return Root(x, r, J, it, ramps[ramp], code)


def unset_root(F, x0) -> Root:
    """A Root of zeros at x0 shaped like ``continuation``'s (with ``newton``) for F: a loop's
    state before its first root, from one trace of F."""
    r, J = jax.tree.map(lambda o: jnp.zeros(o.shape, o.dtype), _jacobian_shapes(F, x0))
    zero = jnp.zeros((), jnp.int32)
    return Root(x0, r, J, zero, zero, zero)


def lazily(needed, f, otherwise, *operands):
    """f(*operands) where ``needed``, else ``otherwise``: a while loop of at most one pass rather
    than ``lax.cond``, so that under ``vmap`` f runs only when some lane needs it. f's work must
    depend on ``operands``, which pass an optimisation barrier tied to the loop's flag: what f
    reads only from its closure is invariant in this loop, and XLA hoists such work out of it
    (under ``vmap`` the grid start's coarse solves then ran for every lane of every chunk of a
    batched IK, 3 times the time of the rest)."""

    def body(c):
        return jnp.zeros_like(c[0]), f(*lax.optimization_barrier((c[0], operands))[1])

    return lax.while_loop(lambda c: c[0], body, (needed, otherwise))[1]
