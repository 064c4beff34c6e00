"""Where is it touching, and how hard: an unknown point force on the body from a measured shape or
tip pose (issue 26).

The force F (world frame, 3 components) acts at an unknown arc length s_F; actuation and every other
load are known. Both are found by Levenberg-Marquardt (``lm.py``) on the measurement residuals
divided by the measurement noise, with the Jacobian in (s_F, F) exact: forward-mode autodiff
through the implicitly differentiated solve, s_F being a breakpoint of the integration plan
(``rod.py``). The start is the best of a grid of locations, each with the force that the
shape's linearisation about the unloaded robot gives there; the uncertainty is the Gauss-Newton
covariance at the answer.
"""

from __future__ import annotations

from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from . import status
from .checks import as_array, check_integer, check_range
from .data import Experiment
from .description import Robot
from .inputs import STANDARD_GRAVITY, gravity_vector
from .lm import covariance, levenberg_marquardt
from .mechanics import positions_at
from .options import DEFAULT_SOLVER, SolverOptions
from .solve import problem, solve
from .tree import pytree, set_fields


@pytree
class TipPose:
    """A measured tip pose, world frame: position [m] (3,) and rotation (body to world) (3, 3)."""

    position: object
    rotation: object

    def __post_init__(self):
        set_fields(
            self,
            position=as_array("tip position", self.position, (3,), unit=" m"),
            rotation=as_array("tip rotation", self.rotation, (3, 3)),
        )


class ForceEstimate(NamedTuple):
    """An estimated point force.

    Attributes:
        s: its arc length [m].
        force: its vector [N], (3,), world frame.
        std_s: the standard error of s [m].
        std_force: the standard errors of the force's components [N], (3,).
        covariance: of (s, F_x, F_y, F_z), (4, 4), SI.
        rms: root-mean-square of the residuals at the answer, in units of the noise (about 1
            when the model and the stated noise fit the data).
        iterations: Levenberg-Marquardt steps from the best start.
        result: a ``tdct_jax.status`` code; message: what it means.
    """

    s: float
    force: np.ndarray
    std_s: float
    std_force: np.ndarray
    covariance: np.ndarray
    rms: float
    iterations: int
    result: int
    message: str

    @property
    def converged(self) -> bool:
        return self.result == status.SUCCESS

    @property
    def magnitude(self) -> float:
        """|F| [N]."""
        return float(np.linalg.norm(self.force))


def _deviation(robot, act, load, gravity, solver, measured, noise, axial, x):
    """The residual (model minus measured, over the noise) at x = (s_F, F), and the result code;
    with ``axial`` one more row: F's component along the body axis d3(s_F) over noise[2]."""
    sol = solve(robot, act, load.with_point(x[0], x[1:]), gravity=gravity, solver=solver, throw=False)
    rows = []
    if axial:
        d3 = sol.rotation[jnp.argmin(jnp.abs(sol.s - x[0])), :, 2]
        rows = [jnp.dot(d3, x[1:])[None] / noise[2]]
    if isinstance(measured, TipPose):
        A = measured.rotation.T @ sol.rotation[-1]
        angle = 0.5 * jnp.stack([A[2, 1] - A[1, 2], A[0, 2] - A[2, 0], A[1, 0] - A[0, 1]])
        r = [(sol.position[-1] - measured.position) / noise[0], angle / noise[1]]
    else:
        dev = positions_at(sol, measured.s) - measured.position
        r = [(jnp.sqrt(measured.weight)[:, None] * dev).reshape(-1) / noise[0]]
    return jnp.concatenate(r + rows), sol.result


FTOL = 1e-9
"""The fit has converged, too, when a step lowers the cost by at most this fraction: a flat valley
along which the data cannot tell locations apart (the reported uncertainty says how far)."""


@partial(jax.jit, static_argnames=("solver", "axial"))
def _evaluate(x, robot, act, load, gravity, solver, measured, noise, axial):
    """Residual, its exact Jacobian in x and the result code."""

    def f(x):
        r, code = _deviation(robot, act, load, gravity, solver, measured, noise, axial, x)
        return r, (r, code)

    J, (r, code) = jax.jacfwd(f, has_aux=True)(x)
    return r, J, code


