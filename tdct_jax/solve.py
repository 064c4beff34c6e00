"""The static shape: ``solve`` and the Solution it returns (paper Sec. II; docs/model.md)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from . import multiple, rod, roots, status
from .checks import as_array, is_concrete
from .description import Robot
from .inputs import STANDARD_GRAVITY, Actuation, Loads, gravity_vector
from .options import DEFAULT_SOLVER, SolverOptions
from .scene import Scene
from .shooting import force_scale, shoot, tip_compliance
from .tree import pytree


def tip_angle(R):
    """theta_tip: the angle of the tangent R e3 in the world z-y plane from +z, toward +y [rad]."""
    return jnp.arctan2(R[..., 1, 2], R[..., 2, 2])


@pytree
class Solution:
    """Static shape of the robot at the RK4 nodes.

    Nodes come interval by interval (rod.py: the intervals between section ends, tube
    depths, tendon anchors and point loads, coincident ones of the robot's own counted once),
    ``steps + 1`` each: both sides of every breakpoint appear, ``total_force`` and
    ``total_moment`` jumping at point loads. The paper's robot has two intervals, [0, d] and
    [d, L]. ``distinct()`` picks one node per arc length.

    Attributes:
        s: arc length of the undeformed robot [m], (n,).
        position: p(s) [m], world frame, (n, 3).
        rotation: R(s), body to world, (n, 3, 3).
        force, moment: the rod's internal force n(s) [N] and moment m(s) [N m], world frame.
        total_force, total_moment: rod plus tendons, N(s) and M(s); at s = 0 the load on the base.
        strain, curvature: v(s) and u(s) [1/m], body frame.
        residual: scaled residual (tip force rows, then moment rows, then any driven tendons'
            and contact rows).
        residual_norm: its max norm.
        iterations: Newton steps over all load stages.
        stages: load stages of the last ramp tried (one of SolverOptions.stages).
        result: a ``tdct_jax.status`` code: SUCCESS (0), NEWTON_LIMIT, CONTINUATION_EXHAUSTED,
            NONFINITE, and with a scene CONTACT_UNCONVERGED or PENETRATION; ``message`` says what
            it means and what to do.
        contact: with a scene (``solve(..., scene=)``), a ``contact.Contact``: candidates' arc
            lengths, positions, gaps, normal forces, normals, the wrench on each obstacle and
            which touch; None without one.
        tensions: each tendon's tension [N], (n_t,): the given ones, and those found for the
            displacement-driven tendons.
        displacements: what each tendon's encoder reads [m], (n_t,): its rest length inside the
            straight robot less its present rest length there (positive when pulled); for a
            displacement-driven tendon, its command (more than the shape takes up where slack).
        slack: True for a displacement-driven tendon gone slack (its tension exactly 0), (n_t,).
        tendon_tension: each tendon's tension at every node [N], (n, n_t): its base tension
            (``tensions``) up to its anchor and zero beyond, unless friction makes it vary along
            the robot (``Section.friction``); at a node, that of the span starting there. The next
            pose's ``Actuation(memory=...)`` along a sequence.
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
    iterations: jax.Array
    stages: jax.Array
    result: jax.Array
    contact: object
    tensions: jax.Array
    displacements: jax.Array
    slack: jax.Array
    tendon_tension: jax.Array

    @property
    def converged(self):
        """result == SUCCESS: the scaled tip residual is at most the tolerance."""
        return self.result == status.SUCCESS

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

    def fold(self, robot: Robot) -> tuple[float, float, int]:
        """Where one solution's tendon paths bend sharpest: (|u_xy| r_t, s [m], tendon index from 0),
        |u_xy| the bending curvature [1/m] at a node and r_t the offset [m] of a tendon present
        there, at their largest product; (0.0, 0.0, -1) without tendons. Concrete values only.

        At 1 or more the bend's radius 1/|u_xy| is at most the tendon's offset: on the inside of
        the bend the tendon's path (and the body at that radius) folds back on itself, and the
        shape, converged or not, is not physical (``notes`` says so).
        """
        s, u = np.asarray(self.s), np.asarray(self.curvature)
        if not robot.tendons:
            return 0.0, 0.0, -1
        bend = np.linalg.norm(u[:, :2], axis=-1)
        step = np.append(s[0], (s[1:] + s[:-1]) / 2)  # the middle of the step ending at each node
        reach = np.array([np.inf if t.end is None else float(t.end) for t in robot.tendons])
        product = bend[:, None] * np.array([float(t.offset) for t in robot.tendons]) * (step[:, None] < reach)
        node, tendon = np.unravel_index(np.argmax(product), product.shape)
        return float(product[node, tendon]), float(s[node]), int(tendon)

    def notes(self, robot: Robot) -> list[str]:
        """Notes on a converged solution (``converged``) whose shape is not physical: a tendon path
        that folds (``fold`` at 1 or more). The command line prints them as ``tdct: note:`` lines."""
        value, s, i = self.fold(robot)
        if not bool(self.converged) or value < 1:
            return []
        return [
            f"tendon {i + 1}'s path folds at s = {1e3 * s:.1f} mm: curvature x offset = {value:.3g}, at least 1 (the bend's "
            "radius is below the tendon's offset): the shape solves the equations but is not physical; lower the tension or load"
        ]

    def distinct(self) -> np.ndarray:
        """Indices of one solution's nodes at distinct arc lengths, in order (the shape files'
        rows): of the nodes at one arc length (both sides of a breakpoint, a zero-length
        interval's, e.g. the tube's at insertion 0), the last, after every jump there."""
        s = np.asarray(self.s)
        return np.flatnonzero(np.append(s[1:] != s[:-1], True))


@jax.jit
def solution_and_compliance(robot: Robot, act: Actuation, load: Loads, gravity, guess, solver: SolverOptions):
    """The compiled solve: the Solution, and the 6x6 tip compliance d(tip position, tip rotation
    vector) / d(F_e, M_e) (eq. 41) from Newton's Jacobians at the root, for one 6x6 solve more.

    The compliance is exact in value but has no derivatives of its own (``tdct.compliance``
    supplies them). Unchecked: ``solve_arguments`` checks the arguments.
    """
    _, info, res, ys = roots.path(robot, act, load, gravity, guess, solver)
    sol = _assembled(robot, act, load, gravity, solver, ys, res, info)
    J_res, (J_p, J_R) = info.jacobians
    return sol, tip_compliance(robot, sol.tip_rotation, J_res, J_p, J_R, force_scale(robot, act, load, gravity))


def solution_at(robot: Robot, act: Actuation, load: Loads, gravity, solver: SolverOptions, x, info) -> Solution:
    """The Solution at the scaled base unknowns x of a root found elsewhere (``info``: its
    iterations, stages and result code), by one integration along the path."""
    res, ys = shoot(robot, act, load, gravity, solver, x, force_scale(robot, act, load, gravity), path=True)
    return _assembled(robot, act, load, gravity, solver, ys, res, info)


def _assembled(robot, act, load, gravity, solver, ys, res, info) -> Solution:
    """The Solution from a path ``ys`` as ``shoot`` (or ``multiple.path``) gives it: nodes
    interval by interval, steps + 1 each, so that both sides of every breakpoint appear (the node
    at an interval's start is after the breakpoint's jump)."""
    nodes, pl, act, lengths, slack, touching = ys
    s, y, (v, u, n, m) = rod.node_quantities(robot, act, load, gravity, nodes, pl, solver.tendon_model)
    # a slack tendon's tension is zero to round-off at the root (the Fischer-Burmeister row is
    # linear in it there): reported as exactly zero; a driven tendon's encoder reads its command
    tensions = jnp.where(slack, 0.0, jnp.asarray(act.tensions, float))
    displacements = rod.displacements(robot, lengths)
    if act.driven:
        displacements = displacements.at[np.asarray(act.driven)].set(act.displacements)
    result = info.result if touching is None else status.contact_result(info.result, touching.gap, 2 * solver.tol * robot.length)
    return Solution(
        s, y.p, y.R, n, m, y.N, y.M, v, u, res, jnp.max(jnp.abs(res)), info.iterations, info.stages, result, touching,
        tensions, displacements, slack, rod.tension_profile(pl, nodes),
    )  # fmt: skip


def solve(
    robot: Robot,
    act: Actuation | None = None,
    load: Loads | None = None,
    *,
    gravity=STANDARD_GRAVITY,
    solver: SolverOptions = DEFAULT_SOLVER,
    guess=None,
    throw: bool = True,
    scene=None,
) -> Solution:
    """Static shape of a tendon-driven robot (paper Sec. II; docs/model.md) by Newton shooting.

    The unknowns are the total force and moment at the base (and the tensions of
    displacement-driven tendons), started from the straight rod. Derivatives of every output with
    respect to every input (robot fields, tensions, insertions, loads, gravity) come from implicit
    differentiation of the converged root, so ``jax.grad``, ``jax.jacfwd`` and ``jax.vmap`` pass
    straight through.

    Args:
        robot: geometry and materials (``Robot``: ``Robot.paper()``, ``Robot.from_toml(path)``).
        act: tendon tensions [N] (or displacements [m]) and tube insertions [m]; None: nothing
            pulled, every tube withdrawn.
        load: tip load and loads along the body, world frame (``Loads``; ``Loads.from_mass``
            for a tip mass); None: none.
        gravity: world gravity [m/s^2]; None or zeros switch the robot's weight off.
        solver: steps, transition, tendon model, tolerance and Newton limit (SolverOptions).
        guess: base force and moment (N(0) [N], M(0) [N m]), shape (6,), to start Newton from,
            e.g. a neighbouring solution's ``base_wrench``; None starts from the straight rod.
        throw: raise ConvergenceError when the solve did not converge (the default, as for every
            entry point; inside jit or vmap the check runs in the compiled program). With False,
            check ``sol.result`` / ``sol.converged``.
        scene: obstacles the robot may touch (a ``tdct.Scene``; contact.py): frictionless
            contact along the body and at the tip, reported in ``sol.contact``. It rides in the
            Loads (``Loads.scene``), so derivatives in the obstacles' numbers and vmaps over them
            pass through. Single shooting only (``solver.intervals`` = 1).

    Returns:
        Solution.

    Raises:
        ValueError: bad input (names field, value and allowed range).
        ConvergenceError: with ``throw``, the result code's message (what failed, what to do).
    """
    sol = solution_and_compliance(*solve_arguments(robot, act, load, gravity, guess, solver, scene))[0]
    check_solution(sol, solver, throw)
    return sol


def check_solution(sol: Solution, solver: SolverOptions, throw: bool, what: str = "the shooting solve") -> None:
    """``status.check`` of a Solution (or a batch of them), with its numbers in the message."""
    status.check(
        sol.result,
        throw=throw,
        what=what,
        iterations=sol.iterations,
        stages=sol.stages,
        residual_norm=sol.residual_norm,
        max_iter=solver.max_iter,
        tol=solver.tol,
    )


def solve_arguments(robot, act, load, gravity, guess, solver, scene=None) -> tuple:
    """Checks a single solve's arguments; returns those of ``solution_and_compliance``."""
    robot, act, load = problem(robot, act, load, solver, scene)
    robot.warn_outside_calibration(act.tensions, load.tip_force)
    guess = jnp.full(6, jnp.nan) if guess is None else as_array("guess", guess, (6,))
    return robot, act, load, *_on_cpu(gravity_vector(gravity), guess), solver


def problem(robot, act, load, solver, scene=None, *, batch: bool = False) -> tuple[Robot, Actuation, Loads]:
    """(robot, act, load) checked, with defaults (``Actuation.of``, ``Loads.of``) and ``scene`` in
    the Loads: types, counts and ranges that need robot and inputs together, the solver options
    against the robot. Without ``batch``, concrete inputs must be one configuration."""
    for name, obj, cls in (("robot", robot, Robot), ("solver", solver, SolverOptions)):
        if not isinstance(obj, cls):
            raise TypeError(f"{name} must be a tdct.{cls.__name__}, got {type(obj).__name__}")
    act, load = Actuation.of(act, robot), Loads.of(load)
    if scene is not None:
        load = with_scene(robot, load, scene, solver)
    if not batch:
        for name, x, core in (("tensions", act.tensions, 1), ("insertions", act.insertions, 1), ("tip_force", load.tip_force, 1)):
            if is_concrete(x) and np.ndim(x) > core:
                raise ValueError(
                    f"{name} has shape {np.shape(x)}: one configuration is expected here; solve a batch with tdct.sweep or jax.vmap"
                )
    rod.check_arguments(robot, act, load, solver)
    multiple.check(robot, load, solver)
    return robot, act, load


def with_scene(robot: Robot, load: Loads, scene, solver) -> Loads:
    """``load`` with ``scene`` in it, after its checks: a Scene, the base outside every obstacle,
    single shooting; obstacles far beyond the robot get a UnitWarning (``Scene.check_reach``)."""
    if not isinstance(scene, Scene):
        raise TypeError(f"scene must be a tdct.Scene, got {type(scene).__name__}")
    if solver.intervals > 1:
        raise ValueError(
            f"solver intervals = {solver.intervals} with a scene: contact is solved by single shooting only; use intervals = 1"
        )
    if is_concrete(robot.sections[0].outer_diameter):
        scene.check_base(float(robot.sections[0].outer_diameter) / 2)
    if is_concrete(robot.length):
        scene.check_reach(float(robot.length))
    return load.with_scene(scene)


def _on_cpu(*arrays):
    """The arrays committed to the CPU where another backend (a GPU) is the default, so that the
    solve they enter runs there (jit runs where its committed arguments are; the pytrees' numpy
    leaves follow). One solve is a long chain of small operations, each a kernel launch on a GPU,
    and faster on the CPU. Traced arrays (the caller's jit or vmap, and so sweeps) stay as they are."""
    if jax.default_backend() == "cpu" or not all(is_concrete(a) for a in arrays):
        return arrays
    return jax.device_put(arrays, jax.local_devices(backend="cpu")[0])
