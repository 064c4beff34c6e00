"""Shooting: the tip residual, a globalised Newton loop, implicit differentiation, and solve()."""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from ._checks import as_array, check_range, is_concrete
from .integrate import rk4
from .loads import STANDARD_GRAVITY, Actuation, TipLoad
from .robot import Robot
from .segments import E3, Segment, State, paper_transition, rod_force, strains, vector_field
from .so3 import orthonormalize, rotation_columns, tip_angle

TRANSITIONS = ("balanced", "paper")
TENDON_MODELS = ("exact", "paper")
TOL = 1e-10
"""Default convergence threshold on the scaled tip residual (max norm)."""
MAX_ITER = 50
"""Default limit on Newton iterations."""
STEPS = 16
"""Default RK4 steps per segment."""


@dataclasses.dataclass(frozen=True)
class SolverOptions:
    """The discrete model (static: each distinct value compiles once).

    Attributes:
        steps: RK4 steps per segment (backbone [0, d] and silicone-only [d, L]).
        transition: "balanced" (total rod + tendon force and moment continuous at s = d) or
            "paper" (rod force and moment continuous, eqs. 31-32 as printed).
        tendon_model: tendon load in the backbone segment, "exact" (Rucker-Webster, tangents
            tilted by u x r_t) or "paper" (eqs. 21-22 as printed).
    """

    steps: int = STEPS
    transition: str = "balanced"
    tendon_model: str = "exact"

    def __post_init__(self):
        if not isinstance(self.steps, (int, np.integer)) or self.steps < 1:
            raise ValueError(f"steps = {self.steps!r} must be an integer >= 1")
        if self.transition not in TRANSITIONS:
            raise ValueError(f"transition = {self.transition!r} must be one of {TRANSITIONS}")
        if self.tendon_model not in TENDON_MODELS:
            raise ValueError(f"tendon_model = {self.tendon_model!r} must be one of {TENDON_MODELS}")


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Solution:
    """Static shape of the robot at the RK4 nodes (2 * steps + 1 of them, s = d appears once).

    Attributes:
        s: arc length of the undeformed robot [m], (n,).
        position: p(s) [m], world frame, (n, 3).
        rotation: R(s), body to world, (n, 3, 3).
        force, moment: the rod's internal force n(s) [N] and moment m(s) [N m], world frame.
        total_force, total_moment: rod plus tendons, N(s) and M(s); at s = 0 the load on the base.
        strain, curvature: v(s) and u(s) [1/m], body frame.
        residual: scaled tip residual (force rows, then moment rows), (6,).
        residual_norm: its max norm; converged: residual_norm <= tol; iterations: Newton steps.
    """

    s: jax.Array
    position: jax.Array
    rotation: jax.Array
    force: jax.Array
    moment: jax.Array
    total_force: jax.Array
    total_moment: jax.Array
    strain: jax.Array
    curvature: jax.Array
    residual: jax.Array
    residual_norm: jax.Array
    converged: jax.Array
    iterations: jax.Array

    @property
    def tip_position(self):
        """p(L) [m], (3,)."""
        return self.position[..., -1, :]

    @property
    def tip_rotation(self):
        """R(L), (3, 3)."""
        return self.rotation[..., -1, :, :]

    @property
    def base_wrench(self):
        """(N(0), M(0)): the total force and moment at the base, the shooting unknowns, (6,)."""
        return jnp.concatenate([self.total_force[..., 0, :], self.total_moment[..., 0, :]], axis=-1)

    @property
    def tip_angle(self):
        """theta_tip: the tip tangent's angle in the z-y plane from +z, toward +y [rad]."""
        return tip_angle(self.tip_rotation)


class ConvergenceError(RuntimeError):
    """The shooting iteration did not reach the tolerance (raised by solve(..., throw=True))."""


