"""Inverse kinematics: the tensions and insertion that put the tip at a target pose, with the tube
insertion as a redundant, stiffness-aware input (paper Secs. V.A and V.B).

The free inputs (any subset of the tendons, and the insertion) are scaled to v = (tau / tau_max,
d / L) and kept inside their bounds exactly. Two phases:

1. Reach: bounded Levenberg-Marquardt on the task residual e (tip position error / L, weighted,
   and optionally the orientation error). Each step solves a small box-constrained least-squares
   problem exactly by enumerating the active sets (3^n of them for n <= 5 free inputs), so
   active bounds are handled exactly, not by clipping. Two ways to evaluate a step: "augmented"
   (the default) iterates the shooting unknowns x and the inputs v together, Newton on the tip
   boundary residual r(x, v) = 0 and Gauss-Newton on e, one forward-mode Jacobian pass of
   (r, e) per step; "nested" runs a converged forward solve at every step and differentiates
   it implicitly.
2. Optimise (with an objective, once reached): sequential quadratic programming on
   min phi(v) subject to e(v) = 0 and the bounds, with phi's exact gradient (forward-mode
   autodiff through the implicitly differentiated solve and compliance), a damped BFGS
   Hessian of the Lagrangian, and the same exact active-set subproblem.

A target that the bounds do not let the tip reach ends phase 1 at a stationary point of |e|^2:
status UNREACHABLE with the nearest pose found and its distance. Derivatives of the solution
with respect to the target and the robot come from implicit differentiation of the optimality
conditions at the solution (``jax.jacfwd`` through ``inverse_kinematics``).
"""

from __future__ import annotations

import functools
import inspect
import itertools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from . import general, status
from .batch import Kernel, default_chunk_size, lanes_per_call, run_batched
from .checks import UnitWarning, as_array, check_choice, check_integer, check_range, is_concrete, target_note, warn_user
from .description import GeneralRobot
from .inputs import GeneralActuation, Loads
from .linalg import solve_spd
from .loads import STANDARD_GRAVITY, Actuation, TipLoad, gravity_vector
from .options import DEFAULT_SOLVER, SolverOptions
from .robot import Robot
from .shooting import compliance_at, force_scale, root, scaled, shoot, unscaled
from .solve import Solution, check_inputs, solution_and_compliance, tip_angle
from .tree import pytree, set_fields, static

TOL = 1e-10
"""Default tolerance on the scaled task residual: position error / L (and orientation error [rad])."""
MAX_STEPS = 60
"""Default limit on IK steps (both phases together)."""
OBJECTIVES = ("stiffness", "tension", "insertion")
METHODS = ("augmented", "nested")
AXES = "xyz"


@pytree
class Target:
    """A tip pose to reach, world frame.

    Attributes:
        position: tip position [m], (3,); a leading batch axis (n, 3) holds n targets.
        direction: unit tip tangent to reach, (3,) (normalised here), or None.
        tip_angle: in-plane tip angle theta_tip [rad] (z-y plane, from +z toward +y) in
            [-pi, pi], or None; at most one of direction and tip_angle. Batched like the position.
        position_weight: weight of the position error (per robot length), > 0.
        orientation_weight: weight of the orientation error (per radian), >= 0.
        axes: the position components that count (static), e.g. "yz" for a target in the z-y
            plane, "y" for a tip height; default all three.
    """

    position: object
    direction: object = None
    tip_angle: object = None
    position_weight: float = 1.0
    orientation_weight: float = 1.0
    axes: str = static(default="xyz")

    def __post_init__(self):
        if (
            not isinstance(self.axes, str)
            or not self.axes
            or any(a not in AXES for a in self.axes)
            or len(set(self.axes)) != len(self.axes)
        ):
            raise ValueError(f"axes = {self.axes!r} must name position components once each, from 'xyz'")
        position = as_array("position", self.position, trailing=(3,), unit=" m")
        direction = self.direction
        if direction is not None:
            direction = as_array("direction", direction, trailing=(3,))
            if is_concrete(direction):
                norm = np.linalg.norm(direction, axis=-1, keepdims=True)
                if np.any(norm == 0.0):
                    raise ValueError("direction = [0, 0, 0]: a tip direction must be a nonzero vector")
                direction = direction / norm
        tip = as_array("tip_angle", self.tip_angle, unit=" rad") if self.tip_angle is not None else None
        check_range("tip_angle", tip, -np.pi, np.pi, unit=" rad") if tip is not None else None
        if direction is not None and tip is not None:
            raise ValueError("give at most one of direction (a unit tangent) and tip_angle (in-plane), not both")
        weights = {}
        for name, lo_open in (("position_weight", True), ("orientation_weight", False)):
            weights[name] = as_array(name, getattr(self, name), ())
            check_range(name, weights[name], 0.0, lo_open=lo_open)
        set_fields(self, position=position, direction=direction, tip_angle=tip, **weights)

    @property
    def orientation(self) -> str | None:
        return "direction" if self.direction is not None else "tip_angle" if self.tip_angle is not None else None

    @property
    def size(self) -> int:
        """Rows of the task residual."""
        return len(self.axes) + {None: 0, "direction": 2, "tip_angle": 1}[self.orientation]


@pytree
class Bounds:
    """Physical bounds on the inputs: tendons only pull, the tube stays inside the robot.

    Attributes:
        tension: (lowest, highest) tension of every free tendon [N], 0 <= lowest <= highest; on a
            GeneralRobot a tendon's own ``max_tension`` lowers its highest.
        insertion: (shallowest, deepest) insertion of every free tube [m] in [0, L]; None: (0, L).
        displacement: (lowest, highest) displacement of every free displacement-driven tendon of a
            GeneralRobot [m]; None: (-L / 10, L / 10).
    """

    tension: tuple = (0.0, 10.0)
    insertion: tuple | None = None
    displacement: tuple | None = None

    def __post_init__(self):
        tension = as_array("bounds.tension", self.tension, (2,), unit=" N")
        check_range("bounds.tension", tension, 0.0, unit=" N")
        insertion = None if self.insertion is None else as_array("bounds.insertion", self.insertion, (2,), unit=" m")
        check_range("bounds.insertion", insertion, 0.0, unit=" m") if insertion is not None else None
        displacement = self.displacement
        if displacement is not None:
            displacement = as_array("bounds.displacement", displacement, (2,), unit=" m")
        for name, b in (("bounds.tension", tension), ("bounds.insertion", insertion), ("bounds.displacement", displacement)):
            if b is not None and is_concrete(b) and b[0] > b[1]:
                raise ValueError(f"{name} = {b.tolist()} must be (lowest, highest) with lowest <= highest")
        set_fields(self, tension=tension, insertion=insertion, displacement=displacement)


DEFAULT_BOUNDS = Bounds()


