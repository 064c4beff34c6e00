"""Multiple shooting: a robot's RK4 steps in K intervals integrated side by side (issue 24).

The chain of RK4 steps of single shooting splits into K intervals of equal step count, each
integrated with ``vmap`` from its own start State. The chain is the robot's P breakpoint
intervals (``rod.plan``; the paper robot's two, [0, d] and [d, L]) of ``steps`` steps each, K
dividing P * steps (``rod.check_intervals``): cut into pieces of g = gcd(P steps / K,
steps) steps (``rod.pieces``), each inside one breakpoint interval, P steps / (K g) of them an
interval; K = P q (q dividing steps) makes every breakpoint a boundary, each breakpoint interval
cut into q, and K dividing P gives each interval P / K whole breakpoint intervals. A breakpoint's
jump (dN, dM: point loads and masses) is applied at the start of the piece after it, so at an
interval's start where the breakpoint is a boundary: the start unknowns are the state before it.

The unknowns are single shooting's scaled x (6 + n_d,): the base wrench, then the
displacement-driven tensions, which enter every interval; and each interior interval's start:
its rotation R_j and scaled total force n_j = N_j / F_c and moment m_j = M_j / (F_c L), K - 1 of
each. Positions and tendon lengths are not unknowns: the vector field depends on neither, so
each interval runs from p = 0, l = 0 and they are the running sums of the intervals'. The
residuals: continuity of (R, N, M) at each interior start, vee of the skew part of R_end R_j^T
for the rotation (9 (K - 1)), then single shooting's (tip, then the driven tendons'), scaled as
in shooting.py.

Each interval's end depends on its own start z_j = (R_j, n_j, m_j) and on the driven tensions t
only, so the Jacobian is block bidiagonal plus the columns of t. Its blocks, with the start's
rotation perturbed as (I + w^) R_j, come from one ``jacfwd`` pass over all intervals at once
(9 + n_d tangents, each perturbing every interval's start alike). A Newton step eliminates the
interior updates along the intervals (condensation): with z_j extended by t, d z_j = a_j + B_j dx,
d z_0 = (0, dx), a_j = c_j + A_j-1 a_j-1 and B_j = A_j-1 B_j-1 (c_j: the continuity residual),
leaving a (6 + n_d) system for x (the closing rows through the last end, and the tendon lengths
through every interval), damped as ``newton.newton`` damps it; rotations then move by the Cayley
map. At the root that system's matrix is the chain rule of single shooting's Jacobian, so the
implicit derivatives and the compliance (eq. 41) are single shooting's. The chain of dependent
operations is K times shorter; the arithmetic is that of single shooting with 9 + n_d tangents
instead of 6 + n_d.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from . import rod, shooting
from .newton import continuation, damped
from .segments import State
from .so3 import cayley, hat, orthonormalize, vee_skew

N_START = 9
"""Perturbations of an interval's start: rotation (3), scaled N (3), scaled M (3) (then the n_d
driven tensions)."""

ORTHONORMALIZE = 4
"""Newton-Schulz steps that bring the coarse pass's rotations onto SO(3): each squares the error."""


class Unknowns(NamedTuple):
    """Multiple shooting's unknowns: the scaled x (6 + n_d,) of single shooting (base wrench, then
    displacement-driven tensions) and the interior starts' R (K - 1, 3, 3),
    n = N / F_c and m = M / (F_c L) (K - 1, 3) each."""

    x: jax.Array
    R: jax.Array
    n: jax.Array
    m: jax.Array


class Blocks(NamedTuple):
    """Newton's linearisation in each interval's z = (start R, n, m, driven tensions / F_c) (9 + n_d):
    A (K, 9 + n_d, 9 + n_d) d(end rotation vector about the next start's R, n, m, then the
    tensions) / dz, P (K, 3, 9 + n_d) d(end position) / dz, L (K, n_l, 9 + n_d) d(tendon lengths
    along the interval) / dz, D (3, 3, 9 + n_d) d(tip R) / dz of the last interval, and H
    (6 + n_d, 6 + n_l + n_d) d(closing residual) / d(tip n, m, total lengths, tensions / F_c)."""

    A: jax.Array
    P: jax.Array
    L: jax.Array
    D: jax.Array
    H: jax.Array


