"""Object manipulation (paper Sec. V.A): tip load capacity (Fig. 14) and optimal insertion (Fig. 13).

``capacity`` and ``insertion_optimum`` are pure JAX (jit, vmap; ``capacity`` also grad, by
implicit differentiation of its root). ``load_capacity`` and ``optimal_insertion`` run them over
grids in chunks with progress, like ``tdct.sweep``.
"""

from __future__ import annotations

import inspect
from functools import partial
from time import perf_counter
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from . import status
from .batch import Kernel, batch_options
from .checks import check_integer, is_concrete
from .description import Robot
from .inputs import STANDARD_GRAVITY, Actuation, Loads, gravity_vector
from .options import DEFAULT_SOLVER, SolverOptions
from .results import CapacityResult, OptimumResult
from .solve import problem, solve
from .sweep import configure, prepare, sweep, unflatten

HEIGHT_TOL = 1e-9
"""Default tolerance on the tip height [m] for the load capacity."""
SLOPE_TOL = 1e-9
"""Default tolerance on d y_tip / d insertion (dimensionless) at the optimal insertion."""
MAX_STEPS = 30
"""Default limit on the outer iterations (Newton steps on the mass, Illinois steps on the depth)."""


class Capacity(NamedTuple):
    """Largest tip mass [kg] that the tip lifts to the target height; ``reachable`` is False (mass
    0, result UNREACHABLE) when even the unloaded tip stays below it. ``iterations``: Newton steps
    on the mass; ``result``: a ``tdct_jax.status`` code (SUCCESS, UNREACHABLE, OUTER_LIMIT, or the
    failed solve's code)."""

    mass: jax.Array
    reachable: jax.Array
    iterations: jax.Array
    result: jax.Array

    @property
    def converged(self):
        return self.result == status.SUCCESS


def _tip_height(robot, act, load, mass, depth, gravity, solver, guess=None):
    """Tip height y(L) [m] and the solution, with ``mass`` [kg] hung at the tip and the first tube
    ``depth`` [m] deeper (None: the insertions as they are, for a robot with or without tubes)."""
    if depth is not None:
        insertions = jnp.asarray(act.insertions).at[..., 0].add(depth)
        act = Actuation._rebuild(act.tensions, insertions, act.displacements, act.driven)
    load = load.with_tip(load.tip_force + mass * gravity)
    sol = solve(robot, act, load, gravity=gravity, solver=solver, guess=guess, throw=False)
    return sol.tip_position[1], sol


def _first_tube(robot, what: str) -> None:
    """Refuses a robot without a tube where the first tube's insertion is what is sought."""
    if robot.n_tubes < 1:
        raise ValueError(f"{what}: the robot has no tube; the insertion optimised is its first tube's")


def _height_and_slope(height_at, x):
    """height_at(x) = (y, solution); returns y, dy/dx (forward-mode autodiff), ok, solution."""
    y, dy, sol = jax.jvp(height_at, (x,), (jnp.ones_like(x),), has_aux=True)
    return y, dy, sol.converged & jnp.isfinite(y) & jnp.isfinite(dy), sol


def _failed_solve(sol):
    """The solve's own code where it failed, else NONFINITE (a non-finite height or slope)."""
    return jnp.where(sol.converged, status.NONFINITE, sol.result)


def capacity(
    robot: Robot,
    act: Actuation,
    *,
    height: float = 0.0,
    height_tol: float = HEIGHT_TOL,
    max_steps: int = MAX_STEPS,
    gravity=STANDARD_GRAVITY,
    solver: SolverOptions = DEFAULT_SOLVER,
    throw: bool = True,
) -> Capacity:
    """Load capacity (Fig. 14): the tip mass m at which the tip height y(L) falls to ``height`` [m].

    Safeguarded Newton on m with the exact derivative dy/dm from forward-mode autodiff; a
    bracket [lo, hi] with y(lo) > height >= y(hi) catches steps that overshoot or fail to
    converge. The root is differentiable (``lax.custom_root``): d m / d(robot, act) comes from
    the implicit function theorem, so robot parameters can be fitted to measured capacities.

    Args:
        robot, act: the robot and its actuation (the tip mass replaces any tip load).
        height: target tip height y [m] (world frame, base at 0).
        height_tol: tolerance on the tip height [m] (the outer iteration's own).
        max_steps: most Newton steps on the mass.
        gravity: world gravity [m/s^2]; the tip mass weighs m * gravity.
        solver: SolverOptions for every solve.
        throw: raise ConvergenceError unless the result is SUCCESS (default, as everywhere),
            also where the tip cannot reach ``height`` at all (UNREACHABLE).

    Returns:
        Capacity (mass [kg], reachable, iterations, result).
    """
    robot, act, _ = problem(robot, act, Loads(), solver)
    max_steps = check_integer("max_steps", max_steps)
    cap = _capacity(robot, act, height, height_tol, gravity_vector(gravity), solver, max_steps)
    status.check(cap.result, throw=throw, what="the load capacity", max_steps=max_steps, unreachable=_unreachable(height))
    return cap