class Plan(NamedTuple):
    """What is free (static): which tendons and which tubes (0-based; a ``Robot``'s one tube is
    tube 0, its insertion), which objective. v holds the free tendons' scaled tensions (or, for a
    GeneralActuation's ``driven`` tendons, scaled displacements) in this order, then the tubes'."""

    tendons: tuple
    tubes: tuple
    objective: object  # None, a name in OBJECTIVES, or a callable (sol, act) -> scalar
    method: str


@pytree
class IKResult:
    """Outcome of ``inverse_kinematics``.

    Attributes:
        actuation: the tensions [N] and insertion [m] found (every bound holds); for a
            GeneralRobot a GeneralActuation, its tensions those of the solution (the driven
            tendons' included).
        solution: the forward Solution there (``solution.tip_position`` etc.).
        position_error: distance from the tip to the target position (over ``target.axes``) [m].
        orientation_error: angle between tip and target orientation [rad] (0 without one).
        objective: the objective's value there (NaN without one).
        iterations: IK steps taken.
        result: a ``tdct_jax.status`` code: SUCCESS (reached), UNREACHABLE (the nearest pose
            found is returned, ``position_error`` away), OUTER_LIMIT, or the forward solve's own.
    """

    actuation: Actuation
    solution: Solution
    position_error: jax.Array
    orientation_error: jax.Array
    objective: jax.Array
    iterations: jax.Array
    result: jax.Array

    @property
    def reached(self):
        return self.result == status.SUCCESS

    @property
    def tip_position(self):
        return self.solution.tip_position

    @property
    def tip_angle(self):
        return self.solution.tip_angle


# ----------------------------------------------------------------------------- subproblems


def _patterns(n: int) -> np.ndarray:
    """Every active set of n box-constrained variables: 0 free, 1 at its lower, 2 at its upper bound."""
    return np.array(list(itertools.product((0, 1, 2), repeat=n)), dtype=np.int8).reshape(-1, n)


def box_qp(H, g, lo, hi, J=None, c=None):
    """argmin 1/2 s^T H s + g^T s over lo <= s <= hi (and J s = c when given), H positive
    definite, exactly: every active set is solved (fixed variables at their bounds) and the best
    feasible solution kept. Returns (s, multipliers of J s = c, whether a feasible one exists)."""
    n = g.shape[0]
    m = 0 if J is None else J.shape[0]
    tol = 1e-12 * (1.0 + jnp.max(jnp.abs(hi - lo)))

    def one(p):
        fixed = p > 0
        value = jnp.where(p == 1, lo, hi) * fixed
        keep = ~fixed
        A = jnp.where(keep[:, None] & keep[None, :], H, 0.0) + jnp.diag(fixed.astype(H.dtype))
        rhs = jnp.where(fixed, value, -(g + H @ value))
        if m:
            Jf = J * keep[None, :]
            K = jnp.block([[A, Jf.T], [Jf, -1e-14 * jnp.eye(m)]])
            sol = jnp.linalg.solve(K, jnp.concatenate([rhs, c - J @ value]))
            s, lam = sol[:n], sol[n:]
            consistent = jnp.max(jnp.abs(J @ s - c)) <= 1e-9 * (1.0 + jnp.max(jnp.abs(c)))
        else:
            s, lam, consistent = solve_spd(A, rhs), jnp.zeros(0), True
        ok = jnp.all(jnp.isfinite(s)) & jnp.all(s >= lo - tol) & jnp.all(s <= hi + tol) & consistent
        return s, lam, ok, 0.5 * s @ H @ s + g @ s

    s, lam, ok, q = jax.vmap(one)(jnp.asarray(_patterns(n)))
    k = jnp.argmin(jnp.where(ok, q, jnp.inf))
    return jnp.clip(s[k], lo, hi), lam[k], jnp.any(ok)


# ----------------------------------------------------------------------------- the problem


class Problem(NamedTuple):
    """Everything an IK step needs besides the free inputs v (a pytree; ``plan`` is static)."""

    robot: Robot | GeneralRobot
    target: Target
    load: TipLoad | Loads  # Loads for a GeneralRobot
    gravity: jax.Array
    base: Actuation | GeneralActuation  # values of the fixed inputs, by the robot's kind
    lo: jax.Array  # bounds of v
    hi: jax.Array
    tension_scale: jax.Array  # [N] per unit of v
    solver: SolverOptions
    preferred_insertion: jax.Array  # [m], for the "insertion" objective
    direction: jax.Array  # unit world direction for the "stiffness" objective (NaN: largest eigenvalue)


DISPLACEMENT_SCALE = 0.1
"""A free displacement-driven tendon's scaled input: its displacement over this fraction of L."""


def _split(base, plan: Plan):
    """Static positions in v of the free tendons driven by tension and of those driven by
    displacement (a GeneralActuation's ``driven``), with the latter's places in ``displacements``."""
    driven = getattr(base, "driven", ())
    pulled = tuple(j for j, t in enumerate(plan.tendons) if t not in driven)
    moved = tuple(j for j, t in enumerate(plan.tendons) if t in driven)
    return pulled, moved, tuple(driven.index(plan.tendons[j]) for j in moved)


def actuation_of(v, prob: Problem, plan: Plan):
    """The actuation (an Actuation, or a GeneralActuation for a GeneralRobot) with the free inputs
    set from the scaled v."""
    k, base, L = len(plan.tendons), prob.base, prob.robot.length
    if isinstance(base, Actuation):
        tensions = jnp.asarray(base.tensions)
        if k:
            tensions = tensions.at[jnp.asarray(plan.tendons)].set(v[:k] * prob.tension_scale)
        insertion = v[k] * L if plan.tubes else jnp.asarray(base.insertion)
        return Actuation(tensions, insertion)
    pulled, moved, places = _split(base, plan)
    tensions, insertions, displacements = (jnp.asarray(x, float) for x in (base.tensions, base.insertions, base.displacements))
    if pulled:
        free = np.array([plan.tendons[j] for j in pulled])
        tensions = tensions.at[free].set(v[np.array(pulled)] * prob.tension_scale)
    if moved:
        displacements = displacements.at[np.array(places)].set(v[np.array(moved)] * (DISPLACEMENT_SCALE * L))
    if plan.tubes:
        insertions = insertions.at[np.array(plan.tubes)].set(v[k:] * L)
    return GeneralActuation._rebuild(tensions, insertions, displacements, base.driven)