def check(robot, load, solver) -> None:
    """Raises for an interval count multiple shooting cannot take (ValueError naming ``intervals``)
    and for the paper's variants."""
    K = solver.intervals
    if K == 1:
        return
    rod.check_intervals(robot, load, solver)
    if solver.transition != "balanced" or solver.tendon_model != "exact":
        raise ValueError(
            f"solver intervals = {K} with transition = {solver.transition!r}, tendon_model = {solver.tendon_model!r}: "
            "multiple shooting needs the 'balanced' transition and the 'exact' tendon model; "
            "use intervals = 1 for the paper's variants"
        )


def _starts(u: Unknowns, F_c, L):
    """Every interval's start rotation, N and M, (K, ...) each; the base's R = I."""
    R = jnp.concatenate([jnp.eye(3)[None], u.R])
    N = jnp.concatenate([u.x[None, :3], u.n]) * F_c
    M = jnp.concatenate([u.x[None, 3:6], u.m]) * (F_c * L)
    return R, N, M


class Run(NamedTuple):
    """The intervals integrated side by side (``run``): end States (K, ...) from p = 0, tendon
    lengths along each interval (K, n_l; n_l = 0 where none are needed), the actuation with the
    driven tensions and the plan, and the nodes
    (``path``; None otherwise)."""

    ends: State
    lengths: jax.Array
    act: object
    plan: object
    nodes: object


def run(robot, act, load, gravity, solver, x, starts, F_c, path: bool = False) -> Run:
    """Every interval integrated from its start (R, N, M) (K, ...): the breakpoint intervals cut by
    ``rod.pieces``, the driven tensions from x[6:] in every interval."""
    R, N, M = starts
    K = solver.intervals
    y0 = State(jnp.zeros((K, 3)), R, N, M)
    act = rod.with_driven(act, x, F_c)
    pl = rod.plan(robot, act, load, gravity)
    ps, g = rod.pieces(pl, solver.steps, K)
    l0 = jnp.zeros((K, robot.n_tendons)) if act.driven or path else None
    end, nodes = jax.vmap(lambda p, c: rod.integrate(robot, load, gravity, p, c, g, path, rotation=solver.rotation))(
        ps, rod.Carry(y0, None, l0)
    )
    return Run(end.y, jnp.zeros((K, 0)) if l0 is None else end.l, act, pl, nodes)


def _closing(robot, load, r: Run, N, M, lengths, x, F_c):
    """The closing residual at the tip's N, M (before the jump at L) with the tendon lengths summed
    over the intervals and x: tip (6,), then the driven tendons (``rod.closing``); and its
    slack flags."""
    act = rod.with_driven(r.act, x, F_c)
    return rod.closing(robot, act, load, r.plan, State(None, None, N, M), lengths, F_c)


def _closing_at(robot, load, u: Unknowns, r: Run, F_c):
    """``_closing`` at the last interval's end."""
    return _closing(robot, load, r, r.ends.N[-1], r.ends.M[-1], jnp.sum(r.lengths, 0), u.x, F_c)


def _residual(robot, load, u: Unknowns, r: Run, F_c):
    """Continuity at every interior start (K - 1, 9), flattened, then the closing residual (6 + n_d,)."""
    ends, L = r.ends, robot.length
    cont = jnp.concatenate(
        [vee_skew(ends.R[:-1] @ jnp.swapaxes(u.R, -1, -2)), ends.N[:-1] / F_c - u.n, ends.M[:-1] / (F_c * L) - u.m], -1
    )
    return jnp.concatenate([cont.reshape(-1), _closing_at(robot, load, u, r, F_c)[0]])


def evaluate(robot, act, load, gravity, solver, u: Unknowns, F_c, path: bool = False):
    """The residual (``_residual``) at u and the Run of the intervals from their starts."""
    r = run(robot, act, load, gravity, solver, u.x, _starts(u, F_c, robot.length), F_c, path)
    return _residual(robot, load, u, r, F_c), r