@partial(jax.jit, static_argnames=("max_steps",))
def _capacity(robot, act, height, height_tol, gravity, solver, max_steps) -> Capacity:
    """``capacity`` without its checks, compiled once per robot structure, solver and ``max_steps``
    (its loop and root close over new functions at each call, which would otherwise compile again)."""
    load = Loads()

    def f(m):
        return _tip_height(robot, act, load, m, None, gravity, solver)[0] - height

    def search(_, m0):
        def probe(m, guess):
            y, dy, ok, sol = _height_and_slope(lambda m: _tip_height(robot, act, load, m, None, gravity, solver, guess), m)
            return y - height, dy, ok, jnp.where(ok, sol.base_wrench, guess), _failed_solve(sol)

        def not_done(c):
            m, y, dy, lo, hi, w, it, y0, ok0, code0 = c
            return (it == 0) | ((y0 > 0) & ok0 & (it <= max_steps) & (jnp.abs(y) > height_tol))

        def body(c):
            m, y, dy, lo, hi, w, it, y0, ok0, code0 = c
            newton = m - y / dy
            inside = (dy < 0) & (newton > lo) & (newton < hi)
            widen = jnp.where(jnp.isfinite(hi), (lo + hi) / 2, 2 * jnp.maximum(m, 1e-3))
            m_new = jnp.where(it == 0, m0, jnp.where(inside, newton, widen))
            y_new, dy_new, ok, w, code = probe(m_new, w)
            y0, ok0, code0 = (jnp.where(it == 0, a, b) for a, b in ((y_new, y0), (ok, ok0), (code, code0)))
            above = ok & (y_new > 0)
            lo, hi = jnp.where(above, m_new, lo), jnp.where(above, hi, m_new)
            m, y, dy = (jnp.where(ok | (it == 0), a, b) for a, b in ((m_new, m), (y_new, y), (dy_new, dy)))
            return m, y, dy, lo, hi, w, it + 1, y0, ok0, code0

        init = (m0, jnp.inf, -1.0, m0, jnp.inf, jnp.full(6, jnp.nan), 0, jnp.inf, True, status.SUCCESS)
        m, y, _, _, _, _, it, y0, ok0, code0 = lax.while_loop(not_done, body, init)
        reachable = ok0 & (y0 > 0)
        met = jnp.where(jnp.abs(y) <= height_tol, status.SUCCESS, status.OUTER_LIMIT)
        result = jnp.where(~ok0, code0, jnp.where(reachable, met, status.UNREACHABLE))
        return m, (reachable.astype(float), result.astype(float), (it - 1).astype(float))

    m, (reachable, result, it) = lax.custom_root(f, jnp.zeros(()), search, lambda g, y: y / g(jnp.ones_like(y)), has_aux=True)
    reachable = reachable > 0.5
    return Capacity(jnp.where(reachable, m, 0.0), reachable, it.astype(jnp.int32), jnp.round(result).astype(jnp.int32))


def _unreachable(height) -> str:
    """What UNREACHABLE means for a load capacity at ``height`` [m]."""
    where = f"the height y = {float(height):g} m" if is_concrete(height) else "the target height"
    return f"even with no tip mass the tip stays below {where}, so it holds no mass there (mass 0, reachable False)"


class Optimum(NamedTuple):
    """Insertion depth [m] that maximises the tip height, the height there [m], its slope dy/dd,
    Illinois steps taken, and a ``tdct_jax.status`` code."""

    insertion: jax.Array
    height: jax.Array
    slope: jax.Array
    iterations: jax.Array
    result: jax.Array

    @property
    def converged(self):
        return self.result == status.SUCCESS