def scaled_inputs(act, prob: Problem, plan: Plan):
    """The inverse of ``actuation_of``: v of an actuation."""
    L = prob.robot.length
    if isinstance(act, Actuation):
        v = [jnp.asarray(act.tensions)[jnp.asarray(plan.tendons)] / prob.tension_scale] if plan.tendons else []
        if plan.tubes:
            v.append(jnp.reshape(act.insertion / L, (1,)))
        return jnp.concatenate(v) if v else jnp.zeros(0)
    pulled, moved, places = _split(act, plan)
    v = jnp.zeros(len(plan.tendons) + len(plan.tubes))
    if pulled:
        v = v.at[np.array(pulled)].set(
            jnp.asarray(act.tensions)[np.array([plan.tendons[j] for j in pulled])] / prob.tension_scale
        )
    if moved:
        v = v.at[np.array(moved)].set(jnp.asarray(act.displacements)[np.array(places)] / (DISPLACEMENT_SCALE * L))
    if plan.tubes:
        v = v.at[len(plan.tendons) :].set(jnp.asarray(act.insertions)[np.array(plan.tubes)] / L)
    return v


def _wrench(sol, act):
    """The shooting unknowns of a Solution, unscaled: its base wrench, then (a GeneralRobot's)
    the displacement-driven tendons' tensions [N]."""
    if getattr(act, "driven", ()):
        return jnp.concatenate([sol.base_wrench, sol.tensions[np.array(act.driven)]])
    return sol.base_wrench


def _tip_force(load):
    """The tip force [N] of a TipLoad or Loads."""
    return load.force if isinstance(load, TipLoad) else load.tip_force


def task_residual(p, R, target: Target, L):
    """The weighted task residual e: position error / L on ``target.axes``, then the orientation
    error (tip angle difference [rad], or the target direction's x, y components in the tip frame)."""
    index = np.array([AXES.index(a) for a in target.axes])
    rows = [target.position_weight * (p[index] - target.position[index]) / L]
    if target.orientation == "tip_angle":
        rows.append(jnp.reshape(target.orientation_weight * _wrap(tip_angle(R) - target.tip_angle), (1,)))
    elif target.orientation == "direction":
        rows.append(target.orientation_weight * (R.T @ target.direction)[:2])
    return jnp.concatenate(rows)


def pose_errors(p, R, target: Target):
    """(position error [m] over ``target.axes``, orientation error [rad])."""
    index = np.array([AXES.index(a) for a in target.axes])
    position = jnp.linalg.norm(p[index] - target.position[index])
    if target.orientation == "tip_angle":
        return position, jnp.abs(_wrap(tip_angle(R) - target.tip_angle))
    if target.orientation == "direction":
        t = R[:, 2]
        return position, jnp.arctan2(jnp.linalg.norm(jnp.cross(t, target.direction)), t @ target.direction)
    return position, jnp.zeros(())


def _wrap(angle):
    return (angle + jnp.pi) % (2 * jnp.pi) - jnp.pi


def objective_value(sol: Solution, C, act: Actuation, prob: Problem, plan: Plan):
    """phi in its physical unit: compliance along the direction [m/N] (or the largest eigenvalue of
    its symmetric part), total squared tension [N^2], squared distance from the preferred
    insertion [m^2], or the user's callable of (Solution, Actuation)."""
    if plan.objective == "stiffness":
        CM = C[:3, :3]
        d = prob.direction
        along = d @ CM @ d
        largest = jnp.linalg.eigvalsh((CM + CM.T) / 2)[-1]
        return jnp.where(jnp.all(jnp.isfinite(d)), along, largest)
    if plan.objective == "tension":
        return jnp.sum(jnp.asarray(act.tensions) ** 2)
    if plan.objective == "insertion":
        insertion = act.insertion if isinstance(act, Actuation) else act.insertions[0]  # one tube (checked)
        return (insertion - prob.preferred_insertion) ** 2
    return plan.objective(sol, act)


class Evaluation(NamedTuple):
    """A converged forward solve at v and what the IK needs of it."""

    e: jax.Array  # task residual
    G: jax.Array  # de/dv
    phi: jax.Array  # objective (0 without one)
    dphi: jax.Array  # d phi / dv
    wrench: jax.Array  # base wrench, the next solve's start
    code: jax.Array  # the forward solve's status code


def evaluate(v, guess, prob: Problem, plan: Plan) -> Evaluation:
    """Forward solve at v (from ``guess``) with the task residual, the objective and their exact
    derivatives in v (forward mode through the implicitly differentiated root). Only the root and
    one integration to the tip are differentiated: a user's objective, which sees the whole
    Solution, adds the path."""

    def f(v):
        act = actuation_of(v, prob, plan)
        problem = (prob.robot, act, prob.load, prob.gravity)
        F_c = force_scale(*problem)
        if callable(plan.objective):
            sol = solution_and_compliance(*problem, guess, prob.solver)[0]
            x, code, p, R = scaled(prob.robot, _wrench(sol, act), F_c), sol.result, sol.tip_position, sol.tip_rotation
        else:
            sol, (x, info) = None, root(*problem, guess, prob.solver)
            tip = shoot(*problem, prob.solver, x, F_c)[1]
            code, p, R = info.result, tip.p, tip.R
        e = task_residual(p, R, prob.target, prob.robot.length)
        C = compliance_at(*problem, prob.solver, x) if plan.objective == "stiffness" else None
        pulled = general.with_driven(act, x, F_c) if isinstance(act, GeneralActuation) else act  # the driven tensions found
        phi = jnp.zeros(()) if plan.objective is None else objective_value(sol, C, pulled, prob, plan)
        return (e, phi), (e, phi, unscaled(prob.robot, x, F_c), code)

    (G, dphi), (e, phi, wrench, code) = jax.jacfwd(f, has_aux=True)(v)
    return Evaluation(e, G, phi, dphi, wrench, code)


# ----------------------------------------------------------------------------- phase 1: reach


MU_START = 1e-3
"""Initial Levenberg-Marquardt damping (relative to the diagonal of G^T G)."""
MU_GIVE_UP = 1e10
"""Damping at which a phase stops: no step it could take lowers its merit."""
KKT_TOL = 1e-7
"""Phase 2 has converged on the target when the projected gradient of the Lagrangian is below this
relative to the objective's gradient (``_kkt_residual``, scaled inputs)."""
DRIFT = 1e-3
"""Phase 2 takes no step whose task residual exceeds this (about 0.16 mm of position on the
default robot) unless it is already further away: the exact penalty alone lets a large step trade
the target for the objective where the reachable set is thin."""
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


class Reach(NamedTuple):
    v: jax.Array
    wrench: jax.Array
    e: jax.Array
    steps: jax.Array
    code: jax.Array  # SUCCESS (reached), UNREACHABLE (stationary above tol), or a failure code


def _unset(f, *args):
    """Zeros shaped like f(*args) (no evaluation): the loop state before the start is evaluated."""
    return jax.tree.map(lambda a: jnp.zeros(a.shape, a.dtype), jax.eval_shape(f, *args))


def _where(keep, new, old):
    return jax.tree.map(lambda a, b: jnp.where(keep, a, b), new, old)


