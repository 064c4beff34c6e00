"""The robot in motion: implicit time stepping of the Cosserat rod of rod plus tendons, each time
step a boundary-value problem in arc length solved by shooting (Till, Aloi and Rucker, IJRR 2019;
docs/dynamics.md).

Time derivatives are replaced by the BDF-alpha formula (Till et al., eq. 12): for any variable z
along the rod,

    z_t(t_i) = c0 z(t_i) + z_h,     z_h = c1 z(t_i-1) + c2 z(t_i-2) + d1 z_t(t_i-1),
    c0 = (1.5 + a) / (dt (1 + a)),  c1 = -2 / dt,  c2 = (0.5 + a) / (dt (1 + a)),  d1 = a / (1 + a),

a in [-0.5, 0]: a = -0.5 is the trapezoidal rule (second order, no numerical dissipation), a = 0
BDF2 (second order, damping the fastest modes most). The history z_h is known at each step, so
the dynamic equations become ODEs in s, integrated by RK4 like the static ones, with the state
(p, R, N, M) of statics plus the body-frame velocity q and angular velocity w:

    p' = R v,  R' = R u^,
    N' = -f + rho R (q_t + w x q),                M' = -p' x N + R (rhoJ w_t + w x rhoJ w),
    q' = v_t - u x q + w x v,                     w' = u_t - u x w,

with N, M the total force and moment of rod plus tendons (massless tendons: their forces stay
internal, as in statics). The constitutive relations are the static ones with Kelvin-Voigt
damping (``Section.damping`` = tau_d): the rod's stress is K (v - e3) + tau_d K v_t, which with
v_t = c0 (v - e3) + v_h (the history kept of the strain v - e3, not of v, so that no unit vector's
rounding is multiplied by c0) is the static relation with stiffness (1 + c0 tau_d) K and
reference strain e3 - tau_d v_h / (1 + c0 tau_d), so that the static solver of the strains
serves unchanged.

The history lives where the vector field is evaluated: at each RK4 stage of each step (4 points
a step), so the integration in s keeps its fourth order. The unknowns of each time step are the
static ones, the base's N(0), M(0) (q = w = 0 at the clamped base); with K shooting intervals
(``solver.intervals``, multiple shooting) also each interior interval's start (R, N, M, q, w),
and its continuity is K - 1 more residuals. Single shooting's sensitivity grows as exp(k L),
k L = 1.06 sqrt(steps per first period) for a cantilever: the time step's inertia acts as an
elastic foundation whose stiffness grows as 1 / dt^2, and K intervals divide k L by K. Chord
steps, then Newton's method (a jacfwd Jacobian, one forward pass for all intervals at once;
Levenberg-Marquardt where a step does not lower the residual) start from the last three roots
extrapolated (``_extrapolate``, ``_step``), and the root passes ``lax.custom_root``: derivatives of any trajectory
output with respect to every input go through each step's implicit solve.

Tendon friction takes statics' rows, the last time step's tension profile as the memory
(``_integrate``); tubes that move carry the history to the moved stage points (``remap``).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from . import contact, newton, rod, status
from .checks import as_array, check_range, is_concrete
from .description import Robot
from .inputs import STANDARD_GRAVITY, Actuation, Loads, gravity_vector
from .options import DEFAULT_SOLVER, SolverOptions
from .segments import E3, Segment, State, body_strains, tendon_pb, tendon_tangents
from .so3 import cayley, hat, orthonormalize, vee_skew
from .solve import solve, with_scene
from .tree import pytree

ALPHA = -0.2
"""Default BDF-alpha parameter (Till et al.'s choice): second order, a little high-frequency
dissipation."""

INTERVALS = 4
"""``simulate``'s shooting intervals by default (the largest count up to it that divides the
robot's P x ``steps`` RK4 steps). Single shooting fails outright on the paper robot under a
sudden 2 N pull at 5 ms steps; four intervals converge at every step (docs/dynamics.md)."""


def default_solver(robot: Robot, load: Loads, steps: int = DEFAULT_SOLVER.steps, **options) -> SolverOptions:
    """``simulate``'s solver by default: statics' options (``options`` override them) with the
    largest shooting-interval count up to ``INTERVALS`` that divides the robot's RK4 steps (one
    with tendon friction or a scene in ``load``: single shooting carries the tension profiles and
    the contact candidates' absolute positions)."""
    n = rod.n_intervals(robot, load) * steps
    most = 1 if robot.has_friction or load.scene is not None else INTERVALS
    return SolverOptions(steps=steps, intervals=max(k for k in range(1, most + 1) if n % k == 0), **options)


class Scheme(NamedTuple):
    """BDF-alpha coefficients (module docstring) of one step length."""

    c0: jax.Array
    c1: jax.Array
    c2: jax.Array
    d1: jax.Array


def scheme(dt, alpha=ALPHA) -> Scheme:
    """The BDF-alpha coefficients for step ``dt`` [s] and parameter ``alpha`` in [-0.5, 0]."""
    return Scheme((1.5 + alpha) / (dt * (1 + alpha)), -2.0 / dt, (0.5 + alpha) / (dt * (1 + alpha)), alpha / (1 + alpha))


STATIC = Scheme(0.0, 0.0, 0.0, 0.0)
"""Every time derivative zero: the dynamic equations reduce to statics."""


class Dyn(NamedTuple):
    """The state along s: the static State y, the body-frame velocity q [m/s] and angular
    velocity w [rad/s], each tendon's rest length from the interval's start l [m] (n_t,), and
    with tendon friction the tendons' ``rod.Friction`` state (None without)."""

    y: State
    q: jax.Array
    w: jax.Array
    l: jax.Array
    f: rod.Friction | None = None


class Layout(NamedTuple):
    """One time step's integration plan: per RK4 step (P intervals x ``steps``), its interval's
    parameters, start s0 [m], length h [m], the jump (dN, dM) and point mass [kg] at its start;
    and the ``rod.Plan`` it was made from (its last jump and point mass act at L)."""

    P: rod.Interval
    s0: jax.Array
    h: jax.Array
    dN: jax.Array
    dM: jax.Array
    mass: jax.Array
    plan: rod.Plan | None


def _points(b, steps: int, offsets=(0.0,)):
    """Arc lengths [m] of ``steps`` RK4 steps per interval between breakpoints b (P + 1,), each
    step's points at ``offsets`` of its length: (P, steps, len(offsets))."""
    h = (b[1:] - b[:-1]) / steps
    at = np.arange(steps)[:, None] + np.asarray(offsets)[None, :]
    return b[:-1, None, None] + h[:, None, None] * at[None]


def layout(robot: Robot, act: Actuation, load: Loads, gravity, steps: int) -> Layout:
    """``rod.plan``'s intervals as ``steps`` RK4 steps each."""
    pl = rod.plan(robot, act, load, gravity)
    n = pl.b.size - 1
    h = (pl.b[1:] - pl.b[:-1]) / steps
    first = (np.arange(steps) == 0)[None, :, None]

    def jump(d):
        return jnp.where(first, d[:-1, None], 0.0).reshape(n * steps, 3)

    return Layout(
        jax.tree.map(lambda a: jnp.repeat(a, steps, axis=0), pl.intervals),
        _points(pl.b, steps).reshape(-1),
        jnp.repeat(h, steps),
        jump(pl.dN),
        jump(pl.dM),
        jnp.where(first[..., 0], pl.mass[:-1, None], 0.0).reshape(-1),
        pl,
    )


def _integrate(robot: Robot, load: Loads, gravity, lay: Layout, c: Scheme, stages, start: Dyn, memory=None, forces=None):
    """RK4 along the steps of ``lay`` from ``start`` with the stage points' history terms
    ``stages`` (v_h, u_h, q_h, w_h) (n, 4, 12). Returns the end, the nodes (n + 1 Dyn) and what
    the history is made of: each stage point's (v - e3, u, q, w) (the strain rather than v, so
    that c0 z + z_h does not cancel a unit vector's rounding times c0). A point mass m at a step's start
    takes m (g - p_tt) from N, p_tt = R (q_t + w x q) there (stage 1's history). The tendons' rest
    lengths grow as in statics (``rod.integrate``: dl = |p_b| / (1 + tau / EA) where present).

    With tendon friction each step's span keeps one tension per tendon, and at the node that ends
    it the next span's is the last time step's there (``memory``, (n, n_t); None: zeros, loaded
    from slack) held within the capstan bounds, as in statics (``rod.guided``; the tangents there
    from the step's fourth stage's history).

    ``forces``: with ``load.scene``, each step's contact forces against its obstacles [N] (n,
    n_o) (nonzero at candidates only): N jumps at the step's start by the point force -sum_o
    lambda_o n_o(p) (contact.py), p the absolute position (single shooting); the fourth output
    is then every step start's ``contact.Starts`` (position and gaps), else None."""
    after = jnp.array([0.5, 0.5, 1.0])
    weights = jnp.array([1.0, 2.0, 2.0, 1.0]) / 6
    f_d = load.distributed_force
    EA = rod.tendon_stiffness(robot) if robot.tendons else jnp.zeros(0)

    def spans(P: rod.Interval, d: Dyn) -> rod.Interval:
        return P if d.f is None else P._replace(tau=P.present * d.f.tau)

    def strains(P: rod.Interval, s, z_h, d: Dyn):
        """The segment and the damped constitutive relation's (v, u) at the state d."""
        seg = rod._segment(robot, P, s)
        a = 1.0 + c.c0 * P.damping
        stiff = Segment(seg.K_se * a, seg.K_bt * a, seg.rho, seg.tau, seg.r, seg.backbone, seg.tilt, seg.dr)
        # K' (v - v*') with K' = a K, v*' = e3 - tau_d v_h / a: the static relation shifted by K' (v*' - e3)
        bf = d.y.R.T @ d.y.N - seg.K_se * P.damping * z_h[:3]
        bm = d.y.R.T @ d.y.M - seg.K_bt * P.damping * z_h[3:6]
        return (seg, *body_strains(stiff, bf, bm))

    def field(P: rod.Interval, s, z_h, d: Dyn):
        seg, v, u = strains(spans(P, d), s, z_h, d)
        v_h, u_h, q_h, w_h = z_h[:3], z_h[3:6], z_h[6:9], z_h[9:]
        v_t, u_t, q_t, w_t = c.c0 * (v - E3) + v_h, c.c0 * u + u_h, c.c0 * d.q + q_h, c.c0 * d.w + w_h
        R = d.y.R
        dp = R @ v
        dN = -P.rho * gravity - f_d + P.rho * (R @ (q_t + jnp.cross(d.w, d.q)))
        dM = -jnp.cross(dp, d.y.N) + R @ (P.rhoJ * w_t + jnp.cross(d.w, P.rhoJ * d.w))
        dq = v_t - jnp.cross(u, d.q) + jnp.cross(d.w, v)
        dw = u_t - jnp.cross(u, d.w)
        dl = P.present * jnp.linalg.norm(tendon_pb(seg, v, u), axis=-1) / (1 + seg.tau / EA)
        df = None if d.f is None else jax.tree.map(jnp.zeros_like, d.f)
        return Dyn(State(dp, R @ hat(u), dN, dM), dq, dw, dl, df), jnp.concatenate([v - E3, u, d.q, d.w])

    def tangents(P: rod.Interval, s, z_h, d: Dyn):
        """Each tendon's world tangent at d, (n_t, 3) (tensions: the span just integrated)."""
        seg, v, u = strains(spans(P, d), s, z_h, d)
        return tendon_tangents(seg, v, u) @ d.y.R.T

    def step(d: Dyn, k):
        P, s0, h, dN, dM, m, z_h, previous, f = k
        d = d._replace(y=d.y._replace(N=d.y.N + dN + m * _acceleration(c, d, z_h[0, 6:9]), M=d.y.M + dM))
        touch = None
        if f is not None:
            F, touch = contact.at_start(load.scene, f, d.y.p, P.radius)
            d = d._replace(y=d.y._replace(N=d.y.N - F))
        k1, z1 = field(P, s0, z_h[0], d)
        k2, z2 = field(P, s0 + h / 2, z_h[1], jax.tree.map(lambda a, b: a + h * after[0] * b, d, k1))
        k3, z3 = field(P, s0 + h / 2, z_h[2], jax.tree.map(lambda a, b: a + h * after[1] * b, d, k2))
        k4, z4 = field(P, s0 + h, z_h[3], jax.tree.map(lambda a, b: a + h * after[2] * b, d, k3))
        ks = (k1, k2, k3, k4)
        new = jax.tree.map(lambda a, *b: a + h * sum(w * bi for w, bi in zip(weights, b, strict=True)), d, *ks)
        new = new._replace(y=new.y._replace(R=orthonormalize(new.y.R)))
        if new.f is not None:
            new = new._replace(f=rod.guided(new.f, tangents(P, s0 + h, z_h[3], new), P, s0 + h, h, previous))
        return new, (new, jnp.stack([z1, z2, z3, z4]), touch)

    if robot.has_friction and start.f is None:
        P0 = jax.tree.map(lambda a: a[0], lay.P)
        n_t = robot.n_tendons
        start = start._replace(f=rod.Friction(P0.tau, P0.tau, jnp.zeros((n_t, 3)), jnp.zeros(n_t)))
        start = start._replace(f=start.f._replace(T=tangents(P0, lay.s0[0], stages[0, 0], start)))
    if robot.has_friction and memory is None:
        memory = jnp.zeros((lay.h.size, robot.n_tendons))
    xs = (lay.P, lay.s0, lay.h, lay.dN, lay.dM, lay.mass, stages, memory, forces)
    end, (nodes, z, touch) = lax.scan(step, start, xs)
    return end, jax.tree.map(lambda a, b: jnp.concatenate([a[None], b]), start, nodes), z, touch


def _acceleration(c: Scheme, d: Dyn, q_h):
    """p_tt = R (q_t + w x q) at the state d, q_t = c0 q + q_h."""
    return d.y.R @ (c.c0 * d.q + q_h + jnp.cross(d.w, d.q))


STAGES = (0.0, 0.5, 0.5, 1.0)
"""Where in its RK4 step each stage's vector field is evaluated, as a fraction of the step."""


def remap(z, b_old, b_new, steps: int):
    """Stage-point values z (P steps, 4, ...) of the integration plan with breakpoints b_old
    (P + 1,), at the stage points of the plan with breakpoints b_new (a tube's end moved): each
    material point's own value. Each stage's values are interpolated along s through the four
    nearest points of the same stage in the old breakpoint interval that holds the new point
    (cubic Lagrange; strains jump at breakpoints, so no interval borrows from its neighbour); a
    new point at a breakpoint belongs to its own interval's side."""
    P = b_old.size - 1
    offsets = jnp.asarray(STAGES)[None, None, :]
    s = _points(b_new, steps, STAGES)
    middle = ((b_new[:-1] + b_new[1:]) / 2)[:, None, None]
    k = jnp.clip(jnp.searchsorted(b_old, s + 1e-9 * (middle - s), side="right") - 1, 0, P - 1)
    h = (b_old[k + 1] - b_old[k]) / steps
    t = jnp.where(h > 0, (s - b_old[k]) / jnp.where(h > 0, h, 1.0), 0.0) - offsets
    n = min(4, steps)
    first = jnp.clip(jnp.floor(t).astype(int) - (n - 1) // 2, 0, steps - n)
    x = t - first

    def basis(j):
        return math.prod(((x - m) / (j - m) for m in range(n) if m != j), start=jnp.ones_like(x))

    weights = jnp.stack([basis(j) for j in range(n)], -1)
    stage = jnp.broadcast_to(jnp.arange(4)[None, None, :, None], (*t.shape, n))
    picked = z.reshape(P, steps, 4, -1)[k[..., None], first[..., None] + jnp.arange(n)[None, None, None, :], stage]
    return jnp.einsum("...n,...nc->...c", weights, picked).reshape(z.shape)


CHORD_STEPS = 4
"""Most chord steps (the Jacobian of the extrapolated guess, a primal pass each) a time step tries
before Newton's own: from a guess as close as the last roots' extrapolation, each squares the
error's ratio to the guess's (e_k ~ e_0^(k+1))."""

N_START = 15
"""An interior shooting interval's start unknowns: its rotation (3), then N, M, q and w (3 each)."""


class Unknowns(NamedTuple):
    """One time step's unknowns: the scaled base wrench and driven tensions x (6 + n_d,) (N(0) /
    F_c, M(0) / (F_c L), then each displacement-driven tendon's tension / F_c, as in statics'
    ``rod.shoot``), and with K shooting intervals (``solver.intervals``) each interior start's
    rotation R (K - 1, 3, 3) and its (N, M, q, w) divided by ``_scale`` (K - 1, 12)."""

    x: jax.Array
    R: jax.Array
    z: jax.Array

    def physical(self, F_c, S) -> Unknowns:
        """x times F_c and z times S: the units kept from one time step to the next, whose F_c
        differs where the inputs change (``scaled`` the inverse)."""
        return Unknowns(self.x * F_c, self.R, self.z * S[None])

    def scaled(self, F_c, S) -> Unknowns:
        return Unknowns(self.x / F_c, self.R, self.z / S[None])


def _scale(F_c, L, dt):
    """The units of (N, M, q, w) in the unknowns and the residual: F_c, F_c L, L / dt, 1 / dt."""
    return jnp.repeat(jnp.stack([F_c, F_c * L, L / dt, 1.0 / dt]), 3)


def _candidates(robot: Robot, load: Loads, steps: int) -> np.ndarray:
    """The RK4 steps whose starts are the interior contact candidates of ``load.scene`` (a
    candidate every ``scene.every`` steps, the base excluded; the tip's comes last)."""
    n = rod.n_intervals(robot, load) * steps
    return load.scene.every * np.arange(1, contact.n_candidates(1, n, load.scene.every))


def _n_contact(robot: Robot, load: Loads, steps: int) -> int:
    """Contact unknowns: one force per candidate (``_candidates`` and the tip) and obstacle, 0
    without a scene."""
    return 0 if load.scene is None else (_candidates(robot, load, steps).size + 1) * load.scene.n_obstacles


class Problem(NamedTuple):
    """One time step's boundary-value problem at given inputs: the robot, actuation (tensions,
    the driven tendons' commanded displacements), loads, gravity, scheme, history ((n_steps, 4,
    12) stage points, (6,) tip), with tendon friction the last step's span tensions
    (``_integrate``'s memory, (n_steps, n_t); else None), force scale F_c, ``_scale``, K, RK4
    steps per breakpoint interval and the contact rows' smoothing mu
    (``contact.fischer_burmeister``)."""

    robot: Robot
    act: Actuation
    load: Loads
    gravity: jax.Array
    c: Scheme
    history: tuple
    memory: jax.Array | None
    F_c: jax.Array
    S: jax.Array
    K: int
    steps: int
    mu: jax.Array = 0.0

    def actuation(self, x) -> Actuation:
        """The actuation with the driven tendons' tensions of the unknowns x."""
        return rod.with_driven(self.act, x, self.F_c)

    @property
    def n_extra(self) -> int:
        """The unknowns after the base wrench: driven tensions, then contact forces (n_c n_o)."""
        return len(self.act.driven) + self.n_contact

    @property
    def n_contact(self) -> int:
        return _n_contact(self.robot, self.load, self.steps)

    @property
    def candidates(self) -> np.ndarray:
        """``_candidates`` of this problem."""
        return _candidates(self.robot, self.load, self.steps)

    def forces(self, x):
        """The contact forces of the unknowns x [N], (n_c, n_o), the tip's last; None without a scene."""
        if self.load.scene is None:
            return None
        return x[6 + len(self.act.driven) :].reshape(-1, self.load.scene.n_obstacles) * self.F_c

    def layout(self, x) -> Layout:
        return layout(self.robot, self.actuation(x), self.load, self.gravity, self.steps)

    def run(self, lay: Layout, R, y, x):
        """The K intervals integrated side by side from their starts, rotations R (K, 3, 3) and
        (N, M, q, w) y (K, 12), each from p = 0 and l = 0, with the contact forces of the
        unknowns x (single shooting): ends, nodes (K, n_steps / K + 1), stage values and with a
        scene each step start's ``contact.Starts``."""
        K = self.K
        lam = self.forces(x)
        forces = None if lam is None else jnp.zeros((lay.h.size, lam.shape[1])).at[self.candidates].set(lam[:-1])

        def split(a):
            return a.reshape(K, -1, *a.shape[1:])

        zeros = jnp.zeros((K, 3))
        start = Dyn(State(zeros, R, y[:, :3], y[:, 3:6]), y[:, 6:9], y[:, 9:], jnp.zeros((K, self.robot.n_tendons)))
        per = jax.tree.map(split, lay._replace(plan=None))
        integrate = jax.vmap(
            lambda lay, stages, d, memory, forces: _integrate(
                self.robot, self.load, self.gravity, lay, self.c, stages, d, memory, forces
            )
        )
        memory = None if self.memory is None else split(self.memory)
        return integrate(per, split(self.history[0]), start, memory, None if forces is None else split(forces))

    def starts(self, u: Unknowns):
        """Every interval's start rotation (K, 3, 3) and (N, M, q, w) (K, 12); the base's R = I, q = w = 0."""
        R = jnp.concatenate([jnp.eye(3)[None], u.R])
        return R, jnp.concatenate([jnp.concatenate([u.x[:6], jnp.zeros(6)])[None], u.z]) * self.S[None]

    def closing(self, lay: Layout, x, ends: Dyn, R_next, lengths=None, starts=None):
        """Each interval's end against the next start, rotation vector of R_end R_next^T and
        (N, M, q, w) / S (K, 15); statics' scaled tip, driven-tendon and contact rows
        (``rod.closing``) at the last end, the tip's point mass taking m p_tt from N there, with
        the tendons' rest lengths ``lengths`` (None: the intervals' summed) and the candidates'
        gaps from the steps' ``starts``; each tendon's slack flag; and the contact.Candidates
        (None without a scene)."""
        last = jax.tree.map(lambda a: a[-1], ends)
        N_L = last.y.N + lay.plan.mass[-1] * _acceleration(self.c, last, self.history[1][:3])
        lengths = jnp.sum(ends.l, 0) if lengths is None else lengths
        touch = None
        if self.load.scene is not None:
            where = self.candidates
            tip_gap = self.load.scene.distances(last.y.p) - lay.plan.intervals.radius[-1]
            gaps = jnp.concatenate([starts.gap[0, where], tip_gap[None]])
            touch = contact.Candidates(self.forces(x), gaps, jnp.append(lay.h[where] == 0, False))
        y_L = last.y._replace(N=N_L)
        tail, slack = rod.closing(self.robot, self.actuation(x), self.load, lay.plan, y_L, lengths, self.F_c, touch, self.mu)
        y = jnp.concatenate([ends.y.N, ends.y.M, ends.q, ends.w], -1) / self.S[None]
        return jnp.concatenate([vee_skew(ends.y.R @ jnp.swapaxes(R_next, -1, -2)), y], -1), tail, slack, touch

    def residual(self, u: Unknowns):
        """Continuity at every interior start ((K - 1) 15, flattened), then the tip's (6,), the
        driven tendons' (n_d,) and the contact rows; and the ``Run`` there."""
        lay = self.layout(u.x)
        ends, nodes, z, starts = self.run(lay, *self.starts(u), u.x)
        cont, tail, slack, touch = self.closing(lay, u.x, ends, _next_rotations(u), starts=starts)
        found = None
        if touch is not None:
            where = self.candidates
            p = jnp.concatenate([starts.p[0, where], jnp.sum(ends.y.p, 0)[None]])
            s = jnp.append(lay.s0[where], self.robot.length)
            found = contact.outputs(self.load.scene, s, p, touch, self.F_c, self.robot.length)
        tensions = jnp.where(slack, 0.0, self.actuation(u.x).tensions)
        return _stacked(u, cont, tail), Run(ends, nodes, z, tensions, lay.P.tau, found)

    def linearize(self, u: Unknowns):
        """The residual and its Jacobian in (x, each interior's rotation (I + w^) R, then z): one
        forward pass perturbing every interval's start alike (each end depends on its own start
        only), the driven tensions and the contact forces, its blocks set into the dense matrix.
        The driven tendons' rows depend on every interval's start through the summed lengths:
        their blocks are d(row) / d(lengths) times each interval's d(l) / d(start). Contact
        (single shooting) takes the base wrench's columns of its rows as they come."""
        K, n_d = self.K, len(self.act.driven)
        R, y = self.starts(u)
        R_next = _next_rotations(u)
        base = slice(3, 9)  # the base wrench among a start's perturbations
        E = jnp.eye(N_START)[:, base] if K == 1 else jnp.eye(N_START)
        m = E.shape[1]

        def ends(w):
            v = E @ w[:m]
            x = u.x.at[6:].add(w[m:])
            lay = self.layout(x)
            run, _, _, starts = self.run(lay, R + hat(v[:3])[None] @ R, y + (v[3:] * self.S)[None], x)
            out = (*self.closing(lay, x, run, R_next, starts=starts)[:2], run.l)
            return out, (*out, lay, run, starts)

        n_e = self.n_extra
        (G, T, Gl), (cont, tail, l, lay, run, starts) = jax.jacfwd(ends, has_aux=True)(jnp.zeros(m + n_e))

        def columns(k):  # interval k's start unknowns: the base wrench for the first
            return slice(0, 6) if k == 0 else slice(6 + n_e + N_START * (k - 1), 6 + n_e + N_START * k)

        def own(k, block):  # d(interval k's end) / d(its start's unknowns)
            return block[..., :m][..., base] if k == 0 and K > 1 else block[..., :m]

        extra = slice(6, 6 + n_e)
        n = 6 + n_e + N_START * (K - 1)
        J = jnp.zeros((n, n))
        for k in range(K - 1):
            rows = slice(N_START * k, N_START * (k + 1))
            J = J.at[rows, columns(k)].set(own(k, G[k])).at[rows, columns(k + 1)].set(-jnp.eye(N_START))
            J = J.at[rows, extra].set(G[k][:, m:])
        tip = n - 6 - n_e
        J = J.at[tip:, extra].set(T[:, m:]).at[tip : tip + 6, columns(K - 1)].set(own(K - 1, T[:6]))
        if n_d:
            driven = slice(6, 6 + n_d)
            dl = jax.jacfwd(lambda lengths: self.closing(lay, u.x, run, R_next, lengths, starts)[1][driven])(jnp.sum(l, 0))
            for k in range(K):
                J = J.at[tip + 6 : tip + 6 + n_d, columns(k)].set(dl @ own(k, Gl[k]))
        if self.n_contact:  # single shooting: the base wrench moves every candidate
            J = J.at[tip + 6 + n_d :, columns(0)].set(T[6 + n_d :, :m])
        return _stacked(u, cont, tail), J


class Run(NamedTuple):
    """What ``Problem.residual`` integrated: the intervals' ends, nodes (K, n_steps / K + 1) and
    stage values; the tendon tensions (a slack driven tendon's exactly 0, as in statics); each
    RK4 step's (frictionless) span tensions (n_steps, n_t); with a scene the ``contact.Contact``
    at the candidates, else None."""

    ends: Dyn
    nodes: Dyn
    z: jax.Array
    tensions: jax.Array
    spans: jax.Array
    contact: contact.Contact | None


def _next_rotations(u: Unknowns):
    """Each interval's next start rotation (K, 3, 3); the last interval's (unused) I."""
    return jnp.concatenate([u.R, jnp.eye(3)[None]])


def _stacked(u: Unknowns, cont, tail):
    """The residual vector from ``Problem.closing``'s: each interior start's gap ((K - 1) 15),
    then the tip's and the driven tendons' rows (6 + n_d,)."""
    gap = cont[:-1] - jnp.concatenate([jnp.zeros((u.z.shape[0], 3)), u.z], -1)
    return jnp.concatenate([gap.reshape(-1), tail])


def _update(u: Unknowns, r, J, mu):
    """The next point of ``Problem.linearize``'s system: Newton's step while mu is at most
    ``newton.MU_START`` (every step so far lowered the residual), else Levenberg-Marquardt's in
    Marquardt's scale (the columns' norms differ a thousandfold between rotations and velocities,
    and the smallest singular values are far below MU_START); rotations move by the Cayley map."""
    JJ = J.T @ J
    damped = -jnp.linalg.solve(JJ + mu * jnp.diag(jnp.diag(JJ)), J.T @ r)
    return _move(u, jnp.where(mu <= newton.MU_START, -jnp.linalg.solve(J, r), damped))


def _move(u: Unknowns, d) -> Unknowns:
    """u moved by d in ``Problem.linearize``'s coordinates; rotations by the Cayley map."""
    n_x = u.x.size
    inner = d[n_x:].reshape(-1, N_START)
    return Unknowns(u.x + d[:n_x], cayley(inner[:, :3]) @ u.R, u.z + inner[:, 3:])


def _extrapolate(u: Unknowns, before: Unknowns, earlier: Unknowns, order) -> Unknowns:
    """The next step's guess from the last three roots, by a polynomial of ``order`` (0, 1 or 2,
    traced) in time in each unknown; a rotation by its last relative rotation D1 = R R_before^T
    (order 1: D1 R), and for order 2 turned on by that rotation's change, D1 D0^T D1 R with
    D0 = R_before R_earlier^T."""
    w = jnp.array([[1.0, 0.0, 0.0], [2.0, -1.0, 0.0], [3.0, -3.0, 1.0]])[order]

    def mixed(a, b, c):
        return w[0] * a + w[1] * b + w[2] * c

    def T(R):
        return jnp.swapaxes(R, -1, -2)

    D1, D0 = u.R @ T(before.R), before.R @ T(earlier.R)
    R = jnp.where(order == 2, D1 @ T(D0) @ D1 @ u.R, jnp.where(order == 1, D1 @ u.R, u.R))
    return Unknowns(mixed(u.x, before.x, earlier.x), jax.vmap(orthonormalize)(R), mixed(u.z, before.z, earlier.z))


def _at_rotations(v, R_ref) -> Unknowns:
    """The Unknowns of a vector (x, then each interior's Cayley vector of R R_ref^T and z): the
    coordinates in which ``lax.custom_root`` differentiates the root (``_vector`` the inverse at
    R = R_ref)."""
    n_x = v.size - N_START * R_ref.shape[0]
    return _move(Unknowns(jnp.zeros(n_x), R_ref, jnp.zeros((R_ref.shape[0], 12))), v)


def _vector(u: Unknowns):
    """u as ``_at_rotations``' vector with R_ref = u.R (every Cayley vector zero)."""
    return jnp.concatenate([u.x, jnp.concatenate([jnp.zeros((u.z.shape[0], 3)), u.z], -1).reshape(-1)])


class StepInfo(NamedTuple):
    iterations: jax.Array
    result: jax.Array
    residual_norm: jax.Array


def _newton(problem: Problem, u0: Unknowns, solver: SolverOptions):
    """``newton.damped`` (Levenberg-Marquardt, so that a sudden input does not throw the first
    iterate far off) on the problem, its steps judged by the natural level (a displacement
    row's residual is a gap of micrometres where a tension error of newtons makes it, beside
    force rows that a Newton step's second order can raise): the point, Newton steps and the
    status code."""
    u, r, _, steps, code = newton.damped(problem.linearize, _update, u0, solver.tol, solver.max_iter, natural=True)
    code = jnp.where(code == status.SUCCESS, code, jnp.where(jnp.all(jnp.isfinite(r)), status.NEWTON_LIMIT, status.NONFINITE))
    return u, jnp.asarray(steps, jnp.int32), code.astype(jnp.int32)


def _step(problem_at, guess: Unknowns, previous: Unknowns, solver: SolverOptions):
    """One time step's root, ``problem_at(lam, frozen, mu)`` its Problem with the step's change of
    inputs scaled by lam (1: the step's own), its inputs without derivatives where ``frozen``,
    its contact rows smoothed by mu.

    First up to CHORD_STEPS chord steps from ``guess`` with the Jacobian there, each checked by a
    primal pass (a Jacobian pass costs about four), while each shortens the chord correction
    (the natural level |J^-1 r|, as in ``_newton``): where they
    reach the tolerance, the step is done. Else Newton (``_newton``) from the best point; where it
    fails and there is contact, the smoothed complementarity from the guess, mu decreasing
    (``contact.SMOOTHING``, as statics), then the exact one, each from the last point; then load
    continuation as in statics from the last step's root ``previous``: ``solver.stages`` ramps of equal stages in turn, each stage
    from the last one's root. That search runs without derivatives; its root then passes
    ``lax.custom_root`` at the full inputs, so derivatives of anything downstream go through each
    step's implicit solve, by the Jacobian at the root (``Problem.linearize``: in
    ``_at_rotations``' coordinates there, a rotation's (I + w^) R is cay(w) R to first order).

    Returns the root, the StepInfo (chord and Newton steps and the code of the search, the
    residual of the run at the root: the same to rounding) and that run (ends, nodes, stage
    values, tensions, span tensions, contact: ``Problem.residual``'s ``Run``)."""
    guess, previous = lax.stop_gradient((guess, previous))
    full = problem_at(1.0, frozen=True)
    r, J = full.linearize(guess)
    factors = jax.scipy.linalg.lu_factor(J)

    def chord(state):
        u, r, d, k, _ = state
        u_new = _move(u, -d)
        r_new = full.residual(u_new)[0]
        d_new = jax.scipy.linalg.lu_solve(factors, r_new)
        lower = jnp.all(jnp.isfinite(r_new)) & (jnp.sum(d_new**2) < jnp.sum(d**2))
        return (*jax.tree.map(lambda a, b: jnp.where(lower, a, b), (u_new, r_new, d_new), (u, r, d)), k + 1, lower)

    def chording(state):
        _, r, _, k, lower = state
        return lower & (k < CHORD_STEPS) & (jnp.max(jnp.abs(r)) > solver.tol)

    begin = (guess, r, jax.scipy.linalg.lu_solve(factors, r), jnp.int32(0), jnp.bool_(True))
    guess, r, _, chords, _ = lax.while_loop(chording, chord, begin)

    # each attempt's (mu, ramp stages, start: 0 the guess, 1 the last step's root, 2 the last attempt's point)
    plan = [(0.0, solver.stages[0], 0)]
    if full.load.scene is not None:
        plan += [(mu, 1, 2 if j else 0) for j, mu in enumerate((*contact.SMOOTHING, 0.0))]
    plan += [(0.0, k, 1) for k in solver.stages[1:]]
    mus, ramps, starts = (np.array(column) for column in zip(*plan, strict=True))

    def attempt(state):
        a, last, iterations, _ = state
        mu, k = jnp.asarray(mus)[a], jnp.asarray(ramps)[a]

        def stage(j, carry):
            u, its, code = carry
            u_new, steps, code_new = _newton(problem_at((j + 1) / k, frozen=True, mu=mu), u, solver)
            ok = code == status.SUCCESS
            return jax.tree.map(lambda n, o: jnp.where(ok, n, o), u_new, u), its + steps, jnp.where(ok, code_new, code)

        start = jax.tree.map(lambda *c: jnp.asarray(c)[jnp.asarray(starts)[a]], guess, previous, last)
        u, its, code = lax.fori_loop(0, k, stage, (start, jnp.int32(0), jnp.int32(status.SUCCESS)))
        u = jax.tree.map(lambda n, o: jnp.where(jnp.all(jnp.isfinite(u.x)), n, o), u, start)
        code = jnp.where((mu > 0) & (code == status.SUCCESS), status.NEWTON_LIMIT, code)  # smoothed: not the root
        return a + 1, u, iterations + its, code

    def more(state):
        a, *_, code = state
        return (code != status.SUCCESS) & (a < len(plan))

    done = jnp.max(jnp.abs(r)) <= solver.tol
    first = (jnp.int32(0), guess, chords, jnp.where(done, status.SUCCESS, status.NEWTON_LIMIT).astype(jnp.int32))
    _, found, iterations, code = lax.while_loop(more, attempt, first)

    problem = problem_at(1.0)
    R_ref = found.R

    def residual(v):
        return problem.residual(_at_rotations(v, R_ref))[0]

    def tangent_solve(g, y):
        return jnp.linalg.solve(full.linearize(found)[1], y)

    u = _at_rotations(lax.custom_root(residual, _vector(found), lambda f, v: v, tangent_solve), R_ref)
    r, out = problem.residual(u)
    norm = lax.stop_gradient(jnp.max(jnp.abs(r)))
    return u, StepInfo(iterations, code, norm), out


@pytree
class Trajectory:
    """The robot along time (``simulate``), SI units, world frame.

    Attributes:
        t: times [s], (n,), the first the start.
        s: arc length of each node [m], (n, m): ``steps`` nodes per breakpoint interval, and the
            tip (the nodes move where a tube's end does).
        position: p(s, t) [m], (n, m, 3). rotation: R(s, t), (n, m, 3, 3).
        force, moment: the total internal force N [N] and moment M [N m] of rod plus tendons
            (at s = 0 the load on the base), (n, m, 3).
        velocity: p_t [m/s] and angular_velocity: R w [rad/s], (n, m, 3).
        tensions: the tendon tensions [N], (n, n_t): the given ones and those found for
            displacement-driven tendons (slack: 0).
        tendon_tension: each tendon's tension at every node [N], (n, m, n_t): that of the span
            starting there (the tip: the last span's), zero beyond its anchor; with tendon
            friction it falls or rises along the tendon (``Solution.tendon_tension`` of statics).
        displacements: what each tendon's encoder reads [m], (n, n_t): its rest length inside
            the straight robot less its present one (``rod.displacements``).
        insertions: each tube's depth [m], (n, n_tubes).
        contact_force: with a scene, each contact candidate's normal force against each obstacle
            [N], (n, n_c, n_o), exactly 0 where not touching: candidates at every
            ``scene.every``-th node from the base (``s[:, every::every]``) and the tip; (n, 0, 0)
            without a scene.
        contact_gap: the body surface's distance to each obstacle there [m], (n, n_c, n_o).
        iterations: chord and Newton steps of each time step (n,) (``_step``), 0 at the start.
        result: each time step's status code (n,) (``tdct_jax.status``), SUCCESS (0) when its
            scaled residual reached ``solver.tol``.
        residual_norm: each time step's scaled residual, max norm (n,).
    """

    t: jax.Array
    s: jax.Array
    position: jax.Array
    rotation: jax.Array
    force: jax.Array
    moment: jax.Array
    velocity: jax.Array
    angular_velocity: jax.Array
    tensions: jax.Array
    tendon_tension: jax.Array
    displacements: jax.Array
    insertions: jax.Array
    contact_force: jax.Array
    contact_gap: jax.Array
    iterations: jax.Array
    result: jax.Array
    residual_norm: jax.Array

    @property
    def converged(self):
        """Every time step converged."""
        return jnp.all(self.result == status.SUCCESS)

    @property
    def tip_position(self):
        """p(L, t) [m], (n, 3)."""
        return self.position[..., -1, :]


def _inputs(robot: Robot, load: Loads, driven: tuple, given: dict, n: int | None):
    """The per-time inputs (tensions, the driven tendons' displacements, tip force and moment,
    the point loads' forces and moments, the tube depths) as arrays with a leading time axis of n rows (constants
    broadcast along time), and n; a point load's None is ``load``'s own."""
    k = np.size(load.point_s)
    shapes = {
        "tensions": ((robot.n_tendons,), " N", None),
        "displacements": ((len(driven),), " m", None),
        "tip_force": ((3,), " N", None),
        "tip_moment": ((3,), " N m", None),
        "point_force": ((k, 3), " N", load.point_force),
        "point_moment": ((k, 3), " N m", load.point_moment),
        "insertions": ((robot.n_tubes,), " m", None),
    }
    rows = {}
    for name, (shape, unit, own) in shapes.items():
        x = given[name]
        x = (jnp.zeros(shape) if own is None else own) if x is None else as_array(name, x, unit=unit)
        if np.ndim(x) not in (len(shape), len(shape) + 1) or np.shape(x)[np.ndim(x) - len(shape) :] != shape:
            where = f" ({k} point loads at load.point_s)" if name.startswith("point") else ""
            raise ValueError(f"{name} has shape {np.shape(x)}: {shape} or (times, {', '.join(map(str, shape))}) expected{where}")
        rows[name] = x
    lengths = {name: np.shape(x)[0] for name, x in rows.items() if np.ndim(x) > len(shapes[name][0])}
    if n is None:
        if not lengths:
            raise ValueError("steps: give the number of time steps, or inputs with a time axis")
        n = max(lengths.values())
    for name, m in lengths.items():
        if m != n:
            raise ValueError(f"{name} has {m} rows: one per time, {n} (steps + 1: row 0 is the start)")
    check_range("tensions", rows["tensions"], 0.0, unit=" N")
    return [jnp.broadcast_to(x, (n, *shapes[name][0])) for name, x in rows.items()], n


def check(robot: Robot, act: Actuation, load: Loads, solver: SolverOptions) -> None:
    """What ``simulate`` does not handle, refused by name; statics' checks of robot and inputs
    together (``act``: the driven tendons' largest displacements)."""
    if solver.transition != "balanced" or solver.tendon_model != "exact":
        raise ValueError("solver: simulate uses the 'balanced' transition and 'exact' tendons")
    rod.check_arguments(robot, act, load, solver)
    rod.check_intervals(robot, load, solver)


def simulate(
    robot: Robot,
    dt: float,
    steps: int | None = None,
    *,
    tensions=None,
    displacements=None,
    driven: tuple = (),
    tip_force=None,
    tip_moment=None,
    point_force=None,
    point_moment=None,
    insertions=None,
    load: Loads | None = None,
    scene=None,
    start: str = "static",
    alpha: float = ALPHA,
    gravity=STANDARD_GRAVITY,
    solver: SolverOptions | None = None,
    throw: bool = True,
    checkpoint: bool = False,
) -> Trajectory:
    """The robot's motion under time-varying tendon tensions or displacements and loads (module
    docstring).

    Args:
        robot: any robot of the description; ``Section.damping`` sets material damping.
        dt: time step [s].
        steps: number of time steps; None: the inputs' time axis (its length less one: row 0 is
            the start).
        tensions: tendon tensions [N], (n_t,) for all times or (steps + 1, n_t), row i at t = i dt;
            a displacement-driven tendon's are not used.
        displacements: the driven tendons' displacements [m] (the length pulled at the base, as
            ``Actuation.displacements``), (n_d,) or (steps + 1, n_d); their tensions are found at
            each step, 0 where the tendon goes slack (statics' complementarity row).
        driven: indices of the displacement-driven tendons, 0 for tendon 1.
        tip_force, tip_moment: world-frame tip load [N], [N m], (3,) or (steps + 1, 3).
        point_force, point_moment: world-frame forces [N] and moments [N m] of ``load``'s k point
            loads (at ``load.point_s``, fixed), (k, 3) or (steps + 1, k, 3): e.g. held at the start
            and then removed; None: ``load``'s own, constant.
        insertions: tube depths [m], (n_tubes,) for all times or (steps + 1, n_tubes): a tube
            pushed in or drawn back along time (its end a moving breakpoint: the history is
            carried to the new stage points in the material coordinate, ``remap``; the tube's own
            axial inertia is neglected, docs/dynamics.md).
        load: distributed force and point loads (``Loads``; its tip load is replaced by
            ``tip_force`` and ``tip_moment``, its point loads' values by ``point_force`` and
            ``point_moment`` where given).
        scene: obstacles the robot may touch (a ``tdct.Scene``, fixed in space): statics'
            frictionless contact rows at each step, single shooting (docs/dynamics.md).
        start: "static": at rest in the static equilibrium of the inputs' first row; "straight":
            the straight, unstrained robot at rest.
        alpha: BDF-alpha parameter in [-0.5, 0] (module docstring).
        gravity: world gravity [m/s^2].
        solver: RK4 steps per breakpoint interval, shooting intervals, Newton's tolerance and
            limit per time step; None: ``default_solver`` (four intervals where they divide).
        throw: raise ``ConvergenceError`` when a time step does not converge (naming it); else
            check ``Trajectory.result``.
        checkpoint: under reverse mode (``jax.grad``), keep only each step's carry and run the
            step again on the way back (``jax.checkpoint``): memory of a long trajectory's
            gradient for about one more forward pass (benchmarks/dynamics_derivatives.py).

    Returns:
        Trajectory at the times 0, dt, ..., steps dt.
    """
    load = Loads() if load is None else load
    for name, obj, cls in (("robot", robot, Robot), ("load", load, Loads), ("solver", solver, SolverOptions)):
        if not isinstance(obj, cls) and not (name == "solver" and obj is None):
            raise TypeError(f"{name} must be a tdct.{cls.__name__}, got {type(obj).__name__}")
    if scene is not None:
        load = load.with_scene(scene)
    solver = default_solver(robot, load) if solver is None else solver
    if scene is not None:
        load = with_scene(robot, load, scene, solver)
    if start not in ("static", "straight"):
        raise ValueError(f"start = {start!r}: 'static' or 'straight'")
    dt = as_array("dt", dt, (), unit=" s")
    check_range("dt", dt, 0.0, lo_open=True, unit=" s")
    check_range("alpha", alpha, -0.5, 0.0)
    if steps is not None:
        steps = int(steps)
        check_range("steps", steps, 1)
    driven = tuple(int(i) for i in driven)
    given = {"tensions": tensions, "displacements": displacements, "tip_force": tip_force, "tip_moment": tip_moment}
    given |= {"point_force": point_force, "point_moment": point_moment, "insertions": insertions}
    rows, n = _inputs(robot, load, driven, given, None if steps is None else steps + 1)
    T, D, F, C, PF, PM, I = rows
    moving = np.ndim(insertions) == 2
    if moving and robot.has_friction:
        raise ValueError(
            "insertions along time with tendon friction: not simulated yet (the tension profiles are not carried with the moving nodes); hold the tubes still"
        )
    act = Actuation(T[0], I[0], D[0], driven)
    check(robot, Actuation(T[0], I[0], jnp.max(D, 0), driven), load, solver)
    if moving and is_concrete(robot.length) and is_concrete(I):
        L = float(robot.length)
        for i in np.flatnonzero(np.any((np.asarray(I) < 0) | (np.asarray(I) > L), axis=1))[:1]:
            check_range(f"insertions[{i}] (t = {i * float(dt):g} s)", I[i], 0.0, L, unit=f" m (0 to the robot length {L:g} m)")
    g = gravity_vector(gravity)
    base = jnp.concatenate(
        [
            F[0],
            C[0] + jnp.cross(robot.length * E3, F[0]),
            T[0, np.asarray(driven, int)],
            jnp.zeros(_n_contact(robot, load, solver.steps)),
        ]
    )  # the tip load carried to the base, contact free
    if start == "static":  # the static solver's load continuation finds the start
        held = load._with(point_force=PF[0], point_moment=PM[0]).with_tip(F[0], C[0])
        found = solve(robot, act, held, gravity=g, solver=solver, throw=throw)
        pressed = jnp.zeros(0) if scene is None else found.contact.force.reshape(-1)
        base = jnp.concatenate([found.base_wrench, found.tensions[np.asarray(driven, int)], pressed])
    out = _simulate(robot, act, load, rows, dt, alpha, g, base, solver, start == "static", moving, checkpoint)
    if throw and is_concrete(out.result):
        failed = np.flatnonzero(np.asarray(out.result) != status.SUCCESS)
        if failed.size:
            i = int(failed[0])
            context = dict(max_iter=solver.max_iter, tol=solver.tol, stages=max(solver.stages))
            context |= dict(residual_norm=float(out.residual_norm[i]), iterations=int(out.iterations[i]))
            advice = "Try more solver.intervals (multiple shooting), a ramped input or more solver.max_iter"
            raise status.ConvergenceError(
                f"simulate: time step {i} (t = {float(out.t[i]):g} s) did not converge: "
                f"{status.message(int(out.result[i]), raise_max_iter=advice, **context)}",
                int(out.result[i]),
            )
    return out


@jax.jit(static_argnames=("solver", "static_start", "moving", "checkpoint"))
def _simulate(robot, act, load, rows, dt, alpha, gravity, base, solver, static_start, moving, checkpoint):
    """``simulate``'s compiled part: one scan over the time rows, each an implicit step (the first,
    with ``static_start``, the static root: every coefficient zero), so that the root and the
    sweep are compiled once; ``act``: the driven tendons; with ``moving`` (tube depths that change
    in time) each step's history is first carried to its own stage points (``remap``); ``base``: the base
    wrench (N(0), M(0)) and driven tensions the first Newton starts from, the interior starts
    (multiple shooting) from one static pass from it. The roots pass from step to step in
    physical units (``Unknowns.physical``)."""
    K = solver.intervals
    n_nodes = rod.n_intervals(robot, load) * solver.steps
    c = scheme(dt, alpha)
    L = robot.length
    T = rows[0]

    def inputs(i, lam=1.0):
        """Row i's inputs, or with lam < 1 those of row i - 1 moved lam of the way to row i."""
        j = jnp.maximum(i - 1, 0)
        T_i, D_i, F_i, C_i, PF_i, PM_i, I_i = (a[j] + lam * (a[i] - a[j]) for a in rows)
        ld = load._with(point_force=PF_i, point_moment=PM_i).with_tip(F_i, C_i)
        return Actuation._rebuild(T_i, I_i, D_i, act.driven), ld

    def breakpoints(robot, act_i, ld):
        return rod.plan(robot, act_i, ld, gravity).b

    def problem(i, c_i, history, b_old, memory, lam=1.0, frozen=False, mu=0.0):
        """Row i's Problem; ``history`` at the stage points of breakpoints ``b_old`` (the last step's)."""
        act_i, ld = inputs(i, lam)
        parts = (robot, act_i, ld, gravity, c_i, history, b_old, memory)
        robot_, act_i, ld, gravity_, c_i, history, b_old, memory = lax.stop_gradient(parts) if frozen else parts
        if moving:
            history = (remap(history[0], b_old, breakpoints(robot_, act_i, ld), solver.steps), history[1])
        F_c = rod.force_scale(robot_, act_i, ld, gravity_)
        return Problem(robot_, act_i, ld, gravity_, c_i, history, memory, F_c, _scale(F_c, L, dt), K, solver.steps, mu)

    def advance(carry, i):
        (u, before, earlier), z1, z2, zt1, b_old, memory = carry
        ci = jax.tree.map(lambda a: jnp.where(i == 0, 0.0, a), c)
        history = jax.tree.map(lambda a, b, d: ci.c1 * a + ci.c2 * b + ci.d1 * d, z1, z2, zt1)
        at = problem(i, ci, history, b_old, memory)
        b = breakpoints(robot, *inputs(i)) if moving else b_old
        guess = _extrapolate(u, before, earlier, jnp.clip(i - 1, 0, 2))
        guess, previous = (v.scaled(at.F_c, at.S) for v in (guess, u))
        root, info, (ends, nodes, z, tensions, spans, touch) = _step(
            lambda lam, frozen=False, mu=0.0: problem(i, ci, history, b_old, memory, lam, frozen, mu), guess, previous, solver
        )
        offsets = jnp.cumsum(ends.y.p, 0) - ends.y.p  # each interval ran from p = 0 and l = 0
        lengths = jnp.cumsum(ends.l, 0) - ends.l
        nodes = nodes._replace(y=nodes.y._replace(p=nodes.y.p + offsets[:, None]), l=nodes.l + lengths[:, None])
        nodes = jax.tree.map(lambda a: jnp.concatenate([a[:, :-1].reshape(-1, *a.shape[2:]), a[-1, -1:]]), nodes)
        if nodes.f is not None:  # node j's tension: span j's (the tip's: the last span's, as in statics)
            spans = nodes.f.tau[:-1]
            memory = jnp.concatenate([spans[1:], spans[-1:]])
        z = (z.reshape(n_nodes, 4, 12), jnp.concatenate([ends.q[-1], ends.w[-1]]))
        zt = jax.tree.map(lambda a, b: ci.c0 * a + b, z, at.history)
        if moving:
            z1 = (remap(z1[0], b_old, b, solver.steps), z1[1])
        older = jax.tree.map(lambda a, b: jnp.where(i == 0, a, b), z, z1)  # the next step's z(t - 2 dt)
        profile = jnp.concatenate([spans, spans[-1:]])
        pressed = (jnp.zeros((0, 0)),) * 2 if touch is None else (touch.force, touch.gap)
        out = (nodes, tensions, profile, pressed, info, b)
        return ((root.physical(at.F_c, at.S), u, before), z, older, zt, b, memory), out

    act0, load0 = inputs(0)
    rest = (jnp.zeros((n_nodes, 4, 12)), jnp.zeros(6))
    lay0 = layout(robot, rod.with_driven(act0, base, 1.0), load0, gravity, solver.steps)
    zeros = jnp.zeros(3)
    at_base = Dyn(State(zeros, jnp.eye(3), base[:3], base[3:6]), zeros, zeros, jnp.zeros(robot.n_tendons))
    y = _integrate(robot, load0, gravity, lay0._replace(plan=None), STATIC, rest[0], at_base)[1]
    inner = jax.tree.map(lambda a: a[n_nodes // K : n_nodes : n_nodes // K], y)
    u0 = Unknowns(base.at[3:6].divide(L), inner.y.R, jnp.concatenate([inner.y.N, inner.y.M, inner.q, inner.w], -1))
    # the first step's span tensions: loaded from slack
    slack = jnp.zeros((n_nodes, robot.n_tendons)) if robot.has_friction else None
    start = ((u0, u0, u0), rest, rest, jax.tree.map(jnp.zeros_like, rest), lay0.plan.b, slack)
    step = jax.checkpoint(advance) if checkpoint else advance
    _, (nodes, tensions, profile, pressed, info, b) = lax.scan(step, start, jnp.arange(0 if static_start else 1, T.shape[0]))
    s = jax.vmap(lambda b: jnp.concatenate([_points(b, solver.steps).reshape(-1), b[-1:]]))(b)
    displacements = jax.vmap(lambda l: rod.displacements(robot, l))(nodes.l[:, -1])
    if not static_start:  # the straight, unstrained robot at rest
        s0 = jnp.concatenate([lay0.s0, L[None]])
        n = s0.size
        zeros = jnp.zeros((n, 3))
        straight = Dyn(State(s0[:, None] * E3[None], jnp.broadcast_to(jnp.eye(3), (n, 3, 3)), zeros, zeros), zeros, zeros, None)
        nodes = jax.tree.map(lambda a, b: jnp.concatenate([a[None], b]), straight, nodes._replace(l=None, f=None))
        s = jnp.concatenate([s0[None], s])
        profile = jnp.concatenate([jnp.concatenate([lay0.P.tau, lay0.P.tau[-1:]])[None], profile])
        if load.scene is not None:
            inner = _candidates(robot, load, solver.steps)
            radius = jnp.append(lay0.P.radius[inner], lay0.plan.intervals.radius[-1])
            gap = jax.vmap(load.scene.distances)(s0[np.append(inner, n - 1), None] * E3[None]) - radius[:, None]
            pressed = tuple(jnp.concatenate([a[None], b]) for a, b in zip((jnp.zeros_like(gap), gap), pressed, strict=True))
        else:
            pressed = tuple(jnp.zeros((T.shape[0], 0, 0)) for _ in range(2))
        tensions = jnp.concatenate([T[:1], tensions])
        displacements = jnp.concatenate([jnp.zeros((1, robot.n_tendons)), displacements])
        first = StepInfo(jnp.int32(0), jnp.int32(status.SUCCESS), jnp.zeros(()))
        info = jax.tree.map(lambda a, b: jnp.concatenate([a[None], b]), first, info)
    y = nodes.y
    return Trajectory(
        jnp.arange(T.shape[0]) * dt,
        s,
        y.p,
        y.R,
        y.N,
        y.M,
        jnp.einsum("...ij,...j->...i", y.R, nodes.q),
        jnp.einsum("...ij,...j->...i", y.R, nodes.w),
        tensions,
        profile,
        displacements,
        rows[6],
        *pressed,
        info.iterations,
        info.result,
        info.residual_norm,
    )


@pytree
class Motion:
    """A recorded motion to fit (``fit_motion``): the inputs at each time row (row 0: the start,
    t = 0) and the measured tip positions there, SI units.

    Attributes:
        dt: time step [s]. tensions: (n, n_t) [N]. tip: measured tip positions (n, 3) [m], world
            frame; rows that are NaN are not fitted. tip_force: (n, 3) [N], or None (none).
    """

    dt: float
    tensions: jax.Array
    tip: jax.Array
    tip_force: jax.Array | None = None


class MotionFit(NamedTuple):
    """``fit_motion``'s result: the fitted values by field name, their standard errors (the
    Gauss-Newton covariance, delta method from the log coordinates) and correlation, the robot
    with them, the tip RMSE [m] before and after, and Levenberg-Marquardt's outcome."""

    values: dict
    std_errors: dict
    correlation: np.ndarray
    robot: Robot
    rmse_before: float
    rmse_after: float
    iterations: int
    converged: bool
    message: str


def fit_motion(robot: Robot, motion: Motion, params=("sections[*].E", "sections[*].damping"), *, max_steps: int = 20, **options):
    """Fits positive robot fields (default: the modulus and the damping of every section) to a
    recorded motion by Levenberg-Marquardt on the tip residuals, with their exact Jacobian
    through the whole simulation (``jax.jacfwd`` in the log of each value). ``options`` go to
    ``simulate`` (start, alpha, gravity, solver), which checks the inputs when the fit's program
    is traced; the start values are the robot's."""
    from . import fields, lm

    params = tuple(params)
    for p in params:
        fields.check(robot, p)
    start = np.array([fields.value(robot, p) for p in params], float)
    if np.any(start <= 0):
        raise ValueError(
            f"fit_motion: start values {dict(zip(params, start.tolist(), strict=True))} must be positive (fitted in log)"
        )
    measured = np.asarray(motion.tip, float)
    used = np.all(np.isfinite(measured), axis=1)

    @jax.jit
    def residual_and_jacobian(x):
        def tips(x):
            fitted = fields.replace(robot, {p: jnp.exp(x[i]) for i, p in enumerate(params)})
            traj = simulate(fitted, motion.dt, tensions=motion.tensions, tip_force=motion.tip_force, throw=False, **options)
            r = (traj.tip_position[used] - measured[used]).ravel()
            return r, (r, jnp.max(traj.result))

        J, (r, code) = jax.jacfwd(tips, has_aux=True)(x)
        return r, J, code

    first = []  # the start's residual, from Levenberg-Marquardt's first evaluation

    def evaluate(x):
        r, J, code = residual_and_jacobian(jnp.asarray(x))
        first[:] = first or [np.asarray(r)]
        return np.asarray(r), np.asarray(J), int(code), None

    fit = lm.levenberg_marquardt(evaluate, np.log(start), max_steps=max_steps)
    r0 = first[0]
    _, se, corr, _ = lm.covariance(fit, fit.residual.size)
    values = {p: float(np.exp(fit.x[i])) for i, p in enumerate(params)}
    return MotionFit(
        values,
        {p: float(values[p] * se[i]) for i, p in enumerate(params)},
        corr,
        fields.replace(robot, values),
        float(np.sqrt(np.mean(r0**2) * 3)),
        float(np.sqrt(np.mean(fit.residual**2) * 3)),
        fit.iterations,
        fit.converged,
        fit.message,
    )
