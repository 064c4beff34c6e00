"""Inverse kinematics: the tensions and insertion that put the tip at a target pose, with the tube
insertion as a redundant, stiffness-aware input (paper Secs. V.A and V.B).

The free inputs (any subset of the tendons, and the insertion) are scaled to v = (tau / tau_max,
d / L) and kept inside their bounds exactly. Two phases:

1. Reach: bounded Levenberg-Marquardt on the task residual e (tip position error / L, weighted,
   and optionally the orientation error). Each step solves a small box-constrained least-squares
   problem exactly by enumerating the active sets (3^n of them for n <= 5 free inputs), so
   active bounds are handled exactly, not by clipping. Two ways to evaluate a step: "augmented"
   (the default, except with the stiffness objective) iterates the shooting unknowns x and the
   inputs v together, Newton on the tip boundary residual r(x, v) = 0 and Gauss-Newton on e, one
   forward-mode Jacobian pass of (r, e) per step; "nested" runs a converged forward solve at
   every step and differentiates it implicitly, through the forward solve that phase 2 uses too
   (no Jacobian pass of its own in the compiled program).
2. Optimise (with an objective, once reached): sequential quadratic programming on
   min phi(v) subject to e(v) = 0 and the bounds, with phi's exact gradient (forward-mode
   autodiff through the implicitly differentiated solve and compliance), a damped BFGS
   Hessian of the Lagrangian, and the same exact active-set subproblem.

A target that the bounds do not let the tip reach ends phase 1 at a stationary point of |e|^2:
status UNREACHABLE with the nearest pose found and its distance. When phase 1 from the given start
falls short, the next start is the corner of the input box whose tip, by coarse forward solves
side by side, is nearest the target (``nearest_on_grid``): the basin of the nearest pose.
Derivatives of the solution with respect to the target and the robot come from implicit
differentiation of the optimality conditions at the solution (``jax.jacfwd`` through
``inverse_kinematics``).

The package, one job a module: ``problem`` (target, bounds, what is free, v <-> actuation),
``objectives``, ``evaluation`` (a forward solve with its derivatives in v), ``reach`` (phase 1),
``optimise`` (phase 2), ``starts``, ``driver`` (the solve and its implicit derivatives),
``batched`` (many targets, tracking), ``arguments`` (checks -> Problem); this module is the
public entry.
"""

from __future__ import annotations

import inspect

import jax
import jax.numpy as jnp
import numpy as np

from .. import status
from ..checks import is_concrete
from ..description import Robot
from ..inputs import STANDARD_GRAVITY, Actuation, Loads
from ..options import DEFAULT_SOLVER, SolverOptions
from .arguments import _problem
from .batched import _batched, _track
from .driver import _solve_ik
from .objectives import LeastTension as LeastTension
from .objectives import PreferredInsertion as PreferredInsertion
from .objectives import Stiffness as Stiffness
from .options import DEFAULT_IK
from .options import MAX_STEPS as MAX_STEPS
from .options import IKOptions as IKOptions
from .problem import AXES as AXES
from .problem import DEFAULT_BOUNDS
from .problem import Bounds as Bounds
from .problem import IKResult as IKResult
from .problem import Target as Target
from .problem import describe_task as describe_task