def reach_nested(v0, wrench0, prob: Problem, plan: Plan, tol, max_steps) -> Reach:
    """Phase 1 with a converged forward solve (implicitly differentiated) at every trial. The
    loop's first pass evaluates the start, so the evaluation is compiled once."""

    def cond(c):
        return ~c[-1]

    def body(c):
        v, ev, s, mu, nu, it, code, _ = c
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
        return v, ev, s, mu, nu, it + 1, jnp.where(solved, code, ev.code), done | ~solved

    start = _unset(lambda v: evaluate(v, wrench0, prob, plan), v0)._replace(wrench=wrench0)
    init = (v0, start, jnp.zeros_like(v0), jnp.asarray(MU_START), jnp.asarray(2.0), 0, jnp.int32(status.OUTER_LIMIT), False)
    v, ev, _, _, _, it, code, _ = lax.while_loop(cond, body, init)
    return Reach(v, ev.wrench, ev.e, it - 1, code)


def reach_augmented(v0, wrench0, prob: Problem, plan: Plan, tol, max_steps) -> Reach:
    """Phase 1 on the shooting unknowns x and the inputs v together: each step is Newton on the
    tip boundary residual r(x, v) = 0 with Gauss-Newton on e for v, from one forward-mode
    Jacobian pass of (r, e) in (x, v); x is eliminated, so the bounded step is taken in v alone.
    ``wrench0`` must be the converged base wrench at v0. The loop's first pass linearises at the
    start, so the Jacobian pass is compiled once."""
    robot, L = prob.robot, prob.robot.length
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
        return F, (dx0, K, Ev + Ex @ K, e + Ex @ dx0)

    def merit(F):
        return jnp.where(jnp.all(jnp.isfinite(F)), F @ F, jnp.inf)

    def cond(c):
        return ~c[-1]

    def body(c):
        z, F, lin, s, mu, nu, it, code, _ = c
        first = it == 0
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
        code, done = _reach_status(F[n:], lin[2], z[n:], mu, it, prob, tol, max_steps, stalled)
        # reached only with the boundary residual converged too; stationary (UNREACHABLE) once it is
        # near enough for the closing forward solve to converge from here
        r = jnp.max(jnp.abs(F[:n]))
        code = jnp.where((code == status.SUCCESS) & (r > prob.solver.tol), jnp.int32(status.OUTER_LIMIT), code)
        code = jnp.where((code == status.UNREACHABLE) & (r > jnp.sqrt(prob.solver.tol)), jnp.int32(status.OUTER_LIMIT), code)
        done = done & ((code != status.OUTER_LIMIT) | (it >= max_steps) | (mu >= MU_GIVE_UP))
        s = _lm_step(lin[2], lin[3], mu, prob.lo - z[n:], prob.hi - z[n:])
        return z, F, lin, s, mu, nu, it + 1, code, done

    z0 = jnp.concatenate([scaled(robot, wrench0, F_s), v0])
    F0, lin0 = _unset(linearise, z0)
    init = (z0, F0, lin0, jnp.zeros_like(v0), jnp.asarray(MU_START), jnp.asarray(2.0), 0, jnp.int32(status.OUTER_LIMIT), False)
    z, F, _, _, _, _, it, code, _ = lax.while_loop(cond, body, init)
    return Reach(z[n:], unscaled(robot, z[:n], F_s), F[n:], it - 1, code)


# ----------------------------------------------------------------------------- phase 2: optimise


def optimise(v0, wrench0, prob: Problem, plan: Plan, tol, max_steps) -> Reach:
    """Phase 2: min phi(v) subject to e(v) = 0 and the bounds, by SQP (damped BFGS Hessian of the
    Lagrangian, exact active-set subproblems, l1 merit phi / phi_0 + rho |e|_1, and no step that
    leaves the task further than ``DRIFT``). The loop's first pass evaluates the start (phi_0
    there), so the evaluation is compiled once."""
    n = v0.shape[0]

    def merit(ev, scale, rho):
        ok = jnp.all(jnp.isfinite(ev.e)) & (ev.code == status.SUCCESS)
        return jnp.where(ok, ev.phi / scale + rho * jnp.sum(jnp.abs(ev.e)), jnp.inf)

    def cond(c):
        return ~c[-1]

    def body(c):
        v, ev, kkt, H, s, lam, scale, rho, mu, corrected, it, code, _ = c
        first = it == 0
        trial = evaluate(v + s, ev.wrench, prob, plan)
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
        code = jnp.where(
            converged, status.SUCCESS, jnp.where(mu >= MU_GIVE_UP, status.CONTINUATION_EXHAUSTED, status.OUTER_LIMIT)
        )
        done = converged | failed | (it >= max_steps) | (mu >= MU_GIVE_UP)
        return v, ev, kkt, H, s, lam, scale, rho, mu, correct, it + 1, jnp.where(failed, ev.code, code).astype(jnp.int32), done

    start = _unset(lambda v: evaluate(v, wrench0, prob, plan), v0)._replace(wrench=wrench0)
    m = prob.target.size
    zero = jnp.zeros_like(v0)
    init = (
        v0,
        start,
        jnp.asarray(jnp.inf),
        jnp.eye(n),
        zero,
        jnp.zeros(m),
        1.0,
        jnp.asarray(1.0),
        jnp.asarray(0.0),
        False,
        0,
        jnp.int32(status.OUTER_LIMIT),
        False,
    )
    v, ev, *_, it, code, _ = lax.while_loop(cond, body, init)
    return Reach(v, ev.wrench, ev.e, it - 1, code)


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


# ----------------------------------------------------------------------------- the solve and its derivatives


def default_start(prob: Problem, plan: Plan, p, force):
    """A start from the target position p [m] alone: the circular arc from the base (tangent +z)
    through p, less the sag that the tip force [N] and the robot's weight would cause on their own
    (a linear cantilever estimate), fixes a bending angle; the tendons on that side pull with the
    tension whose moment bends the silicone so far, no tube. A GeneralRobot: its first section's
    stiffness and density, every tendon as if anchored at the tip; free displacement-driven tendons
    start at the displacement ``prob.base`` gives."""
    robot = prob.robot
    L, (EI, rho, angles, offsets) = robot.length, _arc_parameters(robot)
    sag = (force * L**3 / 3 + rho * prob.gravity * L**4 / 8) / EI
    sag = sag * jnp.minimum(1.0, 0.5 * L / jnp.maximum(jnp.linalg.norm(sag[:2]), 1e-300))
    x, y = p[0] - sag[0], p[1] - sag[1]
    angle = 2 * jnp.arctan2(jnp.hypot(x, y), jnp.maximum(p[2], 0.0))
    share = jnp.maximum(jnp.cos(angles - jnp.arctan2(y, x)), 0.0)
    tensions = angle / L * EI * share / jnp.maximum(jnp.sum(share**2), 1e-12) / offsets
    k = len(plan.tendons)
    if isinstance(prob.base, Actuation):
        v = [tensions[jnp.asarray(plan.tendons)] / prob.tension_scale] if plan.tendons else []
        if plan.tubes:
            v.append(jnp.reshape(prob.lo[-1], (1,)))
        v = jnp.concatenate(v)
    else:
        base = prob.base
        v = scaled_inputs(GeneralActuation._rebuild(tensions, base.insertions, base.displacements, base.driven), prob, plan)
        v = v.at[k:].set(prob.lo[k:])
    return jnp.clip(v, prob.lo, prob.hi)


