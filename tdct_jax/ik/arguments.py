"""The arguments of ``inverse_kinematics`` checked and turned into a ``Problem``, a ``Plan`` and a
start."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from ..checks import UnitWarning, array_module, as_array, check_choice, check_range, is_concrete, target_note, warn_user
from ..inputs import Actuation, gravity_vector
from ..solve import problem
from .objectives import KINDS, SHORTHANDS
from .options import IKOptions
from .problem import (
    AXES,
    DISPLACEMENT_SCALE,
    Bounds,
    Plan,
    Problem,
    Target,
    _split,
    describe_task,
    scaled_inputs,
)
from .starts import default_start


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
    guess,
    ik,
    gravity,
    solver,
):
    """Checks the arguments; returns (Problem, Plan, start v0, start unknowns (NaN))."""
    if not isinstance(target, Target):
        target = Target(target)
    batched = jnp.ndim(target.position) == 2
    robot, base, load = problem(robot, guess, load, solver, batch=batched)
    if load.scene is not None:
        raise ValueError(
            "load.scene is set: inverse kinematics with obstacles is not supported yet (the contact forces would be "
            "more unknowns in every IK step); solve the forward problem with tdct.solve(..., scene=...)"
        )
    n_t, n_tubes = robot.n_tendons, robot.n_tubes
    L = float(robot.length) if is_concrete(robot.length) else robot.length
    typed = tendons
    if tendons is None:
        tendons = tuple(range(1, n_t + 1))
    elif isinstance(tendons, (int, np.integer)):
        tendons = (tendons,)  # one tendon
    elif isinstance(tendons, (tuple, list, np.ndarray)):
        tendons = tuple(tendons)
    for t in tendons if isinstance(tendons, tuple) else (None,):
        if isinstance(t, bool) or not isinstance(t, (int, np.integer)) or not 1 <= t <= n_t:
            raise ValueError(
                f"tendons = {typed!r}: a tendon number or a sequence of them, each in [1, {n_t}] "
                f"(tendons[0] to tendons[{n_t - 1}] of the robot)"
            )
    if len(set(tendons)) != len(tendons):
        raise ValueError(f"tendons = {tendons!r} names a tendon twice")
    tubes = _free_tubes(tubes, insertion, n_tubes)
    if insertion is not None:
        shape = (n_tubes,) if np.ndim(insertion) == 1 else ()
        insertion = as_array("insertion", insertion, shape, unit=" m")
        check_range("insertion", insertion, 0.0, L, unit=f" m (0 to the robot length {float(L):g} m)") if is_concrete(L) else None
        depths = jnp.broadcast_to(insertion, (n_tubes,))
        base = Actuation._rebuild(base.tensions, depths, base.displacements, base.driven)
    if not tendons and not tubes:
        raise ValueError("nothing is free: give at least one free tendon (tendons=) or leave a tube's insertion free")
    if not isinstance(bounds, Bounds):
        raise TypeError(f"bounds must be a tdct.Bounds, got {type(bounds).__name__}")
    ins_bounds = (0.0, L) if bounds.insertion is None else bounds.insertion
    if bounds.insertion is not None and is_concrete(bounds.insertion):
        check_range("bounds.insertion", bounds.insertion, 0.0, float(L), unit=f" m (0 to the robot length {float(L):g} m)")
    if isinstance(objective, str):
        check_choice("objective", objective, tuple(SHORTHANDS))
        objective = SHORTHANDS[objective]()
    if objective is not None and type(objective) not in KINDS and not callable(objective):
        raise TypeError(
            f"objective = {objective!r}: expected tdct.Stiffness, tdct.LeastTension, tdct.PreferredInsertion, "
            f"a callable f(Solution, Actuation) -> scalar, or one of {tuple(SHORTHANDS)}"
        )
    if not isinstance(ik, IKOptions):
        raise TypeError(f"ik must be a tdct.IKOptions, got {type(ik).__name__}")
    direction = getattr(objective, "direction", None)
    preferred_insertion = getattr(objective, "depth", None)
    objective = KINDS.get(type(objective), objective)
    if objective == "insertion" and len(tubes) != 1:
        raise ValueError(
            f"objective = 'insertion': needs exactly one free tube, got tubes {tuple(t + 1 for t in tubes)} "
            f"of a robot with {n_tubes} tube(s)"
        )
    if direction is not None:
        direction = direction / array_module(direction).linalg.norm(direction)
    preferred = 0.5 * L if preferred_insertion is None else preferred_insertion
    if preferred_insertion is not None and is_concrete(preferred):
        check_range("PreferredInsertion.depth", preferred, 0.0, float(L), unit=" m")
    if is_concrete(target.position) and is_concrete(L):
        note = target_note("target position", np.asarray(target.position)[..., [AXES.index(a) for a in target.axes]], float(L))
        if note:
            warn_user(note, UnitWarning)
    free = len(tendons) + len(tubes)
    if objective is not None and free <= target.size:
        if n_tubes == 1:  # one tube (the paper's robot): the insertion
            inputs = f"tendons {tendons}{' and the insertion' if tubes else '; the insertion fixed'}"
        else:
            inputs = f"tendons {tendons}, tubes {tuple(t + 1 for t in tubes)}"
        raise ValueError(
            f"objective = {getattr(objective, '__name__', objective)!r}: nothing to choose: {free} free input(s) "
            f"({inputs}) for {target.size} task "
            f"coordinate(s) ({describe_task(target)}); an objective picks among solutions only with more free inputs "
            "than task coordinates: free more tendons (tendons=), leave the insertion free, or give fewer target axes "
            "(Target(..., axes=...))"
        )
    method = ik.method or ("nested" if objective == "stiffness" else "augmented")
    plan = Plan(tuple(t - 1 for t in tendons), tubes, objective, method)
    # numpy where the numbers are concrete: a JAX operation here costs a dispatch on every call
    scale = array_module(bounds.tension).maximum(bounds.tension[1], 1.0)
    lo, hi = _input_bounds(robot, base, plan, bounds, ins_bounds, scale)
    prob = Problem(
        robot=robot,
        target=target,
        load=load,
        gravity=gravity_vector(gravity),
        base=base,
        lo=lo,
        hi=hi,
        tension_scale=scale,
        solver=solver,
        preferred_insertion=array_module(preferred).asarray(preferred, float),
        direction=np.full(3, np.nan) if direction is None else array_module(direction).asarray(direction, float),
        options=ik,
    )
    if guess is None:
        start = _default_starts(prob, plan)
    else:
        start = jnp.clip(scaled_inputs(base, prob, plan), prob.lo, prob.hi)
        start = jnp.broadcast_to(start, (len(target.position),) + start.shape) if batched else start
    return prob, plan, start, np.full(6 + len(getattr(base, "driven", ())), np.nan)


@functools.partial(jax.jit, static_argnames=("plan",))
def _default_starts(prob: Problem, plan: Plan):
    """``default_start`` at the target position, or at each of a batch of them: one compiled
    program (op by op it would compile each of its few dozen operations on first use)."""
    positions = prob.target.position
    if jnp.ndim(positions) == 2:
        forces = jnp.broadcast_to(prob.load.tip_force, jnp.shape(positions))
        return jax.vmap(lambda p, f: default_start(prob, plan, p, f))(positions, forces)
    return default_start(prob, plan, positions, prob.load.tip_force)


def _free_tubes(tubes, insertion, n_tubes: int) -> tuple:
    """The free tubes, 0-based, from ``tubes=`` (numbered from 1; default all unless ``insertion``
    fixes them)."""
    if tubes is None:
        return () if insertion is not None else tuple(range(n_tubes))
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
    """Bounds (lo, hi) of v: tensions over ``scale`` (each capped by its tendon's ``max_tension``),
    displacements over DISPLACEMENT_SCALE L, insertions over L."""
    L, k = robot.length, len(plan.tendons)
    lo, hi = [bounds.tension[0] / scale] * k, [bounds.tension[1] / scale] * k
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
        hi[j] = array_module(cap, bounds.tension).minimum(bounds.tension[1], cap) / scale
    if moved:
        width = DISPLACEMENT_SCALE * L
        d_lo, d_hi = (-width, width) if bounds.displacement is None else bounds.displacement
        for j in moved:
            lo[j], hi[j] = d_lo / width, d_hi / width
    n = len(plan.tubes)
    lo, hi = lo + [ins_bounds[0] / L] * n, hi + [ins_bounds[1] / L] * n
    xp = array_module(*lo, *hi)
    return tuple(xp.stack([xp.asarray(b, float) for b in side]) for side in (lo, hi))
