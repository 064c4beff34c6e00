"""Derived mechanics: exact compliance (eq. 41) at the tip or at any arc length, compliance
ellipsoid (eq. 43), Jacobians, and the shape error against a measured shape (RMSE, eq. 39, and tip
error).

Every derivative here is forward-mode autodiff through the converged shooting solution: JAX
differentiates the root implicitly (one 6x6 shooting Jacobian, no extra Newton solves, no
finite differences). ``finite_difference_compliance`` keeps the paper's method for comparison.
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from . import fields
from .checks import as_array, check_range, is_concrete
from .description import Robot
from .inputs import STANDARD_GRAVITY, Actuation, Loads
from .options import DEFAULT_SOLVER, SolverOptions
from .so3 import rotation_columns
from .solve import check_solution, solution_and_compliance, solve, solve_arguments


def compliance(
    robot: Robot,
    act: Actuation | None,
    load: Loads | None = None,
    *,
    at=None,
    full: bool = False,
    gravity=STANDARD_GRAVITY,
    solver: SolverOptions = DEFAULT_SOLVER,
    guess=None,
    throw: bool = True,
    scene=None,
):
    """Compliance CM = d p(s) / d F (eq. 41), exact, in m/N: at the tip (s = L, F the tip force
    F_e) by default, or at the arc length ``at`` (F a point force applied there).

    The tip's comes from Newton's Jacobians at the converged root (one extra 6x6 solve). At an arc
    length, a zero point load at s is added to the loads and p(s) differentiated in it by forward
    mode through the implicitly differentiated solve. Derivatives of CM itself (e.g. with respect
    to the insertion) go through forward-mode autodiff of the solve. Displacement-driven tendons
    hold their displacements (their tensions adjust).

    Args:
        robot, act, load, gravity, solver, guess: as for ``tdct.solve``; the compliance is taken
            about these loads.
        at: arc length s [m] in [0, L]; None: the tip.
        full: return the 6x6 compliance d(position, rotation vector of the section at s) /
            d(force, moment at s) instead (blocks in m/N, m/(N m), rad/N, rad/(N m); rotation
            vector and loads in the world frame).
        throw: raise ``ConvergenceError`` if the solve did not converge (default, as for
            ``tdct.solve``); with False a non-converged solve gives a matrix of NaN.
        scene: obstacles (as for ``tdct.solve``): the compliance in contact, the contact set
            held (touching candidates stay on their obstacles, the others free).

    Returns:
        CM, shape (3, 3) (or (6, 6) with ``full``).

    Raises:
        ValueError: bad input, ``at`` outside [0, L] included (names field, value and range).
    """
    if at is None:
        C, _ = compliance_and_solution(robot, act, load, gravity=gravity, solver=solver, guess=guess, throw=throw, scene=scene)
    else:
        args = solve_arguments(robot, act, load, gravity, guess, solver, scene)
        at = as_array("at", at, ())
        if is_concrete(robot.length):
            L = float(robot.length)
            check_range("at", at, 0.0, L, unit=f" m (0 to the robot length {L:g} m)")
        C, _ = _checked(_compliance_at, (*args[:-1], at, args[-1]), throw)
    return C if full else C[:3, :3]


@jax.jit
def _compliance_at(robot, act, load, gravity, guess, s, solver):
    """(d(position, rotation vector at s) / d(point force, moment at s), Solution)."""

    def pose(w):
        loads = load.with_point(s, w[:3], w[3:])
        sol = solution_and_compliance(robot, act, loads, gravity, guess, solver)[0]
        i = jnp.searchsorted(sol.s, s, side="right") - 1  # a node lies at s: it is a breakpoint
        return (sol.position[i], sol.rotation[i]), (sol, sol.rotation[i])

    (Jp, JR), (sol, R) = jax.jacfwd(pose, has_aux=True)(jnp.zeros(6))
    return jnp.concatenate([Jp, rotation_columns(JR, R)]), sol


def compliance_and_solution(
    robot, act, load=None, *, gravity=STANDARD_GRAVITY, solver=DEFAULT_SOLVER, guess=None, throw=True, scene=None
):
    """The 6x6 compliance of ``compliance(..., full=True)`` and the Solution it was taken at, in one solve."""
    return _checked(_compliance, solve_arguments(robot, act, load, gravity, guess, solver, scene), throw)


def _checked(f, args, throw, *static):
    """f(*args, *static) = (matrix, Solution), with ``throw`` applied, or the matrix masked with
    NaN where the solve did not converge; ``args[-1]`` is the SolverOptions."""
    M, sol = f(*args, *static)
    check_solution(sol, args[-1], throw)
    return jnp.where(sol.converged, M, jnp.nan), sol


@jax.jit
def _compliance(robot, act, load, gravity, guess, solver):
    return _compliance_from_root(robot, act, load, gravity, guess, solver)


@jax.custom_jvp
def _compliance_from_root(robot, act, load, gravity, guess, solver):
    sol, C = solution_and_compliance(robot, act, load, gravity, guess, solver)
    return C, sol


@_compliance_from_root.defjvp
def _compliance_jvp(primals, tangents):
    """Derivatives of the compliance: forward-mode autodiff of the compliance's own autodiff."""
    return jax.jvp(lambda *args: pose_jacobian(*args, "load"), primals, tangents)