def _arc_parameters(robot):
    """(bending stiffness [N m^2], linear density [kg/m], tendon angles [rad], offsets [m]) for
    ``default_start``: a Robot's silicone, a GeneralRobot's first section (no channels)."""
    if isinstance(robot, Robot):
        return (
            robot.bending_stiffness(False)[0],
            robot.linear_density(False),
            jnp.asarray(robot.tendon_angles),
            robot.tendon_offset,
        )
    sec = robot.sections[0]
    D, d = sec.outer_diameter, sec.inner_diameter
    angles, offsets = (jnp.stack([jnp.asarray(getattr(t, k), float) for t in robot.tendons]) for k in ("angle", "offset"))
    return sec.E * jnp.pi / 64 * (D**4 - d**4), sec.density * jnp.pi / 4 * (D**2 - d**2), angles, jnp.maximum(offsets, 1e-300)


class Found(NamedTuple):
    v: jax.Array
    wrench: jax.Array
    steps: jax.Array
    code: jax.Array


def starts(v0, prob: Problem, plan: Plan):
    """Where phase 1 starts: v0, then, should it end short of the target, fresh starts in turn:
    no tension with the tube out and in, a quarter of the tension range everywhere with half the
    tube, and the arc start (``default_start``) with the tube in."""
    lo, hi = prob.lo, prob.hi
    k = len(plan.tendons)

    def with_insertion(v, where):
        return v.at[k:].set(lo[k:] + where * (hi[k:] - lo[k:])) if plan.tubes else v

    quarter = lo + 0.25 * (hi - lo)
    arc = default_start(prob, plan, prob.target.position, _tip_force(prob.load))
    return jnp.stack(
        [v0, with_insertion(lo, 0.0), with_insertion(lo, 1.0), with_insertion(quarter, 0.5), with_insertion(arc, 1.0)]
    )


STARTS = 5
"""Phase 1's starts: the given one, then four fresh ones (``starts``)."""
CHUNK_SIZE = 64
"""Targets per compiled call of a batched IK on the CPU (other platforms: ``batch.CHUNK_SIZES``).
Targets that miss from their first start run again from every start, padded to this many lanes so
as to reuse the compiled program: a round trip over 1,000 targets took 81 s at 256 lanes against
55 s at 64 (tests/test_ik.py, compile included)."""


@functools.partial(jax.custom_jvp, nondiff_argnums=(4, 5, 6))
def find(prob: Problem, v0, wrench0, n_starts, plan: Plan, tol, max_steps) -> Found:
    """The IK solution in scaled inputs (see the module docstring), from v0 (and the converged or
    NaN base wrench there), then from ``starts`` until one reaches (the nearest pose of them all
    otherwise); its derivatives by implicit differentiation (``_find_jvp``)."""
    candidates = starts(v0, prob, plan)
    reach = reach_augmented if plan.method == "augmented" else reach_nested

    def cond(c):
        k, best, _ = c
        return (k < n_starts) & (best.code != status.SUCCESS)

    def body(c):
        k, best, steps = c
        v, guess = candidates[k], jnp.where(k == 0, wrench0, jnp.nan)
        problem = (prob.robot, actuation_of(v, prob, plan), prob.load, prob.gravity)
        x, info = root(*problem, guess, prob.solver)
        r = reach(v, unscaled(prob.robot, x, force_scale(*problem)), prob, plan, tol, max_steps)
        r = r._replace(code=jnp.where(info.result == status.SUCCESS, r.code, info.result))
        rank, best_rank = (
            jnp.where(x.code == status.SUCCESS, 0, jnp.where(x.code == status.UNREACHABLE, 1, 2)) for x in (r, best)
        )
        closer = (rank < best_rank) | ((rank == best_rank) & (r.e @ r.e < best.e @ best.e))
        return k + 1, jax.tree.map(lambda a, b: jnp.where(closer, a, b), r, best), steps + r.steps

    none = Reach(v0, jnp.full(jnp.shape(wrench0), jnp.nan), jnp.full(prob.target.size, jnp.inf), 0, jnp.int32(status.OUTER_LIMIT))
    _, r, steps = lax.while_loop(cond, body, (0, none, 0))
    r = r._replace(steps=steps)
    if plan.objective is not None:
        o = optimise(r.v, r.wrench, prob, plan, tol, max_steps)
        use = r.code == status.SUCCESS
        r = jax.tree.map(lambda a, b: jnp.where(use, a, b), Reach(o.v, o.wrench, o.e, r.steps + o.steps, o.code), r)
    return Found(r.v, r.wrench, r.steps, r.code)


@find.defjvp
def _find_jvp(plan, tol, max_steps, primals, tangents):
    """Implicit differentiation of the optimality conditions at the solution: inputs at a bound
    follow the bound; the others keep e = 0 (the minimum-norm change when the task does not fix
    them) or, with an objective, the KKT conditions grad phi + G^T lam = 0, e = 0."""
    prob, v0, wrench0, n_starts = primals
    dprob = tangents[0]
    found = find(prob, v0, wrench0, n_starts, plan, tol, max_steps)
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
    zero = jax.tree.map(_zero_like, (wrench, found.steps, found.code))
    return found, Found(dv, *zero)


def _zero_like(x):
    x = jnp.asarray(x)
    return jnp.zeros_like(x) if jnp.issubdtype(x.dtype, jnp.inexact) else np.zeros(x.shape, jax.dtypes.float0)


# ----------------------------------------------------------------------------- entry points


@functools.partial(jax.jit, static_argnames=("plan", "tol", "max_steps"))
def _solve_ik(prob: Problem, v0, wrench0, plan: Plan, *, tol, max_steps, n_starts=STARTS):
    """``find``, then the forward solve there and the result's numbers; (IKResult, wrench)."""
    found = find(prob, v0, wrench0, n_starts, plan, tol, max_steps)
    act = actuation_of(found.v, prob, plan)
    sol, C = solution_and_compliance(prob.robot, act, prob.load, prob.gravity, found.wrench, prob.solver)
    if isinstance(act, GeneralActuation):  # the driven tendons' tensions as found
        act = GeneralActuation._rebuild(sol.tensions, act.insertions, act.displacements, act.driven)
    position, orientation = pose_errors(sol.tip_position, sol.tip_rotation, prob.target)
    phi = jnp.nan if plan.objective is None else objective_value(sol, C, act, prob, plan)
    code = jnp.where(sol.result == status.SUCCESS, found.code, sol.result).astype(jnp.int32)
    return IKResult(act, sol, position, orientation, jnp.asarray(phi, float), found.steps, code), _wrench(sol, act)


