"""Multiple shooting: the paper robot's RK4 steps in K intervals integrated side by side (issue 24).

The 2 * steps steps of the one scan over both segments (``shooting.shoot``) split into K intervals
of equal step count, each integrated with ``vmap`` from its own start State. The unknowns are
the scaled base wrench x (6,), as in single shooting, and each interior interval's start: its
rotation R_j and scaled total force n_j = N_j / F_c and moment m_j = M_j / (F_c L), K - 1 of
each. Positions are not unknowns: the vector field does not depend on p (segments.py), so each
interval runs from p = 0 and the positions are the running sum of the intervals' displacements.
The residuals: continuity of (R, N, M) at each interior start, vee of the skew part of
R_end R_j^T for the rotation (9 (K - 1)), then the tip condition (6), scaled as in shooting.py.

Each interval's end depends on its own start only, so the Jacobian is block bidiagonal. Its
blocks A_j = d(end of interval j) / d(start), with the start's rotation perturbed as
(I + w^) R_j, come from one ``jacfwd`` pass over all intervals at once. A Newton step eliminates
the interior updates along the intervals (condensation): d xi_j = a_j + B_j dx, with
d xi_0 = (0, dx), a_j = c_j + A_j-1 a_j-1 and B_j = A_j-1 B_j-1 (c_j: the continuity residual),
leaving a 6x6 system T B_K-1 dx = -(r + T a_K-1) for the base (T: the tip rows), damped as
``newton.newton`` damps it; rotations then move by the Cayley map. At the root T B_K-1 is the
chain rule of single shooting's Jacobian, so the implicit derivatives and the compliance (eq. 41)
are single shooting's. The chain of dependent operations is K times shorter; the arithmetic is
that of single shooting with 9 tangents instead of 6.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from . import shooting
from .description import GeneralRobot
from .newton import continuation, damped
from .segments import State
from .so3 import hat, orthonormalize

N_START = 9
"""Perturbations of an interval's start: rotation (3), scaled N (3), scaled M (3)."""

ORTHONORMALIZE = 4
"""Newton-Schulz steps that bring the coarse pass's rotations onto SO(3): each squares the error."""


class Unknowns(NamedTuple):
    """Multiple shooting's unknowns: the scaled base wrench x (6,) and the interior starts' R
    (K - 1, 3, 3), n = N / F_c and m = M / (F_c L) (K - 1, 3) each."""

    x: jax.Array
    R: jax.Array
    n: jax.Array
    m: jax.Array


class Blocks(NamedTuple):
    """Newton's linearisation, per interval: A (K, 9, 9) d(end rotation vector about the next
    start's R, n, m) / d(start), P (K, 3, 9) d(end position) / d(start), and D (3, 3, 9) d(tip R) /
    d(start of the last interval)."""

    A: jax.Array
    P: jax.Array
    D: jax.Array


def check(robot, solver) -> None:
    """Raises for what multiple shooting does not cover (a GeneralRobot, the paper's variants)."""
    K = solver.intervals
    if K > 1 and isinstance(robot, GeneralRobot):
        raise NotImplementedError(
            f"solver intervals = {K}: multiple shooting covers the paper's tdct.Robot only; solve a GeneralRobot with intervals = 1"
        )
    if K > 1 and (solver.transition != "balanced" or solver.tendon_model != "exact"):
        raise ValueError(
            f"solver intervals = {K} with transition = {solver.transition!r}, tendon_model = {solver.tendon_model!r}: "
            "multiple shooting needs the 'balanced' transition and the 'exact' tendon model (one scan over both segments); "
            "use intervals = 1 for the paper's variants"
        )


def _vee_skew(Q):
    """vee of the skew part of Q (..., 3, 3): the rotation vector of Q to first order."""
    return 0.5 * jnp.stack([Q[..., 2, 1] - Q[..., 1, 2], Q[..., 0, 2] - Q[..., 2, 0], Q[..., 1, 0] - Q[..., 0, 1]], -1)


def _cayley(w):
    """The Cayley map (I - w^/2)^-1 (I + w^/2) of rotation vectors w (..., 3): exactly a rotation,
    equal to exp(w^) to first order."""
    W = hat(w)
    c = 4 / (4 + jnp.sum(w**2, -1))[..., None, None]
    return jnp.broadcast_to(jnp.eye(3), W.shape) + c * (W + W @ W / 2)