def segments(robot: Robot, act: Actuation, opts: SolverOptions) -> tuple[Segment, Segment]:
    """The backbone [0, d] and silicone-only [d, L] segments."""
    tau = jnp.asarray(act.tensions)
    r = robot.tendon_positions
    K_se = robot.shear_stiffness()
    back = Segment(K_se, robot.bending_stiffness(True), robot.linear_density(True), tau, r, True, opts.tendon_model == "exact")
    sil = Segment(K_se, robot.bending_stiffness(False), robot.linear_density(False), tau, r, False)
    return back, sil


def _scale(robot, act, load, gravity):
    """A typical force [N] that scales the residual: tensions, tip load and weight together.

    A constant for differentiation: it only reparametrises the unknowns.
    """
    robot, act, load, gravity = lax.stop_gradient((robot, act, load, gravity))
    weight = jnp.linalg.norm(gravity) * (robot.linear_density(False) * robot.length + robot.tube_linear_density * act.insertion)
    F = jnp.sum(act.tensions) + jnp.linalg.norm(load.force) + jnp.linalg.norm(load.moment) / robot.length + weight
    return jnp.maximum(F, 1e-3)


def _straight_guess(robot, act, load, gravity, F_c):
    """Base unknowns of the straight rod: exact in force, first-order in moment."""
    L, d = robot.length, act.insertion
    rho1, rho2 = robot.linear_density(False), robot.tube_linear_density
    N0 = load.force + gravity * (rho1 * L + rho2 * d)
    M0 = load.moment + jnp.cross(L * E3, load.force) + jnp.cross(E3, gravity) * (rho1 * L**2 + rho2 * d**2) / 2
    return jnp.concatenate([N0 / F_c, M0 / (F_c * L)])


def _integrate(robot, act, load, gravity, opts, x, F_c, path=False):
    """Shoots from base unknowns x (N(0), M(0) scaled by F_c) to the tip.

    Returns the residual and the tip state (with ``path``: the states at every node).
    """
    back, sil = segments(robot, act, opts)
    L, d = robot.length, act.insertion
    y0 = State(jnp.zeros(3), jnp.eye(3), x[:3] * F_c, x[3:] * F_c * L)

    def project(y):
        return y._replace(R=orthonormalize(y.R))

    def run(seg, y, s0, s1):
        return rk4(vector_field(seg, gravity), y, s0, s1, opts.steps, project, path)

    out_b = run(back, y0, 0.0, d)
    y_d = out_b[0] if path else out_b
    if opts.transition == "paper":
        jumped = paper_transition(back, sil, y_d)
        inside = (d > 0) & (d < L)
        y_d = jax.tree.map(lambda a, b: jnp.where(inside, a, b), jumped, y_d)
    out_s = run(sil, y_d, d, L)
    y_L = out_s[0] if path else out_s
    res = jnp.concatenate([(y_L.N - load.force) / F_c, (y_L.M - load.moment) / (F_c * L)])
    if not path:
        return res, y_L
    ys = jax.tree.map(lambda a, b: jnp.concatenate([a, b[1:]]), out_b[1], out_s[1])
    return res, ys