def inverse_kinematics(
    robot: Robot | GeneralRobot,
    target,
    *,
    load: TipLoad | Loads | None = None,
    tendons=None,
    tubes=None,
    insertion=None,
    bounds: Bounds = DEFAULT_BOUNDS,
    objective=None,
    direction=None,
    preferred_insertion=None,
    guess: Actuation | GeneralActuation | None = None,
    method: str = "augmented",
    tol: float = TOL,
    max_steps: int = MAX_STEPS,
    gravity=STANDARD_GRAVITY,
    solver: SolverOptions = DEFAULT_SOLVER,
    throw: bool = True,
) -> IKResult:
    """Tensions and insertion that put the tip at ``target`` (paper Secs. V.A, V.B; module docstring).

    Args:
        robot: the paper's ``Robot`` or any ``GeneralRobot``.
        target: a Target (or a tip position [m], (3,)); a leading batch axis on its fields solves
            many targets at once (``jax.vmap``).
        load: tip force [N] and moment [N m], world frame, held while reaching; none by default.
            For a GeneralRobot also ``Loads`` (one for every target).
        tendons: the free tendons, numbered from 1 like the paper (a GeneralRobot's tendon i + 1
            is its ``tendons[i]``): a number or a sequence (default all); the others keep the
            tension ``guess`` gives them (default 0). A tendon that ``guess`` (a GeneralActuation)
            lists in ``driven`` is free in its displacement, its tension found by the solve.
        tubes: a GeneralRobot's free tubes, numbered from 1 (default all); the others keep the
            depth ``guess`` gives them (default 0).
        insertion: None (free) or a fixed insertion depth [m] (a GeneralRobot: every tube's, one
            depth or one per tube).
        bounds: Bounds on the free tensions [N], insertions [m] and displacements [m]; never
            violated (a driven tendon's tension is not bounded).
        objective: among redundant solutions (free inputs beyond the task's dimensions), the one
            that minimises "stiffness" (the tip compliance along ``direction`` [m/N], or without a
            direction the largest eigenvalue of its symmetric part), "tension" (total squared
            tension: no needless co-contraction), "insertion" (squared distance from
            ``preferred_insertion`` [m], default L / 2; one free tube), or a callable f(Solution, Actuation) ->
            scalar, differentiable. None: the first solution found. With no more free inputs
            than task coordinates there is nothing to choose: a ValueError says so.
        direction: world direction for the "stiffness" objective, (3,), nonzero.
        preferred_insertion: for the "insertion" objective [m], in [0, L].
        guess: an Actuation (a GeneralRobot: a GeneralActuation) to start from (free inputs) and
            to take the fixed inputs from.
        method: "augmented" (shooting unknowns and inputs iterated together) or "nested"
            (a converged forward solve at every step).
        tol: tolerance on the scaled task residual (position error / L; orientation error [rad]).
        max_steps: most IK steps, both phases together (the IK's own limit).
        gravity, solver: as for ``tdct.solve``.
        throw: raise ConvergenceError when the IK failed (not for UNREACHABLE: an unreachable
            target is an answer, the nearest pose); default True, as everywhere.

    Returns:
        IKResult.
    """
    prob, plan, v0, wrench0 = _problem(**_arguments(**locals()))
    run = functools.partial(_solve_ik, tol=float(tol), max_steps=int(max_steps))
    if jnp.ndim(prob.target.position) == 2:
        result = _batched(run, prob, plan, v0, wrench0)
    else:
        result, _ = run(prob, v0, wrench0, plan)
    _check(result, throw, max_steps)
    return result


def _batched(run, prob: Problem, plan: Plan, v0, wrench0) -> IKResult:
    """Many targets (a leading axis on ``prob.target``, and on ``prob.load`` when it has one).
    With concrete values they run through the batch engine in chunks, each target from its first
    start only; those that did not reach run again from every start, so that a few hard targets
    do not hold up the rest. Traced (inside the caller's jit or vmap): one vmap, every start."""
    loads = jnp.ndim(_tip_force(prob.load)) == 2
    per = (prob.target, prob.load if loads else None)
    if not all(is_concrete(x) for x in jax.tree.leaves((prob, v0))):
        return jax.vmap(lambda per, v: run(_one(prob, per), v, wrench0, plan)[0])(per, v0)
    leaves, tree = jax.tree.flatten(per)
    own = tuple(i for i, leaf in enumerate(leaves) if np.ndim(leaf) >= 1)  # the rest (weights) are shared
    points = {f"in{i}": np.asarray(leaves[i]) for i in own} | {"v0": np.asarray(v0)}
    kernel = Kernel(_ik_point, (("plan", plan), ("tree", tree), ("own", own)) + tuple(run.keywords.items()))
    base = (prob._replace(target=None, load=None if loads else prob.load), wrench0, leaves)
    chunk = CHUNK_SIZE if jax.default_backend() == "cpu" else default_chunk_size()
    out = run_batched(kernel, base, points | {"starts": np.ones(len(v0), np.int32)}, chunk_size=chunk, progress=False)
    again = np.flatnonzero(out[".result"] != status.SUCCESS)
    if again.size:  # padded to the first pass's chunk, whose compiled program it reuses
        rows = np.concatenate([again, np.full(max(lanes_per_call(len(v0), chunk) - again.size, 0), again[-1])])
        retry = {k: v[rows] for k, v in points.items()} | {"starts": np.full(rows.size, STARTS, np.int32)}
        for k, v in run_batched(kernel, base, retry, chunk_size=chunk, progress=False).items():
            out[k][again] = v[: again.size]
    shape = jax.eval_shape(
        lambda: run(_one(prob, jax.tree.map(lambda a: a[0] if jnp.ndim(a) else a, per)), v0[0], wrench0, plan)[0]
    )
    paths, tree = jax.tree_util.tree_flatten_with_path(shape)
    return jax.tree.unflatten(tree, [jnp.asarray(out[jax.tree_util.keystr(path)]) for path, _ in paths])


def _one(prob: Problem, per) -> Problem:
    """The problem of one target of a batch: its target, and its load where each has its own."""
    target, load = per
    return prob._replace(target=target, load=prob.load if load is None else load)