def estimate_force(
    robot: Robot,
    measured: Experiment | TipPose,
    *,
    act=None,
    load=None,
    noise: float = 1e-4,
    angle_noise: float = 1e-3,
    axial_noise: float | None = None,
    grid: int = 16,
    max_steps: int = 30,
    gravity=STANDARD_GRAVITY,
    solver: SolverOptions = DEFAULT_SOLVER,
    throw: bool = True,
    scene=None,
) -> ForceEstimate:
    """Estimates one unknown point force (location and vector) on the body from a measurement.

    Args:
        robot: the robot.
        measured: a measured shape (an ``Experiment``: points at arc lengths along the body, with
            its actuation and known load) or a ``TipPose`` (then ``act`` and ``load`` are needed).
        act: the known actuation for a ``TipPose`` (an Actuation).
        load: the known load for a ``TipPose`` (Loads or None).
        noise: the standard deviation of each measured coordinate [m], > 0.
        angle_noise: that of each component of the tip's rotation [rad], > 0 (``TipPose`` only).
        axial_noise: None (default): the force's three components are free. A value [N]: the
            prior that the force is normal to the body's axis where it acts (a frictionless
            contact on the body's side), its axial component 0 with this standard deviation. A
            shape reveals that component only through the body's stretch, so least well.
        grid: the number of start locations, spread evenly over (0, L].
        max_steps: Levenberg-Marquardt's step limit.
        gravity: world gravity [m/s^2] (None: none).
        solver: SolverOptions for every solve.
        throw: raise ConvergenceError when the fit does not converge.
        scene: known obstacles (as for ``tdct.solve``): the unknown force acts besides their
            contact forces.

    Returns:
        ForceEstimate.

    Raises:
        ValueError: non-positive noise, a measurement of the wrong kind, a TipPose without ``act``.
    """
    check_range("noise", noise, 0.0, lo_open=True, unit=" m")
    check_range("angle_noise", angle_noise, 0.0, lo_open=True, unit=" rad")
    if axial_noise is not None:
        check_range("axial_noise", axial_noise, 0.0, lo_open=True, unit=" N")
    grid, max_steps = check_integer("grid", grid), check_integer("max_steps", max_steps)
    if isinstance(measured, Experiment):
        act, load = measured.act, measured.tip_load(gravity)
        n_data = 3 * int(np.count_nonzero(measured.weight))
    elif isinstance(measured, TipPose):
        if act is None:
            raise ValueError("act is None: a TipPose measurement needs the known actuation (act=...)")
        n_data = 6
    else:
        raise ValueError(f"measured must be a tdct.Experiment (a shape) or a TipPose, got {type(measured).__name__}")
    robot, act, load = problem(robot, act, load, solver, scene)
    L = float(robot.length)
    args = (
        robot,
        act,
        load,
        gravity_vector(gravity),
        solver,
        measured,
        jnp.array([noise, angle_noise, axial_noise or 1.0]),
        axial_noise is not None,
    )

    def evaluate(x):
        r, J, code = _evaluate(jnp.asarray(x), *args)
        return np.asarray(r), np.asarray(J), int(code), None

    starts = []
    for s in L * (np.arange(grid) + 1.0) / grid:
        r, J, code, _ = evaluate(np.array([s, 0.0, 0.0, 0.0]))
        if code != status.SUCCESS:
            continue
        F = np.linalg.lstsq(J[:, 1:], -r, rcond=None)[0]  # the axial row (if any) holds F along d3 at 0
        starts.append((float(np.sum((r + J[:, 1:] @ F) ** 2)), np.concatenate([[s], F])))
    if not starts:
        raise status.ConvergenceError("the unloaded robot did not solve at any start location", status.NEWTON_LIMIT)
    x0 = min(starts, key=lambda c: c[0])[1]
    fit = levenberg_marquardt(
        evaluate, x0, lower=[0.0, -np.inf, -np.inf, -np.inf], upper=[L, np.inf, np.inf, np.inf], max_steps=max_steps, ftol=FTOL
    )
    cov, se, _, _ = covariance(fit, n_data + (axial_noise is not None))
    estimate = ForceEstimate(
        s=float(fit.x[0]),
        force=fit.x[1:],
        std_s=float(se[0]),
        std_force=se[1:],
        covariance=cov,
        rms=float(np.sqrt(np.mean(fit.residual**2))),
        iterations=fit.iterations,
        result=fit.result,
        message=fit.message,
    )
    status.check(fit.result, throw=throw, what="the force estimate", max_steps=max_steps)
    return estimate


def synthesize(
    robot: Robot,
    act,
    s: float,
    magnitude: float,
    angle: float,
    *,
    points: int = 161,
    noise: float = 1e-4,
    load=None,
    gravity=STANDARD_GRAVITY,
    solver: SolverOptions = DEFAULT_SOLVER,
    rng: np.random.Generator | None = None,
    sweeps: int = 8,
) -> tuple[Experiment, np.ndarray]:
    """A measured shape under a point force normal to the body where it acts (a frictionless
    contact on its side), for tests and benchmarks.

    The force of ``magnitude`` [N] at arc length ``s`` [m] points along cos(angle) d1 + sin(angle)
    d2 of the *loaded* body there, found by ``sweeps`` fixed-point passes (solve, take the body's
    axes at s, solve again). The shape is sampled at ``points`` arc lengths evenly spread over
    (0, L], each coordinate with Gaussian ``noise`` [m] (None: no rng, no noise).

    Returns:
        The Experiment (with ``act`` and ``load``) and the force [N] (3,), world frame.
    """
    robot, act, load = problem(robot, act, load, solver)
    L = float(robot.length)
    F = np.zeros(3)
    for _ in range(sweeps):
        sol = solve(robot, act, load.with_point(jnp.asarray(s, float), jnp.asarray(F)), gravity=gravity, solver=solver)
        R = np.asarray(sol.rotation[np.argmin(np.abs(np.asarray(sol.s) - s))])
        F = magnitude * (R @ np.array([np.cos(angle), np.sin(angle), 0.0]))
    sol = solve(robot, act, load.with_point(jnp.asarray(s, float), jnp.asarray(F)), gravity=gravity, solver=solver)
    s_m = L * np.arange(1, points + 1) / points
    p = np.asarray(positions_at(sol, s_m))
    if rng is not None:
        p = p + rng.normal(scale=noise, size=p.shape)
    return Experiment(s_m, p, act, load), F