def _newton(F, x0, J0, tol, max_iter):
    """Levenberg-Marquardt-damped Newton on F(x)[0] = 0 with exact jacfwd Jacobians.

    F returns (residual, outputs): Newton also carries the Jacobian of the outputs (the tip pose),
    taken in the same forward pass. The damping mu shrinks tenfold after each step that lowers
    |F| and grows tenfold after each that does not, so the iteration is Newton's (quadratic) near
    the root and a short gradient step far from it. The first pass evaluates x0 itself, so the
    Jacobian code appears once in the compiled loop and the last Jacobians are at the root.
    J0 (zeros shaped like the Jacobians) only sets their shapes. Returns the root and (residual,
    Newton steps taken, (d residual / dx, d outputs / dx)).
    """

    def value_and_jac(x):
        def fr(x):
            out = F(x)
            return out, out[0]

        return jax.jacfwd(fr, has_aux=True)(x)

    def not_done(c):
        x, r, J, mu, it, x_try = c
        return (it == 0) | ((it <= max_iter) & (jnp.max(jnp.abs(r)) > tol))

    def body(c):
        x, r, J, mu, it, x_try = c
        J_try, r_try = value_and_jac(x_try)
        ok = jnp.all(jnp.isfinite(r_try)) & (jnp.sum(r_try**2) < jnp.sum(r**2))
        x, r, J = jax.tree.map(lambda new, old: jnp.where(ok, new, old), (x_try, r_try, J_try), (x, r, J))
        mu = jnp.where(ok, mu / 10, mu * 10)
        J_r = J[0]
        x_try = x - jnp.linalg.solve(J_r.T @ J_r + mu * jnp.eye(x.size), J_r.T @ r)
        return x, r, J, mu, it + 1, x_try

    init = (x0, jnp.full(x0.size, jnp.inf), J0, jnp.asarray(1e-5), 0, x0)
    x, r, J, _, it, _ = lax.while_loop(not_done, body, init)
    return x, (r, (it - 1).astype(x.dtype), J)  # float: the root's aux takes (zero) float tangents


STAGES = (1, 4, 16)
"""Load continuation: numbers of equal load stages tried in turn when Newton fails."""