def insertion_optimum(
    robot: Robot,
    act: Actuation,
    load: Loads,
    lo,
    hi,
    *,
    slope_tol: float = SLOPE_TOL,
    max_steps: int = MAX_STEPS,
    gravity=STANDARD_GRAVITY,
    solver: SolverOptions = DEFAULT_SOLVER,
    throw: bool = True,
) -> Optimum:
    """Refines the insertion that maximises y_tip inside a bracket ``[lo, hi]`` [m] of the slope's sign change.

    The Illinois (modified regula falsi) method on the exact slope dy/dd from autodiff: no
    second derivatives, superlinear convergence, never leaves the bracket. With lo == hi (an
    optimum at d = 0 or d = L) it evaluates that end. ``slope_tol`` is its own tolerance on
    |dy/dd|, ``max_steps`` its own limit; ``solver`` and ``throw`` as for ``capacity``.
    """
    _first_tube(robot, "insertion_optimum")
    gravity = gravity_vector(gravity)
    act = Actuation.of(act, robot)
    insertions = jnp.asarray(act.insertions).at[..., 0].set(0.0)  # the first tube's depth is sought
    act = Actuation._rebuild(act.tensions, insertions, act.displacements, act.driven)

    def probe(d):
        y, dy, ok, sol = _height_and_slope(lambda d: _tip_height(robot, act, load, 0.0, d, gravity, solver), d)
        return y, dy, ok, _failed_solve(sol)

    def not_done(c):
        a, ga, b, gb, y, ok, code, it = c
        return (it < 2) | (ok & (it < max_steps + 2) & (jnp.abs(gb) > slope_tol) & (jnp.abs(b - a) > 1e-12) & (ga * gb < 0))

    def body(c):
        a, ga, b, gb, y, ok, code, it = c
        x = jnp.where(it == 0, lo, jnp.where(it == 1, hi, (a * gb - b * ga) / (gb - ga)))
        y, g, ok_x, code_x = probe(x)
        keep = (it == 1) | (g * gb > 0)
        a, ga = (
            jnp.where(it == 0, x, jnp.where(keep, a, b)),
            jnp.where(it == 0, g, jnp.where(keep, ga / jnp.where(it == 1, 1, 2), gb)),
        )
        b, gb = jnp.where(it == 0, b, x), jnp.where(it == 0, gb, g)
        return a, ga, b, gb, y, ok & ok_x, jnp.where(ok & ~ok_x, code_x, code), it + 1

    init = (lo, jnp.nan, hi, jnp.nan, jnp.nan, True, status.SUCCESS, 0)
    _, ga, d, g, y, ok, code, it = lax.while_loop(not_done, body, init)
    met = (hi <= lo) | (jnp.abs(g) <= slope_tol)
    result = jnp.where(ok, jnp.where(met, status.SUCCESS, status.OUTER_LIMIT), code).astype(jnp.int32)
    opt = Optimum(d, y, g, it - 2, result)
    status.check(opt.result, throw=throw, what="the insertion optimum", max_steps=max_steps)
    return opt


def _capacity_point(base, point, kernel: Kernel):
    robot, act, _ = configure(base, point)
    options = dict(kernel.options, gravity=base[3], solver=base[4], throw=False)
    return capacity(robot, act, **options)._asdict()


def _optimum_point(base, point, kernel: Kernel):
    robot, act, load = configure(base, point)
    options = dict(kernel.options, gravity=base[3], solver=base[4], throw=False)
    return insertion_optimum(robot, act, load, point["lo"], point["hi"], **options)._asdict()


def _grid_options(f, options: dict, solver: SolverOptions) -> tuple[dict, dict, tuple]:
    """Splits a grid entry point's keyword options into the batching options (as for
    ``tdct.sweep``), gravity and solver (shared by every point), and f's own (static, per point)."""
    batching = {k: options.pop(k) for k in ("chunk_size", "progress", "devices") if k in options}
    shared = {"gravity": options.pop("gravity", inspect.signature(f).parameters["gravity"].default), "solver": solver}
    allowed = {k for k, p in inspect.signature(f).parameters.items() if p.kind is p.KEYWORD_ONLY} - {"throw"}
    unknown = sorted(set(options) - allowed)
    if unknown:
        raise TypeError(f"{f.__name__} over a grid: unknown argument(s) {unknown}; allowed: {sorted(allowed)}")
    options.setdefault("max_steps", MAX_STEPS)
    check_integer("max_steps", options["max_steps"])
    return batching, shared, tuple(sorted(options.items()))


