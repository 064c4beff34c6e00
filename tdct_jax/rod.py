"""A robot's breakpoint intervals: the integration plan, the integration across them, the shooting
residual and the node quantities (docs/model.md).

The state is segments.py's (p, R, N, M), N and M the *total* force and moment of rod plus tendons.
Along s the segment parameters change only at breakpoints:

    {0, L} + interior section ends + tube depths + tendon anchors + point-mass and point-load
    locations

Their number is static, their values traced (differentiable); they are sorted at run time. The
robot's own ones that coincide when it is built (an anchor at a section end, a mass on it) count
once (``Robot.merged``). Each
interval [b_k, b_k+1] gets ``solver.steps`` RK4 steps (a zero-length interval returns its state)
and one set of segment parameters, those at its midpoint: section stiffness K_se, K_bt (plus the
tubes inside), linear density, backbone flag (some tube inside: no shear, eq. 16), and each
tendon's tension, masked to zero beyond its anchor. With total N, M an anchor needs no jump: the
tendon simply leaves the cross-section and the rod's own n, m change by its Rucker-Webster point
force and moment, which the constitutive solve gives by itself. Section and tube ends are the
"balanced" transition: the state is continuous. A point force F and moment C at s_p (a point mass:
F = m g) give N(s_p+) = N(s_p-) - F, M(s_p+) = M(s_p-) - C, applied at the start of the interval
that begins at s_p (or, at s_p = L, before the tip condition N(L) = F_e, M(L) = M_e).

Helical tendons: r_t(s) turns with the twist rate, so the tendon tangent is pb_t = u x r_t + r_t' + v;
s rides in the state (s' = 1) so that every RK4 stage sees its own r_t(s). Where no tendon has a
twist (``Tendon.twist`` None, static) r_t is constant and s is not carried.

The paper's printed variants (``SolverOptions``: transition "paper", tendon_model "paper") act
where the first tube is inside and at its end (``Paper``).

Multiple shooting (multiple.py) cuts the same RK4 steps into K intervals of equal step count
(``pieces``), each integrated from its own start by ``integrate``.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from . import contact
from .checks import check_range, is_concrete
from .description import Robot, channelled_second_moments, is_concrete_tree, own_breakpoints, section_area
from .inputs import Actuation, Loads
from .integrate import coupled, rk4
from .segments import (
    E3,
    Segment,
    State,
    carried,
    paper_transition,
    printed_moment,
    rod_force,
    strains,
    strains_at,
    tendon_pb,
    tendon_tangents,
    uncarried,
)


class Interval(NamedTuple):
    """Segment parameters of one interval (a leading axis over intervals in ``Plan``).

    K_se (3,) [N], K_bt (3,) [N m^2], rho [kg/m], backbone (1.0: a tube inside), tau (n_t,) [N]
    (zero beyond each anchor), present (n_t,) (1.0 before each anchor), radius: the body's outer
    radius [m] (contact gaps), mu: the section's tendon friction coefficient (0 without one),
    spacing: its guide spacing [m] (0: a continuous channel), rhoJ (3,): the rotational inertia
    per length [kg m] (density x second moments, body x, y, z), damping: the section's
    Kelvin-Voigt retardation time [s] (dynamics.py)."""

    K_se: jax.Array
    K_bt: jax.Array
    rho: jax.Array
    backbone: jax.Array
    tau: jax.Array
    present: jax.Array
    radius: jax.Array
    mu: jax.Array
    spacing: jax.Array
    rhoJ: jax.Array
    damping: jax.Array


class Plan(NamedTuple):
    """The integration plan: sorted breakpoints b (K + 1,), the intervals' parameters (K, ...), the
    jump (dN, dM) applied at each breakpoint (K + 1, 3) each, the index of the interval that
    starts where the first tube ends (the paper's transition applies there; -1 without a tube),
    and the point mass at each breakpoint (K + 1,) [kg] (their weight is in dN; dynamics.py adds
    their inertia)."""

    b: jax.Array
    intervals: Interval
    dN: jax.Array
    dM: jax.Array
    tube_end: jax.Array
    mass: jax.Array


def _tendon_fields(robot: Robot):
    """Stacked tendon routing: offsets, base angles, twist rates, (n_t,) each."""
    if not robot.tendons:
        return [jnp.zeros(0)] * 3
    twist = [0.0 if t.twist is None else t.twist for t in robot.tendons]
    return [jnp.stack([jnp.asarray(getattr(t, k), float) for t in robot.tendons]) for k in ("offset", "angle")] + [
        jnp.stack([jnp.asarray(x, float) for x in twist])
    ]


def is_helical(robot: Robot) -> bool:
    """Some tendon has a twist rate (static): r_t depends on s."""
    return any(t.twist is not None for t in robot.tendons)


def tendon_positions(robot: Robot, s):
    """r_t(s) and r_t'(s) of every tendon, body frame, (n_t, 3) each (Tendon.position); r_t' is
    None for a robot without helical tendons."""
    offset, angle, twist = _tendon_fields(robot)
    if not is_helical(robot):
        a = angle
        return offset[:, None] * jnp.stack([jnp.cos(a), jnp.sin(a), jnp.zeros_like(a)], axis=-1), None
    a = angle + twist * s
    c, sn = jnp.cos(a), jnp.sin(a)
    r = offset[:, None] * jnp.stack([c, sn, jnp.zeros_like(a)], axis=-1)
    dr = (offset * twist)[:, None] * jnp.stack([-sn, c, jnp.zeros_like(a)], axis=-1)
    return r, dr


def _anchors(robot: Robot):
    """Anchor arc lengths (n_t,), the tip's for tendons anchored there."""
    return jnp.stack([robot.length if t.end is None else t.end for t in robot.tendons]) if robot.tendons else jnp.zeros(0)


def _section_ends(robot: Robot):
    """Interior section ends (n_sections - 1,): the last section ends at ``robot.length``."""
    return jnp.stack([s.end for s in robot.sections[:-1]]) if len(robot.sections) > 1 else jnp.zeros(0)


def interval_parameters(robot: Robot, act: Actuation, k, rank: Ranks, s):
    """K_se (3,), K_bt (3,), linear density, backbone flag and masked tensions of interval k
    (eqs. 6-7, 14-16, 29-30). Which section, tubes and tendons it holds follows from the sorted
    order of the breakpoints (``rank``: each breakpoint's position), not from comparing arc
    lengths, so that a zero-length interval gets the parameters of the interval it becomes when
    its ends move apart (e.g. the tube's at d = 0: derivatives in d are then the right-hand ones).
    ``s`` (the midpoint) only sets the angle of helical tendons' channels."""
    idx = jnp.sum(rank.section_ends <= k)
    present = (rank.anchors > k) if robot.tendons else jnp.zeros(0, bool)
    anchors = _anchors(robot)
    starts = [0.0, *(sec.end for sec in robot.sections[:-1])]
    r, _ = tendon_positions(robot, s)
    props = []
    for start, sec in zip(starts, robot.sections, strict=True):
        through = (start < anchors).astype(float)  # tendons whose channels cut this section
        A = section_area(sec, jnp.sum(through))
        I_x, I_y = channelled_second_moments(sec.outer_diameter, sec.inner_diameter, sec.tendon_channel_diameter, r, through)
        G = sec.E / (2 * (1 + sec.nu))
        mu = 0.0 if sec.friction is None else sec.friction
        props.append(
            jnp.stack(
                [G * A, G * A, sec.E * A, sec.E * I_x, sec.E * I_y, G * (I_x + I_y), sec.density * A, sec.outer_diameter / 2]
                + [jnp.asarray(mu, float), jnp.asarray(sec.guide_spacing, float)]
                + [sec.density * I_x, sec.density * I_y, sec.density * (I_x + I_y), jnp.asarray(sec.damping, float)]
            )
        )
    p = jnp.stack(props)[idx]
    if robot.tubes:
        inside = rank.tubes > k
        EI = jnp.sum(jnp.where(inside, jnp.stack([t.E * t.second_moment for t in robot.tubes]), 0.0))
        rho_t = jnp.sum(jnp.where(inside, jnp.stack([t.density * t.area for t in robot.tubes]), 0.0))
        rhoI = jnp.sum(jnp.where(inside, jnp.stack([t.density * t.second_moment for t in robot.tubes]), 0.0))
        backbone = jnp.any(inside).astype(float)
    else:
        EI = rho_t = rhoI = backbone = jnp.zeros(())
    tau = jnp.where(present, jnp.asarray(act.tensions, float), 0.0)
    K_bt = jnp.stack([p[3] + EI, p[4] + EI, p[5]])
    rhoJ = p[10:13] + rhoI * jnp.array([1.0, 1.0, 2.0])
    return Interval(p[:3], K_bt, p[6] + rho_t, backbone, tau, present.astype(float), p[7], p[8], p[9], rhoJ, p[13])


class Ranks(NamedTuple):
    """Positions in the sorted breakpoints of the interior section ends, the tube depths and the
    tendon anchors (tendons anchored at the tip: a position past every interval)."""

    section_ends: jax.Array
    tubes: jax.Array
    anchors: jax.Array


def _groups(robot: Robot) -> tuple:
    """Each of ``own_breakpoints`` by the index of its group's first member (``Robot.merged``)."""
    return robot.merged or tuple(range(len(own_breakpoints(robot))))


def plan(robot: Robot, act: Actuation, load: Loads, gravity) -> Plan:
    """Breakpoints, sorted, with each interval's parameters and each breakpoint's jump.

    The robot's own breakpoints (``own_breakpoints``) come one per group of coincident ones
    (``Robot.merged``): at the group's first member, moved by the mean of its members' tangents,
    its jump their sum. The unsorted breakpoints are, in this order: the base, the groups led by
    interior section ends, the tube depths, those led by anchors, the point loads, those led by
    point masses, and L; ties keep this order.
    """
    own = own_breakpoints(robot)
    group = _groups(robot)
    n_s, n_a = len(robot.sections) - 1, sum(t.end is not None for t in robot.tendons)
    kind = np.repeat(np.arange(5), [1, n_s, n_a, len(robot.masses), 1])  # base, section end, anchor, mass, L
    m_own = jnp.zeros(len(own))
    if robot.masses:
        m_own = m_own.at[1 + n_s + n_a : -1].set(jnp.stack([m.mass for m in robot.masses]))
    F_own = m_own[:, None] * gravity[None]
    leads = np.unique(group)
    members = np.asarray(group)[None, :] == leads[:, None]  # (groups, own)
    v = jnp.stack([jnp.asarray(x, float) for x in own])
    shift = (jnp.asarray(members, float) @ (v - lax.stop_gradient(v))) / members.sum(axis=1)
    b_own, F_lead, m_lead = (
        lax.stop_gradient(v)[leads] + shift,
        jnp.asarray(members, float) @ F_own,
        jnp.asarray(members, float) @ m_own,
    )
    by = [leads[kind[leads] == k] for k in range(5)]
    s_p = jnp.asarray(load.point_s, float).reshape(-1)
    F_p = jnp.reshape(jnp.asarray(load.point_force, float), (-1, 3))
    C_p = jnp.reshape(jnp.asarray(load.point_moment, float), (-1, 3))
    at = {int(i): k for k, i in enumerate(leads)}
    insertions = jnp.asarray(act.insertions, float).reshape(-1)
    led = [b_own[np.array([at[int(i)] for i in by[k]], dtype=int)] for k in range(5)]
    parts = [led[0], led[1], insertions, led[2], s_p, led[3], led[4]]
    sizes = [p.size for p in parts]
    first = np.cumsum([0, *sizes])
    position = {}  # a lead's index in the unsorted breakpoints
    for k, block in ((0, 0), (1, 1), (2, 3), (3, 5), (4, 6)):
        position |= {int(i): first[block] + j for j, i in enumerate(by[k])}
    lead_rows = np.array([position[int(i)] for i in leads], dtype=int)
    b_all = jnp.concatenate(parts)
    n = b_all.size
    dN_all = jnp.zeros((n, 3)).at[lead_rows].set(-F_lead).at[first[4] : first[5]].set(-F_p)
    dM_all = jnp.zeros((n, 3)).at[first[4] : first[5]].set(-C_p)
    m_all = jnp.zeros(n).at[lead_rows].set(m_lead)
    if n <= 3:
        # one breakpoint between base and tip (0 <= it <= L): the order is known, and the
        # intervals' parameters do not depend on where it lies, so a batch of insertions shares
        # them (as arrays without a batch axis: a sweep of the paper's robot 9% faster)
        order = rank = np.arange(n)
    else:
        order = jnp.argsort(b_all, stable=True)
        rank = jnp.argsort(order, stable=True)
    own_rank = rank[np.array([position[g] for g in group], dtype=int)]
    anchored = [i for i, t in enumerate(robot.tendons) if t.end is not None]
    anchor_rank = jnp.full(robot.n_tendons, n, rank.dtype)
    if anchored:
        anchor_rank = anchor_rank.at[np.asarray(anchored)].set(own_rank[1 + n_s : 1 + n_s + n_a])
    ranks = Ranks(own_rank[1 : 1 + n_s], rank[first[2] : first[3]], anchor_rank)
    b = b_all[order]
    k = jnp.arange(n - 1)
    mid = (b[:-1] + b[1:]) / 2
    intervals = jax.vmap(lambda k, s: interval_parameters(robot, act, k, ranks, s))(k, mid)
    tube_end = ranks.tubes[0] if robot.tubes else jnp.asarray(-1, rank.dtype)
    return Plan(b, intervals, dN_all[order], dM_all[order], tube_end, m_all[order])


def force_scale(robot: Robot, act: Actuation, load: Loads, gravity):
    """A typical force F_c [N] that scales unknowns and residual: tensions, tip load,
    weight, point loads and distributed force. A constant for differentiation."""
    robot, act, load, gravity = lax.stop_gradient((robot, act, load, gravity))
    L = robot.length
    weight = jnp.linalg.norm(gravity) * _mass_moments(robot, act)[0]
    F = jnp.sum(act.tensions) + jnp.linalg.norm(load.tip_force) + jnp.linalg.norm(load.tip_moment) / L + weight
    F = F + jnp.sum(jnp.linalg.norm(load.point_force, axis=-1)) + jnp.sum(jnp.linalg.norm(load.point_moment, axis=-1)) / L
    F = F + jnp.sum(_driven_tensions(robot, act)) if act.driven else F
    return jnp.maximum(F + jnp.linalg.norm(load.distributed_force) * L, 1e-3)


def _driven_tensions(robot: Robot, act: Actuation):
    """Typical tensions [N] of the displacement-driven tendons: each pulled tendon's delta over the
    compliance of the straight robot to it alone, its own stretch l / EA in series with the bend
    r^2 l / EI it makes (the base section's EI), (n_d,). A scale only: the tensions a pull makes
    where the given tensions (a warm start's) are zero."""
    i = np.asarray(act.driven)
    offset = _tendon_fields(robot)[0][i]
    l, EA = rest_lengths(robot)[i], tendon_stiffness(robot)[i]
    sec = robot.sections[0]
    EI = sec.E * jnp.pi / 64 * (sec.outer_diameter**4 - sec.inner_diameter**4)
    return jnp.maximum(act.displacements, 0.0) / (l / EA + offset**2 * l / EI)


def _mass_moments(robot: Robot, act: Actuation):
    """Total mass [kg] and twice its first moment about the base along the straight rod [kg m]:
    sections, tubes to their depths, point masses."""
    starts = [0.0, *(s.end for s in robot.sections[:-1])]
    ends = [*(s.end for s in robot.sections[:-1]), robot.length]
    anchors = _anchors(robot)
    m0 = m1 = 0.0
    for a, b, sec in zip(starts, ends, robot.sections, strict=True):
        rho = sec.density * section_area(sec, jnp.sum((a < anchors).astype(float)))
        m0, m1 = m0 + rho * (b - a), m1 + rho * (b**2 - a**2)
    for tube, d in zip(robot.tubes, jnp.asarray(act.insertions).reshape(-1), strict=True):
        m0, m1 = m0 + tube.density * tube.area * d, m1 + tube.density * tube.area * d**2
    for m in robot.masses:
        m0, m1 = m0 + m.mass, m1 + 2 * m.mass * m.s
    return m0, m1


def straight_rod(robot: Robot, act: Actuation, load: Loads, gravity, F_c, steps: int | None = None):
    """Scaled base unknowns of the straight rod: every load's resultant exactly, its moment about
    the base to first order (the moment arms of the undeformed robot); with a scene (``steps``,
    RK4 steps per breakpoint interval, given) the contact forces follow, all zero."""
    L = robot.length
    m0, m1 = _mass_moments(robot, act)
    N0 = load.tip_force + gravity * m0
    M0 = load.tip_moment + jnp.cross(L * E3, load.tip_force) + jnp.cross(E3, gravity) * m1 / 2
    s_p = jnp.asarray(load.point_s, float)
    N0 = N0 + jnp.sum(load.point_force, 0) + load.distributed_force * L
    arms = s_p[:, None] * E3[None]
    M0 = M0 + jnp.sum(load.point_moment + jnp.cross(arms, load.point_force), 0) + jnp.cross(E3, load.distributed_force) * L**2 / 2
    guesses = jnp.asarray(act.tensions, float)[np.asarray(act.driven, int)]  # the driven tendons' given tensions
    forces = jnp.zeros(0 if steps is None else n_contact_unknowns(robot, load, steps))  # contact free
    return jnp.concatenate([N0 / F_c, M0 / (F_c * L), guesses / F_c, forces])


def _segment(robot: Robot, P: Interval, s, tilt: bool = True) -> Segment:
    r, dr = tendon_positions(robot, s)
    return Segment(P.K_se, P.K_bt, P.rho, P.tau, r, P.backbone, tilt, dr)


class Friction(NamedTuple):
    """The tendons' friction state at a node (module docstring, "Tendon friction"): each tendon's
    tension in the span that starts there tau (n_t,) [N], its base tension tau_b (n_t,) [N], its
    path's world tangent there T (n_t, 3), and the friction exponent phi (n_t,): mu times the
    turning of its path, summed from the base."""

    tau: jax.Array
    base: jax.Array
    T: jax.Array
    phi: jax.Array


class Carry(NamedTuple):
    """What RK4 integrates: the State (inside RK4 as ``segments.carried`` gives it), and where
    needed the arc length s (helical tendons), each tendon's rest length from the base, l (n_t,)
    (displacements), and the tendons' Friction state (a robot with friction); None where not
    needed."""

    y: State
    s: jax.Array | None = None
    l: jax.Array | None = None
    f: Friction | None = None


def rest_lengths(robot: Robot):
    """Each tendon's length from the base to its anchor in the straight, unloaded robot [m], (n_t,)."""
    offset, _, twist = _tendon_fields(robot)
    return _anchors(robot) * jnp.sqrt(1 + (offset * twist) ** 2)


def tendon_stiffness(robot: Robot):
    """Each tendon's axial stiffness EA [N], inf for an inextensible one (no ``stiffness``), (n_t,)."""
    return jnp.stack([jnp.asarray(jnp.inf if t.stiffness is None else t.stiffness, float) for t in robot.tendons])


def displacements(robot: Robot, lengths):
    """What each tendon's encoder reads [m]: its rest length inside the straight robot less its
    present rest length there, ``lengths``, the integral of dl / (1 + tau(s) / EA) along its path
    (``integrate``), (n_t,)."""
    return rest_lengths(robot) - lengths


def with_driven(act: Actuation, x, F_c) -> Actuation:
    """The actuation with the displacement-driven tendons' tensions taken from the unknowns x[6:6 + n_d]."""
    if not act.driven:
        return act
    tensions = jnp.asarray(act.tensions, float).at[np.asarray(act.driven)].set(x[6 : 6 + len(act.driven)] * F_c)
    return Actuation._rebuild(tensions, act.insertions, act.displacements, act.driven, act.memory)


class Pieces(NamedTuple):
    """Consecutive RK4 pieces of equal step count (``pieces``): each one's segment parameters, arc
    length at its start s0, step length h, the jump (dN, dM) applied at its start, (..., 3), and
    the index of its breakpoint interval with whether it is that interval's first piece."""

    P: Interval
    s0: jax.Array
    h: jax.Array
    dN: jax.Array
    dM: jax.Array
    k: jax.Array
    lead: jax.Array


def n_intervals(robot: Robot, load: Loads) -> int:
    """The number of breakpoint intervals of ``plan`` (static): one fewer than the robot's own
    breakpoints, coincident ones counted once (``Robot.merged``), plus the tubes and point loads."""
    return len(set(_groups(robot))) - 1 + robot.n_tubes + load.n_points


def n_contact_unknowns(robot: Robot, load: Loads, steps: int) -> int:
    """Contact unknowns (one force per candidate and obstacle) of ``load.scene``, 0 without one."""
    if load.scene is None:
        return 0
    return contact.n_candidates(n_intervals(robot, load), steps, load.scene.every) * load.scene.n_obstacles


def check_intervals(robot: Robot, load: Loads, solver) -> None:
    """Raises unless the shooting intervals K divide the P steps RK4 steps (P: ``n_intervals``),
    naming ``intervals``, its value and the allowed values."""
    P, n, K = n_intervals(robot, load), solver.steps, solver.intervals
    if (P * n) % K:
        allowed = [k for k in range(1, P * n + 1) if (P * n) % k == 0]
        raise ValueError(
            f"intervals = {K}: a robot with {P} breakpoint intervals of steps = {n} RK4 steps each is split into "
            f"K intervals of equal step count, so K must divide {P} x {n} = {P * n}: one of {allowed} "
            f"(every breakpoint an interval boundary for K = {P} q, q dividing {n})"
        )


def pieces(pl: Plan, steps: int, K: int, every: int | None = None) -> tuple[Pieces, int]:
    """The P breakpoint intervals' P steps RK4 steps as K shooting intervals of c = P steps / K
    steps each: pieces of g = gcd(c, steps) steps (each inside one breakpoint interval), shaped
    (K, c / g, ...), and g; with ``every`` (contact candidates every ``every`` steps) g also
    divides it, so that each candidate is a piece start. The jump of each breakpoint goes with
    the first piece after it."""
    P = pl.b.size - 1
    c = P * steps // K
    g = np.gcd(c, steps) if every is None else np.gcd(np.gcd(c, steps), every)
    per = steps // g  # pieces per breakpoint interval
    h = (pl.b[1:] - pl.b[:-1]) / steps
    first = (np.arange(per) == 0)[None, :, None]

    def jump(d):
        return jnp.where(first, d[:-1, None], 0.0).reshape(P * per, 3)

    ps = Pieces(
        jax.tree.map(lambda a: jnp.repeat(a, per, axis=0), pl.intervals),
        (pl.b[:-1, None] + h[:, None] * (g * np.arange(per))[None]).reshape(-1),
        jnp.repeat(h, per),
        jump(pl.dN),
        jump(pl.dM),
        np.repeat(np.arange(P), per),
        np.tile(np.arange(per) == 0, P),
    )
    return jax.tree.map(lambda a: a.reshape(K, c // g, *a.shape[1:]), ps), int(g)


def integrate(
    robot: Robot,
    load: Loads,
    gravity,
    ps: Pieces,
    c: Carry,
    steps: int,
    path: bool = False,
    forces=None,
    rotation=None,
    paper: Paper | None = None,
    memory=None,
):
    """RK4 over consecutive pieces of ``steps`` steps (``pieces``, one shooting interval), each
    after its jump, from the Carry c; tendon lengths where c.l is not None, arc length for helical
    tendons. Returns the end Carry and the nodes (with ``path``: (pieces, steps + 1, ...), each
    piece's first node after its jump).

    ``forces``: each piece's contact forces against ``load.scene``'s obstacles [N], (pieces,
    n_o), or None (no contact): at its start the piece's N jumps by the point force -sum_o
    lambda_o n_o(p) (contact.py), and the nodes come with each piece start's Starts (position and
    gaps to the obstacles). ``rotation``: ``SolverOptions.rotation``. ``paper``: the paper's
    printed variants (``Paper``), None for neither. ``memory``: with tendon friction, each
    step's previous-pose tension of the span after it (pieces, steps, n_t) (``next_spans``)."""
    helical, lengths, friction = is_helical(robot), c.l is not None, robot.has_friction
    f_d = load.distributed_force
    r_fixed = None if helical else tendon_positions(robot, 0.0)[0]
    printed = paper is not None and paper.tendons
    EA = tendon_stiffness(robot) if robot.tendons else jnp.zeros(0)

    def segment(P: Interval, s, tilt: bool = True) -> Segment:
        return _segment(robot, P, s, tilt) if helical else Segment(P.K_se, P.K_bt, P.rho, P.tau, r_fixed, P.backbone, tilt)

    def carried_tension(P: Interval, c: Carry) -> Interval:
        return P if c.f is None else P._replace(tau=P.present * c.f.tau)

    def field(P: Interval):
        dN = -P.rho * gravity - f_d  # N' = -f: weight and distributed force, constant along the piece

        def rate(seg: Segment, y):
            v, u = strains_at(seg, y)
            dp = y.world(v)
            dM = -jnp.cross(dp, y.N)
            if not seg.tilt:
                dM = dM - y.world(printed_moment(seg, u))
            return y.rate(dp, u, dN, dM), v, u

        def f(c: Carry) -> Carry:
            Pc = carried_tension(P, c)
            seg = segment(Pc, c.s)
            dy, v, u = rate(seg, c.y)
            if printed:  # the printed tendon model where a tube is inside
                dy, v, u = jax.tree.map(
                    lambda a, b: jnp.where(P.backbone > 0, a, b), rate(segment(Pc, c.s, False), c.y), (dy, v, u)
                )
            dl = None
            if lengths:
                dl = P.present * jnp.linalg.norm(tendon_pb(seg, v, u), axis=-1) / (1 + seg.tau / EA)
            df = None if c.f is None else jax.tree.map(jnp.zeros_like, c.f)
            return Carry(dy, None if c.s is None else jnp.ones_like(c.s), dl, df)

        return f

    def project(c: Carry) -> Carry:
        return c._replace(y=c.y.orthonormalized())

    def tangents(P: Interval, c: Carry):
        """Each tendon's world tangent at the node c (tensions: the span just integrated)."""
        seg = segment(carried_tension(P, c), c.s)
        v, u = strains_at(seg, c.y)
        return jax.vmap(c.y.world)(tendon_tangents(seg, v, u))

    def guides(k: Pieces):
        """``project``, then the guide at the node ending step j (each node in a channel, those past
        each disk with ``spacing``): the tension of the span ahead is the previous pose's there,
        held within the capstan bounds tau_b exp(-phi) and tau_b exp(phi) (``memory``)."""

        def at(c: Carry, x) -> Carry:
            c = project(c)
            j, prev = x
            return c._replace(f=guided(c.f, tangents(k.P, c), k.P, k.s0 + (j + 1) * k.h, k.h, prev))

        return at

    def transition(k: Pieces, y: State) -> State:
        """Eqs. 31-36 as printed at the first tube's end, strictly inside the robot."""
        pl = paper.plan
        d = pl.b[jnp.maximum(pl.tube_end, 0)]
        here = k.lead & (k.k == pl.tube_end) & (d > 0) & (d < pl.b[-1])
        before = jax.tree.map(lambda a: a[jnp.maximum(k.k - 1, 0)], pl.intervals)
        jumped = paper_transition(segment(before, k.s0, not paper.tendons), segment(k.P, k.s0), y)
        return jax.tree.map(lambda a, b: jnp.where(here, a, b), jumped, y)

    def piece(c: Carry, kf):
        k, f, prev = kf
        y = c.y._replace(N=c.y.N + k.dN, M=c.y.M + k.dM)
        if paper is not None and paper.plan is not None:
            y = transition(k, y)
        starts = None
        if f is not None:
            F, starts = contact.at_start(load.scene, f, y.p, k.P.radius)
            y = y._replace(N=y.N - F)
        start = Carry(carried(y, rotation), k.s0 if helical else None, c.l, c.f)
        if friction:
            out = rk4(field(k.P), start, k.h, steps, guides(k), path, (jnp.arange(steps), prev))
        else:
            out = rk4(field(k.P), start, k.h, steps, project, path)
        end, nodes = out if path else (out, None)
        end, nodes = end._replace(y=uncarried(end.y)), None if nodes is None else nodes._replace(y=uncarried(nodes.y))
        return end._replace(s=None), nodes if f is None else (nodes, starts)

    if friction and c.f is None:
        P0 = jax.tree.map(lambda a: a[0], ps.P)
        c = c._replace(f=Friction(P0.tau, P0.tau, jnp.zeros((robot.n_tendons, 3)), jnp.zeros(robot.n_tendons)))
        c = c._replace(f=c.f._replace(T=tangents(P0, c._replace(y=carried(c.y, rotation), s=ps.s0[0] if helical else None))))
        memory = jnp.zeros((*ps.h.shape, steps, robot.n_tendons)) if memory is None else memory
    return lax.scan(piece, coupled(c._replace(s=None), ps, forces, memory), (ps, forces, memory))


def guided(f: Friction, T, P: Interval, s, h, previous) -> Friction:
    """The friction state at the node at s that ends a step of length h in interval P, the
    tendons' world tangents there T (n_t, 3): the turning adds to phi, and where a guide sits
    (every node of a channel, or the first past each disk at ``P.spacing``) the tension of the span
    ahead is the previous pose's there, ``previous``, held within the capstan bounds
    tau_b exp(-phi) and tau_b exp(phi) (module docstring, "Tendon friction")."""
    phi = f.phi + P.mu * _turning(f.T, T)
    d = jnp.where(P.spacing > 0, P.spacing, 1.0)
    guide = (P.spacing <= 0) | (jnp.floor(s / d) > jnp.floor((s - h) / d))
    bound = jnp.exp(phi)
    held = jnp.minimum(jnp.maximum(previous, f.base / bound), f.base * bound)
    return f._replace(tau=jnp.where(guide, held, f.tau), T=T, phi=phi)


def _turning(a, b):
    """The angle between unit vectors a and b, row by row [rad]: atan2(|a x b|, a . b), with
    derivative zero where they coincide (a straight path)."""
    w = jnp.cross(a, b)
    return jnp.arctan2(jnp.sqrt(jnp.sum(w * w, -1) + 1e-300), jnp.sum(a * b, -1))


def next_spans(robot: Robot, act: Actuation, P: int, steps: int, g: int):
    """``integrate``'s memory: the previous pose's tension of the span after each step (the last
    step's: its own), from ``act.memory``, a node profile (P (steps + 1), n_t) as
    ``tension_profile`` gives it, shaped (P steps / g, g, n_t); None: zeros (loading from slack)."""
    n = robot.n_tendons
    if act.memory is None:
        return jnp.zeros((P * steps // g, g, n))
    spans = jnp.reshape(act.memory, (P, steps + 1, n))[:, :-1].reshape(P * steps, n)
    return jnp.concatenate([spans[1:], spans[-1:]]).reshape(P * steps // g, g, n)


def tension_profile(pl: Plan, nodes: Carry):
    """Each tendon's tension at every node [N], (P (steps + 1), n_t): that of the span starting
    there (an interval's last node: the span ending there), zero beyond its anchor."""
    P, m = nodes.y.p.shape[:2]
    present = pl.intervals.present[:, None, :]
    if nodes.f is None:
        return jnp.broadcast_to(pl.intervals.tau[:, None, :], (P, m, present.shape[-1])).reshape(P * m, -1)
    tau = nodes.f.tau
    return (jnp.concatenate([tau[:, :-1], tau[:, -2:-1]], 1) * present).reshape(P * m, -1)


class Paper(NamedTuple):
    """The paper's printed variants (``SolverOptions``): ``tendons`` (static), its tendon model
    (eqs. 21-22: tangents e3) where a tube is inside; ``plan``, the Plan whose first tube's end
    takes its transition (eqs. 31-36), or None for the balanced one."""

    tendons: bool
    plan: Plan | None


def paper_variants(solver, pl: Plan) -> Paper | None:
    """The ``Paper`` variants ``solver`` asks for on the plan ``pl``; None for the defaults."""
    tendons, transition = solver.tendon_model == "paper", solver.transition == "paper"
    return Paper(tendons, pl if transition else None) if tendons or transition else None


def by_interval(a, P: int):
    """Nodes of consecutive pieces (pieces, g + 1, ...), P breakpoint intervals' worth, as
    (P, steps + 1, ...): each interval's first node after its breakpoint's jump, each later
    piece's start its predecessor's end (before a contact force there)."""
    a = a.reshape(P, a.shape[0] // P, *a.shape[1:])
    rest = a[:, 1:, 1:]
    return jnp.concatenate([a[:, 0], rest.reshape(P, rest.shape[1] * rest.shape[2], *a.shape[3:])], 1)


def closing(robot: Robot, act: Actuation, load: Loads, pl: Plan, y: State, lengths, F_c, touch=None, mu=0.0):
    """The scaled residual at the tip State y (before the jump at L) with the tendons' lengths:
    tip (6,), then per driven tendon phi(tau / F_c, (delta_shape - delta) / L) (``shoot``), then
    with a scene (``touch``: contact.Candidates, the last one the tip's, whose force is applied
    here) per candidate and obstacle phi_mu(lambda / F_c, gap / L) (contact.py); and each
    tendon's slack flag (n_t,)."""
    L = robot.length
    N_L, M_L = y.N + pl.dN[-1], y.M + pl.dM[-1]
    if touch is not None:
        N_L = N_L - touch.force[-1] @ load.scene.normals(y.p)
    res = [(N_L - load.tip_force) / F_c, (M_L - load.tip_moment) / (F_c * L)]
    slack = jnp.zeros(robot.n_tendons, bool)
    if act.driven:
        i = np.asarray(act.driven)
        gap = displacements(robot, lengths)[i] - act.displacements
        a, b = act.tensions[i] / F_c, gap / L
        res.append(contact.fischer_burmeister(a, b))
        slack = slack.at[i].set(b > a)
    if touch is not None:
        res.append(contact.residual(touch, F_c, L, mu))
    return jnp.concatenate(res), slack


def shoot(robot: Robot, act: Actuation, load: Loads, gravity, solver, x, F_c, path: bool = False, mu=0.0, pl=None):
    """Integrates every interval from the scaled unknowns x to the tip: x[:6] the base wrench
    (N(0), M(0)), x[6:6 + n_d] the tensions of the displacement-driven tendons (act.driven) over
    F_c, then with ``load.scene`` the contact forces lambda / F_c, candidate by candidate, each
    with one per obstacle (contact.py; their rows smoothed by mu, 0: exact).

    Returns:
        The scaled residual: tip (6,), then per driven tendon phi(tau / F_c, (delta_shape -
        delta) / L) with Fischer and Burmeister's phi(a, b) = a + b - |(a, b)|, zero where the
        tendon is taut at its commanded displacement delta (b = 0, a >= 0) or slack (tau = 0, the
        shape asking for more than was pulled: b > 0); then the contact rows (``closing``); and
        the tip State (with ``path``: the Carry at every interval's steps + 1 nodes, shapes (K,
        steps + 1, ...), both sides of each breakpoint, the node at an interval's start after that
        breakpoint's jump; the plan, actuation, tendon lengths, slack flags and the
        contact.Contact, None without a scene).

    ``pl``: the ``plan`` of these inputs, where the caller has it (it does not depend on x
    without displacement-driven tendons); None: made here.
    """
    scene, n_d = load.scene, len(act.driven)
    act = with_driven(act, x, F_c)
    pl = plan(robot, act, load, gravity) if pl is None else pl
    ps, g = pieces(pl, solver.steps, 1, None if scene is None else scene.every)
    ps = jax.tree.map(lambda a: a[0], ps)
    y0 = State(jnp.zeros(3), jnp.eye(3), x[:3] * F_c, x[3:6] * F_c * robot.length)
    l0 = jnp.zeros(robot.n_tendons) if act.driven or path else None
    touch = forces = None
    if scene is not None:
        P = pl.b.size - 1
        where = contact.interior_pieces(P, solver.steps, g, scene.every)
        lam = x[6 + n_d :].reshape(-1, scene.n_obstacles) * F_c
        forces = jnp.zeros((ps.h.size, scene.n_obstacles)).at[where].set(lam[:-1])
    memory = next_spans(robot, act, pl.b.size - 1, solver.steps, g) if robot.has_friction else None
    end, out = integrate(
        robot, load, gravity, ps, Carry(y0, None, l0), g, path, forces, solver.rotation, paper_variants(solver, pl), memory
    )
    nodes, starts = (out, None) if scene is None else out
    if scene is not None:
        # a candidate inside a zero-length interval shares its point with the next one: off
        tip_gap = scene.distances(end.y.p) - pl.intervals.radius[-1]
        touch = contact.Candidates(lam, jnp.concatenate([starts.gap[where], tip_gap[None]]), jnp.append(ps.h[where] == 0, False))
    res, slack = closing(robot, act, load, pl, end.y, end.l, F_c, touch, mu)
    if not path:
        return res, end.y
    found = None
    if scene is not None:
        s = jnp.append(ps.s0[where], robot.length)
        p = jnp.concatenate([starts.p[where], end.y.p[None]])
        found = contact.outputs(scene, s, p, touch, F_c, robot.length)
    nodes = jax.tree.map(lambda a: by_interval(a, pl.b.size - 1), nodes)
    return res, (nodes, pl, act, end.l, slack, found)


def node_quantities(robot: Robot, act, load, gravity, nodes, pl: Plan, tendon_model: str = "exact"):
    """Flattened node arc lengths, States, strains v, u and rod force n, m, each node by its own
    interval's segment parameters (``tendon_model`` "paper": the printed one where a tube is inside)."""
    ys, P = nodes.y, pl.intervals
    K, m = pl.b.size - 1, jnp.shape(ys.p)[1]
    # node arc lengths on the exact grid (the ones carried in the state differ in the last bit),
    # each interval's last node exactly at its breakpoint
    frac = (jnp.arange(m) / (m - 1))[None, :]
    s = jnp.where(frac < 1, pl.b[:-1, None] + (pl.b[1:] - pl.b[:-1])[:, None] * frac, pl.b[1:, None])
    flat = jax.tree.map(lambda a: a.reshape(K * m, *a.shape[2:]), ys)
    P_nodes = jax.tree.map(lambda a: jnp.repeat(a, m, axis=0), P)
    if nodes.f is not None:
        P_nodes = P_nodes._replace(tau=tension_profile(pl, nodes))

    def one(args):
        y, P, s = args

        def at(seg: Segment):
            v, u = strains(seg, y.R, y.N, y.M)
            return (v, u, *rod_force(seg, y, v, u))

        if tendon_model == "paper":
            return jax.tree.map(
                lambda a, b: jnp.where(P.backbone > 0, a, b), at(_segment(robot, P, s, False)), at(_segment(robot, P, s))
            )
        return at(_segment(robot, P, s))

    # lax.map, not vmap: see solve._assemble
    return s.reshape(-1), flat, lax.map(one, (flat, P_nodes, s.reshape(-1)))


def check_arguments(robot: Robot, act: Actuation, load: Loads, solver) -> None:
    """Counts and ranges that need robot and inputs together (ValueError naming field and range)."""
    if (solver.transition != "balanced" or solver.tendon_model != "exact") and not robot.tubes:
        raise ValueError(
            f"solver transition = {solver.transition!r}, tendon_model = {solver.tendon_model!r}: the paper's variants act "
            "where a tube is inside and at its end; this robot has no tube (use 'balanced' and 'exact')"
        )
    n_t, n_tubes = robot.n_tendons, robot.n_tubes
    if any(i >= n_t for i in act.driven):
        raise ValueError(f"driven = {act.driven}: the robot has {n_t} tendons, indices 0 to {n_t - 1}")
    if tuple(jnp.shape(act.tensions)) != (n_t,):
        raise ValueError(f"tensions has shape {jnp.shape(act.tensions)}: the robot has {n_t} tendons, one tension each")
    if tuple(jnp.shape(act.insertions)) != (n_tubes,):
        raise ValueError(f"insertions has shape {jnp.shape(act.insertions)}: the robot has {n_tubes} tubes, one depth each")
    if not is_concrete(robot.length):
        return
    L = float(robot.length)
    check_range("insertions", act.insertions, 0.0, L, unit=f" m (0 to the robot length {L:g} m)")
    check_range("point_s", load.point_s, 0.0, L, unit=f" m (0 to the robot length {L:g} m)")
    for i, t in enumerate(robot.tendons):
        if t.max_tension is not None and is_concrete(act.tensions) and is_concrete(t.max_tension):
            check_range(f"tensions[{i}]", act.tensions[i], 0.0, float(t.max_tension), unit=f" N (tendons[{i}].max_tension)")
    if act.memory is not None:
        n = n_intervals(robot, load) * (solver.steps + 1)
        if not robot.has_friction:
            raise ValueError("memory: a tension profile only acts with tendon friction (no section has a friction coefficient)")
        if tuple(jnp.shape(act.memory)) != (n, n_t):
            raise ValueError(
                f"memory has shape {tuple(jnp.shape(act.memory))}: the previous pose's tendon_tension, ({n}, {n_t}) for this "
                f"robot and loads at steps = {solver.steps} (one row per node)"
            )
    if robot.has_friction and solver.intervals > 1:
        raise ValueError(
            f"solver intervals = {solver.intervals} with tendon friction: the tendons' tension profiles are carried "
            "by single shooting only; use intervals = 1"
        )
    if act.driven and is_concrete_tree(robot):
        with jax.ensure_compile_time_eval():  # under jit, jnp on constants would be traced
            reach = np.asarray(rest_lengths(robot))
        for k, i in enumerate(act.driven):
            check_range(
                f"displacements[{k}] (tendons[{i}])",
                act.displacements[k],
                -np.inf,
                float(reach[i]),
                lo_open=True,
                hi_open=True,
                unit=" m (below the tendon's rest length from the base to its anchor in the straight robot)",
            )