def _ik_point(base, point, kernel: Kernel) -> dict:
    prob, wrench0, leaves = base
    own = kernel.option("own")
    leaves = [point[f"in{i}"] if i in own else leaf for i, leaf in enumerate(leaves)]
    prob = _one(prob, jax.tree.unflatten(kernel.option("tree"), leaves))
    options = dict(tol=kernel.option("tol"), max_steps=kernel.option("max_steps"), n_starts=point["starts"])
    result = _solve_ik(prob, point["v0"], wrench0, kernel.option("plan"), **options)[0]
    return {jax.tree_util.keystr(path): leaf for path, leaf in jax.tree_util.tree_flatten_with_path(result)[0]}


def track(robot: Robot, targets: Target, **options) -> IKResult:
    """Inverse kinematics along a sequence of targets (a Target whose fields have a leading axis),
    each started from the last solution, as one compiled ``lax.scan``: the real-time control case.

    Args:
        robot, targets: the robot and the targets in order (at least one; a Target, or tip
            positions [m] of shape (n, 3)).
        **options: as for ``inverse_kinematics`` (``guess`` starts the first step).

    Returns:
        IKResult with a leading axis over the targets.
    """
    throw = options.pop("throw", True)
    targets = targets if isinstance(targets, Target) else Target(targets)
    if is_concrete(targets.position) and (np.ndim(targets.position) != 2 or len(targets.position) == 0):
        raise ValueError(
            f"targets: track needs at least one target, a Target whose position has shape (n, 3) with n >= 1, "
            f"got shape {np.shape(targets.position)}"
        )
    leaves, tree = jax.tree.flatten(targets)
    own = tuple(i for i, leaf in enumerate(leaves) if jnp.ndim(leaf) >= 1)  # the rest (weights) are shared
    first = jax.tree.unflatten(tree, [leaf[0] if i in own else leaf for i, leaf in enumerate(leaves)])
    args = _arguments(robot, first, **options)
    prob, plan, v0, wrench0 = _problem(**args)
    tol, max_steps = float(args["tol"]), int(args["max_steps"])
    result = _track(prob, leaves, v0, wrench0, plan, tol, max_steps, tree, own)
    _check(result, throw, max_steps)
    return result


@functools.partial(jax.jit, static_argnames=("plan", "tol", "max_steps", "tree", "own"))
def _track(prob, leaves, v0, wrench0, plan, tol, max_steps, tree, own):
    def step(carry, xs):
        v, wrench = carry
        target = jax.tree.unflatten(tree, [xs[own.index(i)] if i in own else leaf for i, leaf in enumerate(leaves)])
        result, wrench_new = _solve_ik(prob._replace(target=target), v, wrench, plan, tol=tol, max_steps=max_steps)
        ok = result.result == status.SUCCESS
        v_new = scaled_inputs(result.actuation, prob, plan)
        return (jnp.where(ok, v_new, v), jnp.where(ok, wrench_new, wrench)), result

    return lax.scan(step, (v0, wrench0), [leaves[i] for i in own])[1]


def describe_task(target: Target) -> str:
    """The task coordinates of a target in words, e.g. "x, y, z and the tip angle"."""
    extra = {None: "", "direction": " and the tip direction (2)", "tip_angle": " and the tip angle"}[target.orientation]
    return ", ".join(target.axes) + extra


def _arguments(*args, **kwargs) -> dict:
    """``inverse_kinematics``'s arguments but ``throw``, bound to its signature, defaults filled."""
    bound = inspect.signature(inverse_kinematics).bind(*args, **kwargs)
    bound.apply_defaults()
    return {name: value for name, value in bound.arguments.items() if name != "throw"}


def _check(result: IKResult, throw: bool, max_steps: int) -> None:
    """``throw`` for everything but UNREACHABLE, which is an answer."""
    code = jnp.where(result.result == status.UNREACHABLE, status.SUCCESS, result.result)
    status.check(code, throw=throw, what="the inverse kinematics", max_steps=max_steps)