def linearize(robot, act, load, gravity, solver, u: Unknowns, F_c):
    """The residual at u and its Blocks, from one forward-mode pass over all intervals at once:
    one perturbation w of every interval's z (each interval's end depends on its own start, and
    every interval on the driven tensions)."""
    L, n_d = robot.length, u.x.size - 6
    R, N, M = _starts(u, F_c, L)
    R_next = jnp.concatenate([u.R, jnp.eye(3)[None]])  # the last interval's rotation rows are unused

    def ends(w):
        x = u.x.at[6:].add(w[9:])
        starts = (hat(w[:3])[None] @ R + R, N + F_c * w[None, 3:6], M + F_c * L * w[None, 6:9])
        r = run(robot, act, load, gravity, solver, x, starts, F_c)
        y = r.ends
        z = jnp.concatenate([vee_skew(y.R @ jnp.swapaxes(R_next, -1, -2)), y.N / F_c, y.M / (F_c * L)], -1)
        return (z, y.p, r.lengths, y.R[-1]), r

    (Z, P, Lj, D), r = jax.jacfwd(ends, has_aux=True)(jnp.zeros(N_START + n_d))
    K = Z.shape[0]
    tensions = jnp.broadcast_to(jnp.eye(N_START + n_d)[N_START:], (K, n_d, N_START + n_d))
    n_l = Lj.shape[1]

    def closing(v):  # v: tip n, m, total lengths, x[6:]
        x = u.x.at[6:].set(v[6 + n_l :])
        return _closing(robot, load, r, v[:3] * F_c, v[3:6] * (F_c * L), v[6 : 6 + n_l], x, F_c)[0]

    v = jnp.concatenate([r.ends.N[-1] / F_c, r.ends.M[-1] / (F_c * L), jnp.sum(r.lengths, 0), u.x[6:]])
    H = jax.jacfwd(closing)(v)
    return _residual(robot, load, u, r, F_c), Blocks(jnp.concatenate([Z, tensions], 1), P, Lj, D, H)


def _condense(A, c):
    """Every interval's z as a function of the update dX of x: dz_j = a_j + B_j dX, a (K, 9 + n_d)
    and B (K, 9 + n_d, 6 + n_d), from the continuity right-hand sides c (K - 1, 9)."""
    m = A.shape[-1]
    a, B = [jnp.zeros(m)], [jnp.zeros((m, m - 3)).at[3:].set(jnp.eye(m - 3))]
    for j in range(A.shape[0] - 1):
        a.append(jnp.zeros(m).at[:N_START].set(c[j]) + A[j] @ a[-1])
        B.append(A[j] @ B[-1])
    return jnp.stack(a), jnp.stack(B)


def _closing_rows(blocks: Blocks):
    """d(closing residual) / d(last z) (6 + n_d, 9 + n_d) and / d(total lengths) (6 + n_d, n_l)."""
    H, n_l = blocks.H, blocks.L.shape[1]
    last = H[:, :6] @ blocks.A[-1, 3:N_START]
    return last.at[:, N_START:].add(H[:, 6 + n_l :]), H[:, 6 : 6 + n_l]


def _reduce(blocks: Blocks, r):
    """The condensed system: J dX = -rhs for x (6 + n_d), and the a, B of ``_condense``."""
    n_x = blocks.H.shape[0]
    a, B = _condense(blocks.A, r[:-n_x].reshape(-1, N_START))
    last, H_l = _closing_rows(blocks)
    J = last @ B[-1] + H_l @ jnp.einsum("kij,kjl->il", blocks.L, B)
    rhs = r[-n_x:] + last @ a[-1] + H_l @ jnp.einsum("kij,kj->i", blocks.L, a)
    return J, rhs, a, B


def _step(u: Unknowns, r, blocks: Blocks, mu):
    """The Levenberg-Marquardt step by condensation: the (6 + n_d) system for x, then the interiors."""
    J, rhs, a, B = _reduce(blocks, r)
    dx = -jnp.linalg.solve(J.T @ J + mu * jnp.eye(J.shape[0]), J.T @ rhs)
    d = a[1:] + B[1:] @ dx
    return Unknowns(u.x + dx, cayley(d[:, :3]) @ u.R, u.n + d[:, 3:6], u.m + d[:, 6:N_START])


def jacobians(blocks: Blocks):
    """Single shooting's Jacobians d(residual) / dx (6 + n_d, 6 + n_d), d(tip p) / dx (3, 6 + n_d)
    and d(tip R) / dx (3, 3, 6 + n_d) by the chain rule along the intervals (at a root:
    RootInfo.jacobians)."""
    J, _, _, B = _reduce(blocks, jnp.zeros((blocks.A.shape[0] - 1) * N_START + blocks.H.shape[0]))
    return J, (jnp.einsum("kij,kjl->il", blocks.P, B), blocks.D @ B[-1])


