"""What an inverse kinematics problem is: the target, the bounds, what is free (``Plan``), the
``Problem`` an IK step sees, the map between the scaled free inputs v and an actuation, the task
residual and the result."""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .. import status
from ..checks import as_array, check_range, is_concrete
from ..description import Robot
from ..inputs import Actuation, Loads
from ..options import SolverOptions
from ..solve import Solution, tip_angle
from ..tree import pytree, set_fields, static
from .options import IKOptions

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
        tension: (lowest, highest) tension of every free tendon [N], 0 <= lowest <= highest; a
            tendon's own ``max_tension`` lowers its highest.
        insertion: (shallowest, deepest) insertion of every free tube [m] in [0, L]; None: (0, L).
        displacement: (lowest, highest) displacement of every free displacement-driven tendon [m];
            None: (-L / 10, L / 10).
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
    """What is free (static): which tendons and which tubes (0-based; the paper robot's one tube
    is tube 0, its insertion), which objective. v holds the free tendons' scaled tensions (or, for
    the Actuation's ``driven`` tendons, scaled displacements) in this order, then the tubes'."""

    tendons: tuple
    tubes: tuple
    objective: object  # None, "stiffness", "tension", "insertion" or a callable (sol, act) -> scalar
    method: str


@pytree
class IKResult:
    """Outcome of ``inverse_kinematics``.

    Attributes:
        actuation: the tensions [N] and insertions [m] found (every bound holds), an
            Actuation whose tensions are those of the solution (the driven tendons' included).
        solution: the forward Solution there (``solution.tip_position`` etc.).
        position_error: distance from the tip to the target position (over ``target.axes``) [m].
        orientation_error: angle between tip and target orientation [rad] (0 without one).
        objective: the objective's value there (NaN without one).
        iterations: IK steps taken in all: phase 1's from every start tried and phase 2's (each
            start and phase 2 limited to ``IKOptions.max_steps``).
        chord_steps: how many of them were chord steps: a warm update's (``track``), each one
            evaluation of the model with no Jacobian pass, about a quarter of a full step's cost.
        result: a ``tdct_jax.status`` code: SUCCESS (reached), UNREACHABLE (the nearest pose
            found is returned, ``position_error`` away), OUTER_LIMIT, or the forward solve's own.
    """

    actuation: Actuation
    solution: Solution
    position_error: jax.Array
    orientation_error: jax.Array
    objective: jax.Array
    iterations: jax.Array
    chord_steps: jax.Array
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


class Problem(NamedTuple):
    """Everything an IK step needs besides the free inputs v (a pytree; ``plan`` is static)."""

    robot: Robot
    target: Target
    load: Loads
    gravity: jax.Array
    base: Actuation  # values of the fixed inputs
    lo: jax.Array  # bounds of v
    hi: jax.Array
    tension_scale: jax.Array  # [N] per unit of v
    solver: SolverOptions
    preferred_insertion: jax.Array  # [m], for the "insertion" objective
    direction: jax.Array  # unit world direction for the "stiffness" objective (NaN: largest eigenvalue)
    options: IKOptions  # its tol and max_steps are leaves


DISPLACEMENT_SCALE = 0.1
"""A free displacement-driven tendon's scaled input: its displacement over this fraction of L."""


def _split(base, plan: Plan):
    """Static positions in v of the free tendons driven by tension and of those driven by
    displacement (the Actuation's ``driven``), with the latter's places in ``displacements``."""
    driven = base.driven
    pulled = tuple(j for j, t in enumerate(plan.tendons) if t not in driven)
    moved = tuple(j for j, t in enumerate(plan.tendons) if t in driven)
    return pulled, moved, tuple(driven.index(plan.tendons[j]) for j in moved)


def actuation_of(v, prob: Problem, plan: Plan):
    """The Actuation with the free inputs set from the scaled v."""
    k, base, L = len(plan.tendons), prob.base, prob.robot.length
    pulled, moved, places = _split(base, plan)
    tensions, insertions, displacements = (jnp.asarray(x, float) for x in (base.tensions, base.insertions, base.displacements))
    if pulled:
        free = np.array([plan.tendons[j] for j in pulled])
        tensions = tensions.at[free].set(v[np.array(pulled)] * prob.tension_scale)
    if moved:
        displacements = displacements.at[np.array(places)].set(v[np.array(moved)] * (DISPLACEMENT_SCALE * L))
    if plan.tubes:
        insertions = insertions.at[np.array(plan.tubes)].set(v[k:] * L)
    return Actuation._rebuild(tensions, insertions, displacements, base.driven)


def scaled_inputs(act, prob: Problem, plan: Plan):
    """The inverse of ``actuation_of``: v of an actuation."""
    L = prob.robot.length
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
    """The shooting unknowns of a Solution, unscaled: its base wrench, then the
    displacement-driven tendons' tensions [N]."""
    if act.driven:
        return jnp.concatenate([sol.base_wrench, sol.tensions[np.array(act.driven)]])
    return sol.base_wrench


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


def describe_task(target: Target) -> str:
    """The task coordinates of a target in words, e.g. "x, y, z and the tip angle"."""
    extra = {None: "", "direction": " and the tip direction (2)", "tip_angle": " and the tip angle"}[target.orientation]
    return ", ".join(target.axes) + extra