def load_capacity(
    robot=None, act=None, *, grid=None, batch=None, solver: SolverOptions = DEFAULT_SOLVER, throw=True, **options
) -> CapacityResult:
    """``capacity`` at one configuration or over a ``grid`` / ``batch`` of inputs (see ``tdct.sweep``).

    Args:
        robot, act, grid, batch: as for ``tdct.sweep`` (the tip mass is what is sought).
        solver: SolverOptions for every solve.
        throw: raise ConvergenceError after the whole grid, naming the first failed or
            unreachable point (default, as everywhere); with False they stay in ``result`` per
            point (UNREACHABLE where the tip cannot reach the height: mass 0).
        **options: ``capacity``'s other keyword arguments (height, height_tol, max_steps,
            gravity) and the batching options of ``tdct.sweep`` (chunk_size, progress, devices).

    Returns:
        CapacityResult with mass [kg], reachable, iterations and result per point.
    """
    batching, shared, own = _grid_options(capacity, options, solver)
    base, points, shape, axes = prepare(robot, act, None, grid, batch, **shared, single=True)
    run = batch_options(**batching)
    start = perf_counter()
    out = unflatten(run(Kernel(_capacity_point, own), base, points, desc="load capacity"), shape)
    own_options = dict(own)
    unreachable = _unreachable(own_options.get("height", 0.0))
    status.check(
        out["result"], throw=throw, what="the load capacity", max_steps=own_options["max_steps"], unreachable=unreachable
    )
    return CapacityResult(shape=shape, axes=axes, inputs=unflatten(points, shape), seconds=perf_counter() - start, **out)


def optimal_insertion(
    robot=None, act=None, load=None, *, grid=None, n_curve=33, solver: SolverOptions = DEFAULT_SOLVER, throw=True, **options
) -> OptimumResult:
    """Insertion depth of the first tube that maximises the tip height y_tip (Fig. 13), with the
    curve y_tip(d); any other tubes stay where ``act`` puts them.

    First the curve on ``n_curve`` depths from 0 to L (one sweep); its highest point brackets
    the optimum, which ``insertion_optimum`` refines to a zero of the exact slope.

    Args:
        robot, act, load: as for ``tdct.sweep``.
        grid: (optional) varies the other inputs, e.g. {"tip_mass": ..., "tensions": ...}.
        n_curve: depths on the curve, >= 3.
        solver: SolverOptions for every solve.
        throw: as for ``load_capacity``.
        **options: ``insertion_optimum``'s other keyword arguments (slope_tol, max_steps,
            gravity) and the batching options of ``tdct.sweep`` (chunk_size, progress, devices).

    Returns:
        OptimumResult with insertion [m], height [m], slope, iterations, result, interior,
        curve_insertion (n_curve,) [m] and curve_height (shape + (n_curve,)) [m].
    """
    if grid is not None and ("insertion" in grid or "insertions" in grid):
        raise ValueError("optimal_insertion: the insertion is what is optimised; do not put it in grid")
    check_integer("n_curve", n_curve, 3)
    batching, shared, own = _grid_options(insertion_optimum, options, solver)
    base, points, shape, axes = prepare(robot, act, load, grid, None, **shared, single=True)
    robot, act, load = base[:3]
    _first_tube(robot, "optimal_insertion")
    run = batch_options(**batching)
    start = perf_counter()
    depths = np.linspace(0.0, float(robot.length), n_curve)
    if robot.n_tubes == 1:
        grid = {**(grid or {}), "insertion": depths}
    else:  # the first tube moves, the others stay
        curve_insertions = np.repeat(np.asarray(act.insertions, dtype=float)[None], n_curve, axis=0)
        curve_insertions[:, 0] = depths
        grid = {**(grid or {}), "insertions": curve_insertions}
    curve = sweep(robot, act, load, grid=grid, **shared, throw=False, **batching)
    heights = curve.tip_position[..., 1].reshape(-1, n_curve)
    k = np.argmax(heights, axis=1)
    interior = (k > 0) & (k < n_curve - 1)
    points["lo"] = np.where(interior, depths[np.maximum(k - 1, 0)], depths[k])
    points["hi"] = np.where(interior, depths[np.minimum(k + 1, n_curve - 1)], depths[k])
    kernel = Kernel(_optimum_point, own)
    out = unflatten(run(kernel, base, points, desc="optimal insertion"), shape)
    curve_result = curve.result.reshape(*shape, n_curve)
    failed_curve = np.where(curve_result != status.SUCCESS, curve_result, 0).max(axis=-1)
    out["result"] = np.where(out["result"] == status.SUCCESS, failed_curve, out["result"]).astype(np.int32)
    status.check(out["result"], throw=throw, what="the optimal insertion", max_steps=dict(own)["max_steps"])
    inputs = unflatten({k: v for k, v in points.items() if k not in ("lo", "hi")}, shape)
    return OptimumResult(
        shape=shape,
        axes=axes,
        inputs=inputs,
        seconds=perf_counter() - start,
        curve_insertion=depths,
        curve_height=heights.reshape(*shape, n_curve),
        interior=interior.reshape(shape),
        **out,
    )