def _problem(
    robot,
    target,
    *,
    load,
    tendons,
    tubes,
    insertion,
    bounds,
    objective,
    direction,
    preferred_insertion,
    guess,
    method,
    tol,
    max_steps,
    gravity,
    solver,
):
    """Checks the arguments; returns (Problem, Plan, start v0, start unknowns (NaN))."""
    if not isinstance(target, Target):
        target = Target(target)
    is_general = isinstance(robot, GeneralRobot)
    batched = jnp.ndim(target.position) == 2
    n_t, n_tubes = robot.n_tendons, robot.n_tubes if is_general else 1
    L = float(robot.length) if is_concrete(robot.length) else robot.length
    if is_general:
        load = Loads.of(load)
        base = GeneralActuation(np.zeros(n_t), np.zeros(n_tubes)) if guess is None else GeneralActuation.of(guess, n_tubes)
        general.check_arguments(robot, base, load, solver)
    else:
        load = TipLoad() if load is None else load
        base = Actuation(np.zeros(n_t)) if guess is None else guess
        check_inputs(robot, base, load, solver, batch=batched)
    typed = tendons
    if tendons is None:
        tendons = tuple(range(1, n_t + 1))
    elif isinstance(tendons, (int, np.integer)):
        tendons = (tendons,)  # one tendon
    elif isinstance(tendons, (tuple, list, np.ndarray)):
        tendons = tuple(tendons)
    for t in tendons if isinstance(tendons, tuple) else (None,):
        if isinstance(t, bool) or not isinstance(t, (int, np.integer)) or not 1 <= t <= n_t:
            where = f"tendons[0] to tendons[{n_t - 1}] of the robot" if is_general else "tendon 1 at body +y"
            raise ValueError(f"tendons = {typed!r}: a tendon number or a sequence of them, each in [1, {n_t}] ({where})")
    if len(set(tendons)) != len(tendons):
        raise ValueError(f"tendons = {tendons!r} names a tendon twice")
    tubes = _free_tubes(tubes, insertion, n_tubes, is_general)
    if insertion is not None:
        shape = (n_tubes,) if is_general and np.ndim(insertion) == 1 else ()
        insertion = as_array("insertion", insertion, shape, unit=" m")
        check_range("insertion", insertion, 0.0, L, unit=f" m (0 to the robot length {float(L):g} m)") if is_concrete(L) else None
        if is_general:
            depths = jnp.broadcast_to(insertion, (n_tubes,))
            base = GeneralActuation._rebuild(base.tensions, depths, base.displacements, base.driven)
        else:
            base = Actuation(base.tensions, insertion)
    if not tendons and not tubes:
        raise ValueError("nothing is free: give at least one free tendon (tendons=) or leave a tube's insertion free")
    if not isinstance(bounds, Bounds):
        raise TypeError(f"bounds must be a tdct.Bounds, got {type(bounds).__name__}")
    ins_bounds = (0.0, L) if bounds.insertion is None else bounds.insertion
    if bounds.insertion is not None and is_concrete(bounds.insertion):
        check_range("bounds.insertion", bounds.insertion, 0.0, float(L), unit=f" m (0 to the robot length {float(L):g} m)")
    if objective is not None and not callable(objective):
        check_choice("objective", objective, OBJECTIVES)
    if objective == "insertion" and len(tubes) != 1:
        raise ValueError(
            f"objective = 'insertion': needs exactly one free tube, got tubes {tuple(t + 1 for t in tubes)} "
            f"of a robot with {n_tubes} tube(s)"
        )
    if direction is not None:
        direction = as_array("direction", direction, (3,))
        if is_concrete(direction) and not np.linalg.norm(direction) > 0:
            raise ValueError("direction = [0, 0, 0]: the stiffness direction must be a nonzero vector")
        direction = direction / jnp.linalg.norm(direction)
    preferred = 0.5 * L if preferred_insertion is None else as_array("preferred_insertion", preferred_insertion, (), unit=" m")
    if preferred_insertion is not None and is_concrete(preferred):
        check_range("preferred_insertion", preferred, 0.0, float(L), unit=" m")
    check_choice("method", method, METHODS)
    tol = as_array("tol", tol, ())
    check_range("tol", tol, 0.0, lo_open=True)
    check_integer("max_steps", max_steps)
    if is_concrete(target.position) and is_concrete(L):
        note = target_note("target position", np.asarray(target.position)[..., [AXES.index(a) for a in target.axes]], float(L))
        if note:
            warn_user(note, UnitWarning)
    free = len(tendons) + len(tubes)
    if objective is not None and free <= target.size:
        inputs = (
            f"tendons {tendons}, tubes {tuple(t + 1 for t in tubes)}"
            if is_general
            else (f"tendons {tendons}{'; the insertion fixed' if not tubes else ' and the insertion'}")
        )
        raise ValueError(
            f"objective = {getattr(objective, '__name__', objective)!r}: nothing to choose: {free} free input(s) "
            f"({inputs}) for {target.size} task "
            f"coordinate(s) ({describe_task(target)}); an objective picks among solutions only with more free inputs "
            "than task coordinates: free more tendons (tendons=), leave the insertion free, or give fewer target axes "
            "(Target(..., axes=...))"
        )
    plan = Plan(tuple(t - 1 for t in tendons), tubes, objective, method)
    scale = jnp.maximum(jnp.asarray(bounds.tension[1]), 1.0)
    lo, hi = _input_bounds(robot, base, plan, bounds, ins_bounds, scale)
    prob = Problem(
        robot=robot,
        target=target,
        load=load,
        gravity=jnp.asarray(gravity_vector(gravity)),
        base=base,
        lo=lo,
        hi=hi,
        tension_scale=scale,
        solver=solver,
        preferred_insertion=jnp.asarray(preferred, float),
        direction=jnp.full(3, jnp.nan) if direction is None else jnp.asarray(direction, float),
    )
    if guess is None:
        forces = jnp.broadcast_to(jnp.asarray(_tip_force(load)), jnp.shape(target.position))
        start = (
            jax.vmap(lambda p, f: default_start(prob, plan, p, f))(target.position, forces)
            if batched
            else default_start(prob, plan, target.position, _tip_force(load))
        )
    else:
        start = jnp.clip(scaled_inputs(base, prob, plan), prob.lo, prob.hi)
        start = jnp.broadcast_to(start, (len(target.position),) + start.shape) if batched else start
    return prob, plan, start, jnp.full(6 + len(getattr(base, "driven", ())), jnp.nan)


def _free_tubes(tubes, insertion, n_tubes: int, is_general: bool) -> tuple:
    """The free tubes, 0-based, from ``tubes=`` (numbered from 1; default all unless ``insertion``
    fixes them)."""
    if tubes is None:
        return () if insertion is not None else tuple(range(n_tubes))
    if not is_general:
        raise ValueError(
            f"tubes = {tubes!r}: a tdct.Robot's one tube is free unless insertion= fixes it; tubes= is for a GeneralRobot"
        )
    if insertion is not None:
        raise ValueError(f"tubes = {tubes!r} and insertion = {insertion!r}: give one (insertion= fixes every tube)")
    typed = tubes
    tubes = (
        (tubes,)
        if isinstance(tubes, (int, np.integer))
        else tuple(tubes)
        if isinstance(tubes, (tuple, list, np.ndarray))
        else (None,)
    )
    for t in tubes:
        if isinstance(t, bool) or not isinstance(t, (int, np.integer)) or not 1 <= t <= n_tubes:
            where = (
                f"each in [1, {n_tubes}] (tubes[0] to tubes[{n_tubes - 1}] of the robot)"
                if n_tubes
                else "but the robot has no tubes"
            )
            raise ValueError(f"tubes = {typed!r}: a tube number or a sequence of them, {where}")
    if len(set(tubes)) != len(tubes):
        raise ValueError(f"tubes = {tubes!r} names a tube twice")
    return tuple(t - 1 for t in tubes)


def _input_bounds(robot, base, plan: Plan, bounds: Bounds, ins_bounds, scale):
    """Bounds (lo, hi) of v: tensions over ``scale`` (each capped by its tendon's ``max_tension``
    on a GeneralRobot), displacements over DISPLACEMENT_SCALE L, insertions over L."""
    L, k = robot.length, len(plan.tendons)
    lo, hi = jnp.full(k, bounds.tension[0]) / scale, jnp.full(k, bounds.tension[1]) / scale
    if isinstance(robot, GeneralRobot):
        pulled, moved, _ = _split(base, plan)
        for j in pulled:
            cap = robot.tendons[plan.tendons[j]].max_tension
            if cap is None:
                continue
            if is_concrete(cap) and is_concrete(bounds.tension) and float(cap) < float(bounds.tension[0]):
                i = plan.tendons[j]
                raise ValueError(
                    f"tendons[{i}].max_tension = {float(cap):g} N is below bounds.tension's lowest "
                    f"{float(bounds.tension[0]):g} N: lower bounds.tension or free another tendon"
                )
            hi = hi.at[j].set(jnp.minimum(bounds.tension[1], cap) / scale)
        if moved:
            width = DISPLACEMENT_SCALE * L
            d_lo, d_hi = (-width, width) if bounds.displacement is None else bounds.displacement
            lo, hi = lo.at[np.array(moved)].set(d_lo / width), hi.at[np.array(moved)].set(d_hi / width)
    n = len(plan.tubes)
    lo = jnp.concatenate([lo, jnp.full(n, ins_bounds[0] / L)])
    hi = jnp.concatenate([hi, jnp.full(n, ins_bounds[1] / L)])
    return lo, hi