def coarse(robot, act, load, gravity, solver, x, F_c) -> Unknowns:
    """Interior starts from the scaled x by one cheap pass: one RK4 step per piece of
    ``rod.pieces``."""
    L = robot.length
    y0 = State(jnp.zeros(3), jnp.eye(3), x[:3] * F_c, x[3:6] * F_c * L)
    act = rod.with_driven(act, x, F_c)
    ps, g = rod.pieces(rod.plan(robot, act, load, gravity), solver.steps, solver.intervals)
    flat = jax.tree.map(lambda a: a.reshape(-1, *a.shape[2:]), ps)._replace(h=ps.h.reshape(-1) * g)
    _, nodes = rod.integrate(robot, load, gravity, flat, rod.Carry(y0), 1, path=True, rotation=solver.rotation)
    ys = jax.tree.map(lambda a: a[ps.h.shape[1] - 1 :: ps.h.shape[1], 1][:-1], nodes.y)
    R = ys.R
    for _ in range(ORTHONORMALIZE):  # a long step leaves R off SO(3); Newton's steps keep it on
        R = jax.vmap(orthonormalize)(R)
    return Unknowns(x, R, ys.N / F_c, ys.M / (F_c * L))


def root(robot, act, load, gravity, guess, solver):
    """``shooting.root`` by multiple shooting: the Unknowns at the root, and RootInfo (its
    Jacobians single shooting's, by ``jacobians``). Newton starts from ``guess`` (as
    ``shooting.root``) or the straight rod, the interiors from ``coarse``; each load stage of the
    continuation from the straight rod at that stage."""
    return _root(robot, act, load, gravity, guess, solver)[:2]


@jax.custom_jvp
def _root(robot, act, load, gravity, guess, solver):
    """``root``, and Newton's Blocks at the root, for its derivatives."""
    check(robot, load, solver)
    F_c = shooting.force_scale(robot, act, load, gravity)
    x0, x_straight = shooting.starts(robot, act, load, gravity, guess, F_c)

    def F_at(lam):
        problem = (robot, *shooting.loads_at(act, load, gravity, lam), solver)
        return lambda u: linearize(*problem, u, F_c), problem

    def solve(F, guess, tol, max_iter):
        return damped(F[0], _step, guess, tol, max_iter)

    def ramp(lam):
        return coarse(*F_at(lam)[1], lam * x_straight, F_c)

    u0 = coarse(robot, act, load, gravity, solver, x0, F_c)
    found = continuation(F_at, u0, ramp, solver.tol, solver.max_iter, solver.stages, solve)
    info = shooting.RootInfo(found.iterations, found.stages, found.result, jacobians(found.jacobians))
    return found.x, info, found.jacobians


@_root.defjvp
def _root_jvp(primals, tangents):
    """Implicit differentiation: the continuity and closing residuals' input tangents condensed
    along the intervals as in ``_step`` with Newton's own Blocks at the root (no Jacobian pass of
    its own), one (6 + n_d) solve for dx, then the interiors'."""
    robot, act, load, gravity, guess, solver = primals
    u, info, blocks = _root(*primals)
    F_c = shooting.force_scale(robot, act, load, gravity)
    _, dr = jax.jvp(lambda r, a, l, g: evaluate(r, a, l, g, solver, u, F_c)[0], primals[:4], tangents[:4])
    J, rhs, a, B = _reduce(blocks, dr)
    dx = -jnp.linalg.solve(J, rhs)
    d = a[1:] + B[1:] @ dx
    du = Unknowns(dx, hat(d[:, :3]) @ u.R, d[:, 3:6], d[:, 6:N_START])
    return (u, info, blocks), (du, *jax.tree.map(shooting.zero_tangent, (info, blocks)))


def path(robot, act, load, gravity, solver, u: Unknowns):
    """``shooting.shoot``'s residual and path from the Unknowns, the intervals integrated side by
    side: (nodes, plan, actuation, lengths, slack) as ``rod.shoot`` gives them (each interior
    start node the previous interval's end)."""
    F_c = shooting.force_scale(robot, act, load, gravity)
    res, r = evaluate(robot, act, load, gravity, solver, u, F_c, path=True)
    n_x = u.x.size
    tail = res[-n_x:]
    offsets = jnp.cumsum(r.ends.p, 0) - r.ends.p
    ys = r.nodes.y._replace(p=r.nodes.y.p + offsets[:, None, None])
    n_b = r.plan.b.size - 1

    def by_breakpoint_interval(a):  # pieces (K, c / g, g + 1, ...) -> (P, steps + 1, ...)
        return rod.by_interval(a.reshape(-1, *a.shape[2:]), n_b)

    lengths = jnp.sum(r.lengths, 0)
    slack = _closing_at(robot, load, u, r, F_c)[1]
    return tail, (rod.Carry(jax.tree.map(by_breakpoint_interval, ys)), r.plan, r.act, lengths, slack, None)