def pose_jacobian(robot, act, load, gravity, guess, solver, wrt):
    """(d(tip pose) / dw, Solution) for w the tip load ("load"), the actuation ("actuation": see
    ``kinematic_jacobian`` for the columns) or a tuple of field names (``fields.py``); the rotation
    part is vee(dR R^T) in the world frame, (6, n)."""
    if wrt == "load":
        w = jnp.concatenate([jnp.asarray(load.tip_force), jnp.asarray(load.tip_moment)])

        def configure(w):
            return robot, act, dataclasses.replace(load, tip_force=w[:3], tip_moment=w[3:])

    elif wrt == "actuation":
        parts = [jnp.asarray(x, float).reshape(-1) for x in (act.tensions, act.displacements, act.insertions)]
        w, cut = jnp.concatenate(parts), np.cumsum([p.size for p in parts])

        def configure(w):
            return robot, Actuation._rebuild(w[: cut[0]], w[cut[1] :], w[cut[0] : cut[1]], act.driven), load

    else:
        w = jnp.stack([jnp.asarray(fields.get(robot, p), float) for p in wrt])

        def configure(w):
            return fields.replace(robot, dict(zip(wrt, w, strict=True))), act, load

    def pose(w):
        sol = solution_and_compliance(*configure(w), gravity, guess, solver)[0]
        return (sol.tip_position, sol.tip_rotation), sol

    (Jp, JR), sol = jax.jacfwd(pose, has_aux=True)(w)
    return jnp.concatenate([Jp, rotation_columns(JR, sol.tip_rotation)]), sol


_pose_jacobian = jax.jit(pose_jacobian, static_argnums=(6,))


def kinematic_jacobian(
    robot, act, load=None, *, gravity=STANDARD_GRAVITY, solver=DEFAULT_SOLVER, guess=None, throw=True, scene=None
):
    """d(tip position [m], tip rotation vector [rad]) / d(tensions [N], insertion [m]), shape (6, n_t + 1).

    The last column is the tube insertion depth, a real differentiable input (one-sided at d = 0
    and d = L, where the solution extends smoothly). Arguments as for ``compliance``.

    With a Actuation, one column per input, shape (6, n_t + len(driven) + n_tubes): each
    tendon's tension [N] in the robot's order, then each displacement-driven tendon's
    displacement [m] in ``driven`` order, then each tube's insertion [m]. A driven tendon's
    tension column is zero: its tension follows from its displacement.

    With a ``scene`` (as for ``tdct.solve``) the contact set is held: the touching candidates stay
    on their obstacles.
    """
    args = solve_arguments(robot, act, load, gravity, guess, solver, scene)
    return _checked(_pose_jacobian, args, throw, "actuation")[0]


def parameter_jacobian(
    robot,
    act,
    load=None,
    *,
    params=("sections[*].E",),
    gravity=STANDARD_GRAVITY,
    solver=DEFAULT_SOLVER,
    guess=None,
    throw=True,
    scene=None,
):
    """d(tip position, tip rotation vector) / d(fields named in ``params``), (6, len(params)).

    Field names as in ``fields.py``: "sections[*].E", "tendons[0].offset", ... ("[*]": one
    value shared by every item). Units follow the fields (e.g. m/Pa for a modulus). Arguments as
    for ``compliance``.
    """
    args = solve_arguments(robot, act, load, gravity, guess, solver, scene)
    robot = args[0]
    check_params(robot, params)
    for p in params:
        fields.value(robot, p)  # set, and for "[*]" one value
    return _checked(_pose_jacobian, args, throw, tuple(params))[0]


def check_params(robot: Robot, params) -> None:
    """Raises ValueError unless each of ``params`` is one of the robot's fields (``fields.check``)."""
    for p in params:
        try:
            fields.check(robot, p)
        except ValueError as e:
            raise ValueError(f"params: {e}") from None