def inverse_kinematics(
    robot: Robot,
    target,
    *,
    load: Loads | None = None,
    tendons=None,
    tubes=None,
    insertion=None,
    bounds: Bounds = DEFAULT_BOUNDS,
    objective=None,
    guess: Actuation | None = None,
    ik: IKOptions = DEFAULT_IK,
    gravity=STANDARD_GRAVITY,
    solver: SolverOptions = DEFAULT_SOLVER,
    throw: bool = True,
) -> IKResult:
    """Tensions and insertion that put the tip at ``target`` (paper Secs. V.A, V.B; module docstring).

    Args:
        robot: the ``Robot`` (``Robot.paper()``, ``Robot.from_toml(path)``, ...).
        target: a Target (or a tip position [m], (3,)); a leading batch axis on its fields solves
            many targets at once (``jax.vmap``).
        load: ``Loads`` (tip force [N] and moment [N m], world frame, and loads along the body),
            held while reaching; none by default. A leading batch axis gives each target its own.
        tendons: the free tendons, numbered from 1 like the paper (tendon i + 1 is the
            robot's ``tendons[i]``): a number or a sequence (default all); the others keep the
            tension ``guess`` gives them (default 0). A tendon that ``guess`` (an Actuation)
            lists in ``driven`` is free in its displacement, its tension found by the solve.
        tubes: the free tubes, numbered from 1 (default all); the others keep the
            depth ``guess`` gives them (default 0).
        insertion: None (free) or a fixed insertion depth [m] of every tube (one depth or one
            per tube).
        bounds: Bounds on the free tensions [N], insertions [m] and displacements [m]; never
            violated (a driven tendon's tension is not bounded).
        objective: among redundant solutions (free inputs beyond the task's dimensions), the one
            that minimises ``Stiffness(direction)`` (the tip compliance along the direction
            [m/N], or without one the largest eigenvalue of its symmetric part),
            ``LeastTension()`` (total squared tension: no needless co-contraction),
            ``PreferredInsertion(depth)`` (squared distance from the depth [m], default L / 2;
            one free tube), or a callable f(Solution, Actuation) -> scalar, differentiable;
            "stiffness", "tension" and "insertion" name the first three with their defaults.
            None: the first solution found. With no more free inputs than task coordinates
            there is nothing to choose: a ValueError says so.
        guess: an Actuation to start from (free inputs) and
            to take the fixed inputs from.
        ik: ``IKOptions``: the method, the tolerance on the scaled task residual and the step
            limit (changing the numbers does not compile a new program).
        gravity, solver: as for ``tdct.solve``.
        throw: raise ConvergenceError when the IK failed (not for UNREACHABLE: an unreachable
            target is an answer, the nearest pose); default True, as everywhere.

    Returns:
        IKResult.
    """
    prob, plan, v0, wrench0 = _problem(**_arguments(**locals()))
    if jnp.ndim(prob.target.position) == 2:
        result = _batched(prob, plan, v0, wrench0)
    else:
        result = _solve_ik(prob, v0, wrench0, plan)[0]
    _check(result, throw, ik.max_steps)
    return result


def track(robot: Robot, targets: Target, *, solver: SolverOptions = DEFAULT_SOLVER, **options) -> IKResult:
    """Inverse kinematics along a sequence of targets (a Target whose fields have a leading axis),
    each started from the last solution, as one compiled ``lax.scan``: the real-time control case.
    A warm update takes its first step from the last update's linearisation (``Model``: the
    first-order predictor of the answer, no evaluation before it), then Gauss-Newton steps to
    the same tolerance as a cold solve (tests/test_ik_tracking.py).

    Args:
        robot, targets: the robot and the targets in order (at least one; a Target, or tip
            positions [m] of shape (n, 3)).
        solver: SolverOptions for every forward solve.
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
    prob, plan, v0, wrench0 = _problem(**_arguments(robot, first, solver=solver, **options))
    result = _track(prob, leaves, v0, wrench0, plan, tree, own)
    _check(result, throw, prob.options.max_steps)
    return result


def _arguments(*args, **kwargs) -> dict:
    """``inverse_kinematics``'s arguments but ``throw``, bound to its signature, defaults filled."""
    bound = inspect.signature(inverse_kinematics).bind(*args, **kwargs)
    bound.apply_defaults()
    return {name: value for name, value in bound.arguments.items() if name != "throw"}


def _check(result: IKResult, throw: bool, max_steps: int) -> None:
    """``throw`` for everything but UNREACHABLE, which is an answer."""
    code = jnp.where(result.result == status.UNREACHABLE, status.SUCCESS, result.result)
    status.check(code, throw=throw, what="the inverse kinematics", max_steps=max_steps)