def _continuation(F_at, x0, x_straight, tol, max_iter):
    """Solves F_at(1)(x)[0] = 0 from x0, ramping all loads in stages when plain Newton fails.

    F_at(lam) gives the residual (and outputs, see _newton) with tensions, tip load and gravity
    scaled by lam; the straight-rod guess is linear in the loads, so lam * x_straight starts each
    ramp. Returns (root, (residual, total Newton steps, the last Jacobians)).
    """
    n = x0.size
    J0 = jax.tree.map(lambda o: jnp.zeros(jnp.shape(o) + (n,)), jax.eval_shape(F_at(1.0), x0))

    def not_done(c):
        return ~c[-1]

    def body(c):
        x, r, it, J, K, stage, _ = c
        lam = stage / K
        guess = jnp.where(stage == 1, jnp.where(K == STAGES[0], x0, lam * x_straight), x)
        x_new, (r_new, it_new, J_new) = _newton(F_at(lam), guess, J0, tol, max_iter)
        ok = jnp.max(jnp.abs(r_new)) <= tol
        K_next = jnp.where(ok, K, K * (STAGES[1] // STAGES[0]))
        stage_next = jnp.where(ok, stage + 1, 1)
        done = (ok & (stage == K)) | (K_next > STAGES[-1])
        return x_new, r_new, it + it_new, J_new, K_next, stage_next, done

    init = (x0, jnp.full(n, jnp.inf), jnp.zeros((), x0.dtype), J0, STAGES[0], 1, False)
    x, r, it, J, *_ = lax.while_loop(not_done, body, init)
    return x, (r, it, J)


# The root's differentiable inputs (robot, act, load, gravity) travel as their leaves: custom_jvp
# builds zero tangents by unflattening, and a Robot of zeros would fail the Robot's own checks.
@functools.partial(jax.custom_jvp, nondiff_argnums=(4, 5))
def _root(leaves, tol, max_iter, guess, tree, opts: SolverOptions):
    """The scaled base unknowns x with a zero tip residual, and (Newton steps, Newton's last
    Jacobians: d residual / dx and d(tip p, tip R) / dx, taken at x)."""
    robot, act, load, gravity = jax.tree.unflatten(tree, leaves)
    F_c = _scale(robot, act, load, gravity)
    x_straight = _straight_guess(robot, act, load, gravity, F_c)
    x_warm = jnp.concatenate([guess[:3] / F_c, guess[3:] / (F_c * robot.length)])
    x0 = jnp.where(jnp.all(jnp.isfinite(guess)), x_warm, x_straight)

    def F_at(lam):
        act_lam = dataclasses.replace(act, tensions=lam * act.tensions)
        load_lam = TipLoad(lam * load.force, lam * load.moment)

        def F(x):
            res, tip = _integrate(robot, act_lam, load_lam, lam * gravity, opts, x, F_c)
            return res, (tip.p, tip.R)

        return F

    x, (_, iterations, J) = _continuation(F_at, x0, x_straight, tol, max_iter)
    return x, (iterations, J)


def _residual(leaves, x, tree, opts):
    robot, act, load, gravity = jax.tree.unflatten(tree, leaves)
    return _integrate(robot, act, load, gravity, opts, x, _scale(robot, act, load, gravity))[0]


@_root.defjvp
def _root_jvp(tree, opts, primals, tangents):
    """Implicit differentiation: dx = -J^-1 (d residual / d inputs) d inputs, with Newton's J."""
    leaves, tol, max_iter, guess = primals
    x, aux = _root(leaves, tol, max_iter, guess, tree, opts)
    J = _jacobian_at_root(leaves, x, aux[1][0], tree, opts)
    _, dF = jax.jvp(lambda leaves: _residual(leaves, x, tree, opts), (leaves,), (tangents[0],))
    return (x, aux), (-jnp.linalg.solve(J, dF), jax.tree.map(jnp.zeros_like, aux))


@functools.partial(jax.custom_jvp, nondiff_argnums=(3, 4))
def _jacobian_at_root(leaves, x, J, tree, opts):
    """J, Newton's d residual / dx at x, free; its own derivatives (second order) by autodiff."""
    return J


@_jacobian_at_root.defjvp
def _jacobian_at_root_jvp(tree, opts, primals, tangents):
    leaves, x, J = primals

    def jacobian(leaves, x):
        return jax.jacfwd(lambda x: _residual(leaves, x, tree, opts))(x)

    return J, jax.jvp(jacobian, (leaves, x), tangents[:2])[1]


@jax.jit(static_argnames=("opts",))
def shoot(robot, act, load, gravity, tol, max_iter, guess, opts: SolverOptions) -> tuple[Solution, jax.Array]:
    """The compiled solve: the Solution, and the 6x6 tip compliance d(tip position, tip rotation
    vector) / d(F_e, M_e) (eq. 41) from Newton's Jacobians at the root, for one 6x6 solve more.

    The compliance is exact in value but has no derivatives of its own (``tdct.compliance``
    supplies them). Unchecked: ``solve_arguments`` checks the arguments.
    """
    leaves, tree = jax.tree.flatten((robot, act, load, gravity))
    x, (iterations, (J_res, (J_p, J_R))) = _root(leaves, tol, max_iter, guess, tree, opts)
    F_c = _scale(robot, act, load, gravity)
    res, ys = _integrate(robot, act, load, gravity, opts, x, F_c, path=True)
    sol = _assemble(robot, act, opts, ys, res, tol, iterations.astype(jnp.int32))
    # The tip load enters only the residual: d res / d(F_e, M_e) = -diag(1 / F_c, 1 / (F_c L)).
    dx_dw = jnp.linalg.solve(J_res, jnp.diag(jnp.repeat(jnp.stack([1 / F_c, 1 / (F_c * robot.length)]), 3)))
    C = jnp.concatenate([J_p @ dx_dw, rotation_columns(J_R @ dx_dw, sol.tip_rotation)])
    return sol, C


def _node_quantities(back: Segment, sil: Segment, y: State, in_backbone):
    """Strains v, u and rod force n, m at one node, by the segment the node belongs to."""

    def with_segment(seg):
        v, u = strains(seg, y.R, y.N, y.M)
        return (v, u, *rod_force(seg, y, v, u))

    return jax.tree.map(lambda a, b: jnp.where(in_backbone, a, b), with_segment(back), with_segment(sil))


def _assemble(robot, act, opts, ys: State, res, tol, iterations) -> Solution:
    """Solution from the node states: strains and rod forces by each node's own segment."""
    back, sil = segments(robot, act, opts)
    n_b = opts.steps + 1
    d, L = act.insertion, robot.length
    s = jnp.concatenate([jnp.linspace(0.0, 1.0, n_b) * d, d + jnp.linspace(0.0, 1.0, n_b)[1:] * (L - d)])
    in_backbone = jnp.where(jnp.arange(s.size) < n_b, d > 0, d >= L)

    # lax.map: a vmap here, inside a sweep's vmap of 16 or more lanes, deadlocks XLA:CPU (jax 0.10.2).
    v, u, n, m = lax.map(lambda a: _node_quantities(back, sil, *a), (ys, in_backbone))
    r_norm = jnp.max(jnp.abs(res))
    return Solution(
        s=s,
        position=ys.p,
        rotation=ys.R,
        force=n,
        moment=m,
        total_force=ys.N,
        total_moment=ys.M,
        strain=v,
        curvature=u,
        residual=res,
        residual_norm=r_norm,
        converged=r_norm <= tol,
        iterations=iterations,
    )


def solve(
    robot: Robot,
    act: Actuation,
    load: TipLoad | None = None,
    *,
    steps: int = STEPS,
    gravity=STANDARD_GRAVITY,
    transition: str = "balanced",
    tendon_model: str = "exact",
    tol: float = TOL,
    max_iter: int = MAX_ITER,
    guess=None,
    throw: bool = False,
) -> Solution:
    """Static shape of the TDCT robot (paper Sec. II; model-notes) by Newton shooting.

    The six unknowns are the total force and moment at the base, started from the straight rod.
    Derivatives of every output with respect to every input (robot fields, tensions, insertion,
    tip load, gravity) come from implicit differentiation of the converged root, so ``jax.grad``,
    ``jax.jacfwd`` and ``jax.vmap`` pass straight through.

    Args:
        robot: geometry and materials.
        act: tendon tensions [N] and tube insertion depth [m].
        load: tip force [N] and moment [N m] in the world frame; none by default.
        steps: RK4 steps per segment.
        gravity: world gravity [m/s^2]; None or zeros switch the robot's weight off.
        transition: "balanced" (default) or "paper", see SolverOptions.
        tendon_model: "exact" (default) or "paper", see SolverOptions.
        tol: tolerance on the scaled tip residual.
        max_iter: most Newton iterations per load stage (see STAGES; ``sol.iterations`` counts all).
        guess: base force and moment (N(0) [N], M(0) [N m]), shape (6,), to start Newton from,
            e.g. a neighbouring solution's ``base_wrench``; None starts from the straight rod.
        throw: raise ConvergenceError if the solve did not converge (needs concrete values).

    Returns:
        Solution; check ``converged`` unless ``throw`` is set.

    Raises:
        ValueError: bad input (names field, value and allowed range).
        ConvergenceError: with ``throw=True``, when the residual stays above ``tol``.
    """
    args, opts = solve_arguments(
        robot,
        act,
        load,
        steps=steps,
        gravity=gravity,
        transition=transition,
        tendon_model=tendon_model,
        tol=tol,
        max_iter=max_iter,
        guess=guess,
    )
    sol = shoot(*args, opts)[0]
    if throw:
        raise_if_failed(sol, tol, max_iter)
    return sol


def solve_arguments(
    robot,
    act,
    load=None,
    *,
    steps=STEPS,
    gravity=STANDARD_GRAVITY,
    transition="balanced",
    tendon_model="exact",
    tol=TOL,
    max_iter=MAX_ITER,
    guess=None,
) -> tuple[tuple, SolverOptions]:
    """Checks ``solve``'s arguments; returns the array arguments of ``shoot`` and its static options."""
    opts = solver_options(steps, transition, tendon_model, tol, max_iter)
    load = TipLoad() if load is None else load
    guess = jnp.full(6, jnp.nan) if guess is None else as_array("guess", guess, (6,))
    check_inputs(robot, act, load)
    gravity, guess = _on_cpu(gravity_vector(gravity), guess)
    return (robot, act, load, gravity, tol, max_iter, guess), opts


def _on_cpu(*arrays):
    """The arrays committed to the CPU where another backend (a GPU) is the default, so that the
    solve they enter runs there (jit runs where its committed arguments are; the pytrees' numpy
    leaves follow). One solve is a long chain of small operations, each a kernel launch on a GPU,
    and faster on the CPU. Traced arrays (the caller's jit or vmap, and so sweeps) stay as they are."""
    if jax.default_backend() == "cpu" or not all(is_concrete(a) for a in arrays):
        return arrays
    return jax.device_put(arrays, jax.local_devices(backend="cpu")[0])


def gravity_vector(gravity):
    """World gravity [m/s^2] as a (3,) array; None means none (the robot's weight switched off)."""
    return jnp.zeros(3) if gravity is None else jnp.asarray(as_array("gravity", gravity, (3,)), dtype=float)


def solver_options(steps, transition, tendon_model, tol, max_iter) -> SolverOptions:
    """Checks the solver settings; returns the static part."""
    check_range("tol", tol, 0.0, lo_open=True)
    if not isinstance(max_iter, (int, np.integer)) or max_iter < 1:
        raise ValueError(f"max_iter = {max_iter!r} must be an integer >= 1")
    return SolverOptions(steps=steps, transition=transition, tendon_model=tendon_model)


def nested_solve_options(solve_options: dict) -> dict:
    """All five keyword arguments for ``solve`` but gravity, checked, defaults filled in, from steps,
    transition, tendon_model, solve_tol and solve_max_iter: the options of a routine that runs
    solves inside an iteration of its own."""
    allowed = {"steps", "transition", "tendon_model", "solve_tol", "solve_max_iter"}
    unknown = set(solve_options) - allowed
    if unknown:
        raise TypeError(f"unknown solve option(s) {sorted(unknown)}; allowed: {sorted(allowed)}")
    options = dict(steps=STEPS, transition="balanced", tendon_model="exact", tol=TOL, max_iter=MAX_ITER)
    options.update({k.removeprefix("solve_"): v for k, v in solve_options.items()})
    solver_options(**options)
    return options


def check_inputs(robot: Robot, act: Actuation, load: TipLoad) -> None:
    """Cross-checks between robot and actuation that the pytrees cannot make alone."""
    for name, obj, cls in (("robot", robot, Robot), ("act", act, Actuation), ("load", load, TipLoad)):
        if not isinstance(obj, cls):
            raise TypeError(f"{name} must be a tdct.{cls.__name__}, got {type(obj).__name__}")
    if np.shape(act.tensions)[-1:] != (robot.n_tendons,):
        raise ValueError(
            f"tensions has shape {np.shape(act.tensions)}: the robot has {robot.n_tendons} tendons, one tension each"
        )
    if is_concrete(act.insertion) and is_concrete(robot.length):
        check_range(
            "insertion", act.insertion, 0.0, float(robot.length), unit=f" m (0 to the robot length {float(robot.length):g} m)"
        )


def raise_if_failed(sol: Solution, tol: float, max_iter: int) -> None:
    """Raises ConvergenceError naming the residual that did not converge."""
    if isinstance(sol.converged, jax.core.Tracer):
        raise ValueError("throw=True needs concrete values; under jit or vmap use throw=False and check sol.converged")
    if bool(np.all(sol.converged)):
        return
    res = np.abs(np.asarray(sol.residual)).reshape(-1, 6).max(axis=0)
    worst = int(np.argmax(res))
    which = ("tip force", "tip moment")[worst // 3] + " " + "xyz"[worst % 3]
    raise ConvergenceError(
        f"shooting did not converge: scaled {which} residual {res[worst]:.3g} > tol {tol:g} after "
        f"{int(np.max(sol.iterations))} iterations; raise max_iter (now {max_iter}), check the inputs, "
        "or solve a nearby configuration first"
    )