def _intervals(robot, act, solver):
    """Per-step segments and step lengths of the one scan over both segments, (K, 2 steps / K, ...)."""
    back, sil = shooting.segments(robot, act, solver)
    n, K = solver.steps, solver.intervals
    (seg_b, h_b), (seg_s, h_s) = (
        shooting.per_step(back, act.insertion, n),
        shooting.per_step(sil, robot.length - act.insertion, n),
    )
    both = jax.tree.map(lambda a, b: jnp.concatenate([a, b]), (seg_b, h_b), (seg_s, h_s))
    return jax.tree.map(lambda a: a.reshape(K, 2 * n // K, *a.shape[1:]), both)


def _starts(u: Unknowns, F_c, L):
    """Every interval's start rotation, N and M, (K, ...) each; the base's R = I."""
    R = jnp.concatenate([jnp.eye(3)[None], u.R])
    N = jnp.concatenate([u.x[None, :3], u.n]) * F_c
    M = jnp.concatenate([u.x[None, 3:6], u.m]) * (F_c * L)
    return R, N, M


def _residual(u: Unknowns, ends: State, load, F_c, L):
    """Continuity at every interior start (K - 1, 9), flattened, then the tip residual (6,)."""
    cont = jnp.concatenate(
        [_vee_skew(ends.R[:-1] @ jnp.swapaxes(u.R, -1, -2)), ends.N[:-1] / F_c - u.n, ends.M[:-1] / (F_c * L) - u.m], -1
    )
    tip = jnp.concatenate([(ends.N[-1] - load.force) / F_c, (ends.M[-1] - load.moment) / (F_c * L)])
    return jnp.concatenate([cont.reshape(-1), tip])


def ends(robot, act, load, gravity, solver, u: Unknowns, F_c, path: bool = False):
    """Every interval's end State, integrated side by side from its start (p = 0), (K, ...), and
    the residual (``_residual``); with ``path`` the States at every interval's nodes (K, 2 steps / K + 1, ...)."""
    segs, h = _intervals(robot, act, solver)
    y = jax.vmap(lambda seg, h, R, N, M: shooting.integrate(seg, State(jnp.zeros(3), R, N, M), h, gravity, path))(
        segs, h, *_starts(u, F_c, robot.length)
    )
    return (y[1], _residual(u, y[0], load, F_c, robot.length)) if path else (y, _residual(u, y, load, F_c, robot.length))


def linearize(robot, act, load, gravity, solver, u: Unknowns, F_c):
    """The residual at u and its Blocks, from one forward-mode pass over all intervals."""
    L = robot.length
    segs, h = _intervals(robot, act, solver)
    R_next = jnp.concatenate([u.R, jnp.eye(3)[None]])  # the last interval's rotation rows are unused

    def one(seg, h, R, N, M, R_ref):
        def end(w):
            y = shooting.integrate(
                seg, State(jnp.zeros(3), R + hat(w[:3]) @ R, N + F_c * w[3:6], M + F_c * L * w[6:]), h, gravity
            )
            return (jnp.concatenate([_vee_skew(y.R @ R_ref.T), y.N / F_c, y.M / (F_c * L)]), y.p, y.R), y

        (A, P, D), y = jax.jacfwd(end, has_aux=True)(jnp.zeros(N_START))
        return y, A, P, D

    y, A, P, D = jax.vmap(one)(segs, h, *_starts(u, F_c, L), R_next)
    return _residual(u, y, load, F_c, L), Blocks(A, P, D[-1])


def _condense(A, c):
    """Interior updates as functions of the base update: d xi_j = a_j + B_j dx for every
    interval's start, a (K, 9) and B (K, 9, 6), from the continuity right-hand sides c (K - 1, 9)."""
    a, B = [jnp.zeros(N_START)], [jnp.zeros((N_START, 6)).at[3:].set(jnp.eye(6))]
    for j in range(A.shape[0] - 1):
        a.append(c[j] + A[j] @ a[-1])
        B.append(A[j] @ B[-1])
    return jnp.stack(a), jnp.stack(B)


def _step(u: Unknowns, r, blocks: Blocks, mu):
    """The Levenberg-Marquardt step by condensation: the 6x6 base update, then the interiors."""
    a, B = _condense(blocks.A, r[:-6].reshape(-1, N_START))
    T = blocks.A[-1, 3:]
    J, rhs = T @ B[-1], r[-6:] + T @ a[-1]
    dx = -jnp.linalg.solve(J.T @ J + mu * jnp.eye(6), J.T @ rhs)
    d = a[1:] + B[1:] @ dx
    return Unknowns(u.x + dx, _cayley(d[:, :3]) @ u.R, u.n + d[:, 3:6], u.m + d[:, 6:])


def jacobians(blocks: Blocks):
    """Single shooting's Jacobians d(tip residual) / dx (6, 6), d(tip p) / dx (3, 6) and d(tip R) / dx
    (3, 3, 6) by the chain rule along the intervals (at a root: RootInfo.jacobians)."""
    _, B = _condense(blocks.A, jnp.zeros((blocks.A.shape[0] - 1, N_START)))
    return blocks.A[-1, 3:] @ B[-1], (jnp.einsum("kij,kjl->il", blocks.P, B), blocks.D @ B[-1])


def coarse(robot, act, load, gravity, solver, x, F_c) -> Unknowns:
    """Interior starts from the scaled base wrench x by one cheap pass: one RK4 step per interval."""
    segs, h = _intervals(robot, act, solver)
    y0 = State(jnp.zeros(3), jnp.eye(3), x[:3] * F_c, x[3:6] * F_c * robot.length)
    _, ys = shooting.integrate(jax.tree.map(lambda a: a[:, 0], segs), y0, h.sum(1), gravity, path=True)
    R = ys.R[1:-1]
    for _ in range(ORTHONORMALIZE):  # a long step leaves R off SO(3); Newton's steps keep it on
        R = jax.vmap(orthonormalize)(R)
    return Unknowns(x, R, ys.N[1:-1] / F_c, ys.M[1:-1] / (F_c * robot.length))


@jax.custom_jvp
def root(robot, act, load, gravity, guess, solver):
    """``shooting.root`` by multiple shooting: the Unknowns at the root, and RootInfo (its
    Jacobians single shooting's, by ``jacobians``). Newton starts from ``guess`` (as
    ``shooting.root``) or the straight rod, the interiors from ``coarse``; each load stage of the
    continuation from the straight rod at that stage."""
    check(robot, solver)
    F_c = shooting.force_scale(robot, act, load, gravity)
    x0, x_straight = shooting.starts(robot, act, load, gravity, guess, F_c)

    def F_at(lam):
        problem = (robot, *shooting.loads_at(robot, act, load, gravity, lam), solver)
        return lambda u: linearize(*problem, u, F_c), problem

    def solve(F, guess, tol, max_iter):
        return damped(F[0], _step, guess, tol, max_iter)

    def ramp(lam):
        return coarse(*F_at(lam)[1], lam * x_straight, F_c)

    u0 = coarse(robot, act, load, gravity, solver, x0, F_c)
    found = continuation(F_at, u0, ramp, solver.tol, solver.max_iter, solver.stages, solve)
    return found.x, shooting.RootInfo(found.iterations, found.stages, found.result, jacobians(found.jacobians))


@root.defjvp
def _root_jvp(primals, tangents):
    """Implicit differentiation: the continuity and tip residuals' input tangents condensed
    along the intervals as in ``_step``, one 6x6 solve for dx, then the interiors'."""
    robot, act, load, gravity, guess, solver = primals
    u, info = root(*primals)
    F_c = shooting.force_scale(robot, act, load, gravity)
    _, blocks = linearize(robot, act, load, gravity, solver, u, F_c)
    _, dr = jax.jvp(lambda r, a, l, g: ends(r, a, l, g, solver, u, F_c)[1], primals[:4], tangents[:4])
    a, B = _condense(blocks.A, dr[:-6].reshape(-1, N_START))
    T = blocks.A[-1, 3:]
    dx = -jnp.linalg.solve(T @ B[-1], dr[-6:] + T @ a[-1])
    d = a[1:] + B[1:] @ dx
    du = Unknowns(dx, hat(d[:, :3]) @ u.R, d[:, 3:6], d[:, 6:])
    return (u, info), (du, jax.tree.map(shooting.zero_tangent, info))


def path(robot, act, load, gravity, solver, u: Unknowns):
    """The tip residual (6,) and the States at all 2 * steps + 1 nodes (``shooting.shoot``'s
    path) from the Unknowns, the intervals integrated side by side; each interior start node is
    the previous interval's end."""
    ys, r = ends(robot, act, load, gravity, solver, u, shooting.force_scale(robot, act, load, gravity), path=True)
    offsets = jnp.cumsum(ys.p[:, -1], 0) - ys.p[:, -1]
    ys = ys._replace(p=ys.p + offsets[:, None])
    return r[-6:], jax.tree.map(lambda a: jnp.concatenate([a[0], a[1:, 1:].reshape(-1, *a.shape[2:])]), ys)