def finite_difference_compliance(robot, act, load=None, *, step: float = 1e-4, gravity=STANDARD_GRAVITY, solver=DEFAULT_SOLVER):
    """CM by central differences of the tip position over the three tip-force components (the
    paper's method): 6 extra solves, each required to converge. ``step`` [N] is finite and > 0."""
    step = as_array("step", step, ())
    check_range("step", step, 0.0, lo_open=True, unit=" N")
    load = Loads() if load is None else load
    columns = []
    for k in range(3):
        dF = np.zeros(3)
        dF[k] = step
        tips = [
            solve(
                robot,
                act,
                dataclasses.replace(load, tip_force=np.asarray(load.tip_force) + sign * dF),
                gravity=gravity,
                solver=solver,
            ).tip_position
            for sign in (1.0, -1.0)
        ]
        columns.append((tips[0] - tips[1]) / (2 * step))
    return jnp.stack(columns, axis=1)


class Ellipsoid(NamedTuple):
    """Compliance ellipsoid of CM (eqs. 40-43).

    eigenvalues, eigenvectors: of the symmetric part (CM + CM^T)/2, ascending, eigenvectors as
        columns: the paper's lambda_1..3 and mu_1..3 (Figs. 10-11).
    semi_axes, axes: singular values of CM (descending) and the left singular vectors (columns):
        the exact semi-axes and directions of {CM f : |f| = 1} (eq. 43).
    The two agree when CM is symmetric positive definite, as for an unloaded robot without
    tendon tension. Tendon tension and a tip load make CM slightly non-symmetric (the tendon load
    follows the body), and then only the singular values describe the ellipsoid exactly.
    """

    eigenvalues: jax.Array
    eigenvectors: jax.Array
    semi_axes: jax.Array
    axes: jax.Array


def compliance_ellipsoid(CM) -> Ellipsoid:
    """Eigen- and singular-value description of a 3x3 compliance matrix (see Ellipsoid)."""
    CM = jnp.asarray(CM)
    if CM.shape[-2:] != (3, 3):
        raise ValueError(f"CM must have shape (..., 3, 3), got {CM.shape}")
    lam, mu = jnp.linalg.eigh((CM + jnp.swapaxes(CM, -1, -2)) / 2)
    U, S, _ = jnp.linalg.svd(CM)
    return Ellipsoid(lam, mu, S, U)


def positions_at(sol, s):
    """The model's positions p(s) [m] at arc lengths ``s`` [m], shape s.shape + (3,).

    Cubic Hermite interpolation between RK4 nodes with the exact tangents p' = R v, so the
    interpolation error is O(h^4) like RK4's own (each interval between breakpoints with its own
    end tangents: both sides of a breakpoint are nodes). Arc lengths outside [0, L] are clamped to the ends.
    Differentiable in the solution (for calibration); not in ``s``.
    """
    nodes, p = sol.s, sol.position
    n = nodes.size
    s = jnp.clip(jnp.asarray(s, dtype=nodes.dtype), nodes[0], nodes[-1])
    k = jnp.clip(jnp.searchsorted(nodes, s, side="right") - 1, 0, n - 2)
    h = nodes[k + 1] - nodes[k]
    t = jnp.where(h > 0, (s - nodes[k]) / jnp.where(h > 0, h, 1.0), 0.0)[..., None]
    h = h[..., None]
    tangent = jnp.einsum("nij,nj->ni", sol.rotation, sol.strain)
    hm0 = h * tangent[k]
    p0, p1, hm1 = p[k], p[k + 1], h * tangent[k + 1]
    return (2 * t**3 - 3 * t**2 + 1) * p0 + (t**3 - 2 * t**2 + t) * hm0 + (-2 * t**3 + 3 * t**2) * p1 + (t**3 - t**2) * hm1


def shape_deviation(sol, measured):
    """Model minus measured position at each measured point [m], (n, 3); ``measured`` is an
    Experiment (or anything with ``s`` [m] and ``position`` [m])."""
    return positions_at(sol, measured.s) - measured.position


def shape_errors(sol, measured):
    """(shape_deviation, rmse, tip_error) from one interpolation of the model."""
    dev, w = shape_deviation(sol, measured), measured.weight
    last = w.size - 1 - jnp.argmax(w[::-1] > 0)
    return dev, jnp.sqrt(jnp.sum(w * jnp.sum(dev**2, axis=-1)) / jnp.sum(w)), jnp.linalg.norm(dev[last])


def rmse(sol, measured):
    """Root-mean-square distance between model and measured shape (eq. 39) [m].

    Points are weighted by ``measured.weight`` (padding in a stacked batch has weight 0).
    Divide by ``robot.length`` for the paper's "% of total length".
    """
    return shape_errors(sol, measured)[1]


def tip_error(sol, measured):
    """Distance between model and measured position at the last measured point [m]."""
    return shape_errors(sol, measured)[2]
