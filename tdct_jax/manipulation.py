"""Object manipulation (paper Sec. V.A): tip load capacity (Fig. 14) and optimal insertion (Fig. 13).

One entry point per concept, like ``tdct.solve`` and ``tdct.sweep`` in one: ``capacity`` at one
configuration, and ``optimal_insertion`` given a bracket, are pure JAX (jit, vmap; ``capacity``
also grad, by implicit differentiation of its root); given a ``grid`` (or ``batch``), they run over
it in chunks with progress, like ``tdct.sweep``. ``load_capacity`` and ``insertion_optimum`` are
their former names.
"""

from __future__ import annotations

from functools import partial
from time import perf_counter
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from . import status
from .batch import Kernel, batch_options
from .checks import check_integer, deprecated, is_concrete
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
    robot: Robot | None = None,
    act: Actuation | None = None,
    *,
    grid=None,
    batch=None,
    height: float = 0.0,
    height_tol: float = HEIGHT_TOL,
    max_steps: int = MAX_STEPS,
    gravity=STANDARD_GRAVITY,
    solver: SolverOptions = DEFAULT_SOLVER,
    throw: bool = True,
    **batching,
):
    """Load capacity (Fig. 14): the tip mass m at which the tip height y(L) falls to ``height`` [m].

    Safeguarded Newton on m with the exact derivative dy/dm from forward-mode autodiff; a
    bracket [lo, hi] with y(lo) > height >= y(hi) catches steps that overshoot or fail to
    converge. At one configuration the root is differentiable (``lax.custom_root``): d m /
    d(robot, act) comes from the implicit function theorem, so robot parameters can be fitted to
    measured capacities.

    Args:
        robot, act: the robot and its actuation (the tip mass replaces any tip load); defaults
            as for ``tdct.sweep``.
        grid, batch: (optional) inputs to vary, as for ``tdct.sweep``; without them, one
            configuration.
        height: target tip height y [m] (world frame, base at 0).
        height_tol: tolerance on the tip height [m] (the outer iteration's own).
        max_steps: most Newton steps on the mass.
        gravity: world gravity [m/s^2]; the tip mass weighs m * gravity.
        solver: SolverOptions for every solve.
        throw: raise ConvergenceError unless the result is SUCCESS (default, as everywhere),
            also where the tip cannot reach ``height`` at all (UNREACHABLE); over a grid, after
            the whole grid, naming the first such point.
        **batching: over a grid or batch, ``tdct.sweep``'s chunk_size, progress and devices.

    Returns:
        One configuration: Capacity (mass [kg], reachable, iterations, result), pure JAX.
        A grid or batch: CapacityResult with those per point.
    """
    own = dict(height=height, height_tol=height_tol, max_steps=max_steps)
    if grid is None and batch is None:
        _no_batching("capacity", batching)
        return _capacity_one(robot, act, **own, gravity=gravity, solver=solver, throw=throw)
    return _capacity_grid(robot, act, grid, batch, own, gravity, solver, throw, batching)


def _no_batching(what: str, batching: dict) -> None:
    """Refuses batching options where there is no grid to batch."""
    if batching:
        raise TypeError(f"{what}: {sorted(batching)} apply over a grid or batch; give grid= or batch=")


def _capacity_one(robot, act, *, height, height_tol, max_steps, gravity, solver, throw) -> Capacity:
    """``capacity`` at one configuration."""
    robot, act, _ = problem(Robot.paper() if robot is None else robot, act, Loads(), solver)
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


def _optimum_one(robot, act, load, lo, hi, *, slope_tol, max_steps, gravity, solver, throw) -> Optimum:
    """``optimal_insertion`` inside a bracket ``[lo, hi]`` [m] of the slope's sign change.

    The Illinois (modified regula falsi) method on the exact slope dy/dd from autodiff: no
    second derivatives, superlinear convergence, never leaves the bracket. With lo == hi (an
    optimum at d = 0 or d = L) it evaluates that end.
    """
    _first_tube(robot, "optimal_insertion")
    gravity, load = gravity_vector(gravity), Loads() if load is None else load
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
    return _capacity_one(robot, act, **options)._asdict()


def _optimum_point(base, point, kernel: Kernel):
    robot, act, load = configure(base, point)
    options = dict(kernel.options, gravity=base[3], solver=base[4], throw=False)
    return _optimum_one(robot, act, load, point["lo"], point["hi"], **options)._asdict()


BATCHING = ("chunk_size", "progress", "devices")


def _batching(what: str, batching: dict) -> dict:
    """Refuses keyword arguments that are neither the entry point's own nor ``tdct.sweep``'s batching options."""
    unknown = sorted(set(batching) - set(BATCHING))
    if unknown:
        raise TypeError(f"{what}: unknown argument(s) {unknown}; the batching options are {list(BATCHING)}")
    return batching


def _capacity_grid(robot, act, grid, batch, own, gravity, solver, throw, batching) -> CapacityResult:
    """``capacity`` over a grid or batch, in chunks with progress."""
    check_integer("max_steps", own["max_steps"])
    run = batch_options(**_batching("capacity", batching))
    base, points, shape, axes = prepare(robot, act, None, grid, batch, gravity=gravity, solver=solver, single=True)
    start = perf_counter()
    out = unflatten(run(Kernel(_capacity_point, tuple(sorted(own.items()))), base, points, desc="load capacity"), shape)
    unreachable = _unreachable(own["height"])
    status.check(out["result"], throw=throw, what="the load capacity", max_steps=own["max_steps"], unreachable=unreachable)
    return CapacityResult(shape=shape, axes=axes, inputs=unflatten(points, shape), seconds=perf_counter() - start, **out)


def load_capacity(robot=None, act=None, *, grid=None, batch=None, solver: SolverOptions = DEFAULT_SOLVER, throw=True, **options):
    """Former name of ``capacity`` over a grid (a CapacityResult even without one)."""
    deprecated("tdct.load_capacity", "tdct.capacity(robot, act, grid=...)")
    own = {k: options.pop(k) for k in ("height", "height_tol", "max_steps") if k in options}
    own = dict(dict(height=0.0, height_tol=HEIGHT_TOL, max_steps=MAX_STEPS), **own)
    gravity = options.pop("gravity", STANDARD_GRAVITY)
    return _capacity_grid(robot, act, grid, batch, own, gravity, solver, throw, options)


def optimal_insertion(
    robot: Robot | None = None,
    act: Actuation | None = None,
    load: Loads | None = None,
    *,
    bracket=None,
    grid=None,
    n_curve: int = 33,
    slope_tol: float = SLOPE_TOL,
    max_steps: int = MAX_STEPS,
    gravity=STANDARD_GRAVITY,
    solver: SolverOptions = DEFAULT_SOLVER,
    throw: bool = True,
    **batching,
):
    """Insertion depth of the first tube that maximises the tip height y_tip (Fig. 13); any other
    tubes stay where ``act`` puts them.

    Without a ``bracket``: first the curve y_tip(d) on ``n_curve`` depths from 0 to L (one
    sweep); its highest point brackets the optimum, which is then refined as below, at one
    configuration or at every point of a ``grid``. With ``bracket=(lo, hi)`` [m] of the slope's
    sign change: the refinement alone, pure JAX (jit, vmap), by the Illinois (modified regula
    falsi) method on the exact slope dy/dd from autodiff: no second derivatives, superlinear
    convergence, never leaves the bracket (lo == hi evaluates that end, an optimum at 0 or L).

    Args:
        robot, act, load: as for ``tdct.sweep``.
        bracket: (optional) (lo, hi) [m]: refine inside it only.
        grid: (optional) varies the other inputs, e.g. {"tip_mass": ..., "tensions": ...}.
        n_curve: depths on the curve, >= 3.
        slope_tol: tolerance on |dy/dd| (dimensionless), the refinement's own.
        max_steps: most Illinois steps.
        gravity: world gravity [m/s^2].
        solver: SolverOptions for every solve.
        throw: raise ConvergenceError unless the result is SUCCESS (default, as everywhere); over
            a grid, after the whole grid, naming the first failed point.
        **batching: without a bracket, ``tdct.sweep``'s chunk_size, progress and devices.

    Returns:
        With a bracket: Optimum (insertion [m], height [m], slope, iterations, result).
        Otherwise: OptimumResult with those per point, and interior, curve_insertion (n_curve,)
        [m] and curve_height (shape + (n_curve,)) [m].
    """
    own = dict(slope_tol=slope_tol, max_steps=max_steps)
    if bracket is not None:
        _no_batching("optimal_insertion with a bracket", batching)
        if grid is not None:
            raise TypeError("optimal_insertion: give either bracket= (one configuration) or grid=, not both")
        lo, hi = bracket
        robot = Robot.paper() if robot is None else robot
        return _optimum_one(robot, act, load, lo, hi, **own, gravity=gravity, solver=solver, throw=throw)
    if grid is not None and ("insertion" in grid or "insertions" in grid):
        raise ValueError("optimal_insertion: the insertion is what is optimised; do not put it in grid")
    check_integer("n_curve", n_curve, 3)
    check_integer("max_steps", max_steps)
    shared = dict(gravity=gravity, solver=solver)
    batching = _batching("optimal_insertion", batching)
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
    kernel = Kernel(_optimum_point, tuple(sorted(own.items())))
    out = unflatten(run(kernel, base, points, desc="optimal insertion"), shape)
    curve_result = curve.result.reshape(*shape, n_curve)
    failed_curve = np.where(curve_result != status.SUCCESS, curve_result, 0).max(axis=-1)
    out["result"] = np.where(out["result"] == status.SUCCESS, failed_curve, out["result"]).astype(np.int32)
    status.check(out["result"], throw=throw, what="the optimal insertion", max_steps=max_steps)
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


def insertion_optimum(robot, act, load, lo, hi, **options) -> Optimum:
    """Former name of ``optimal_insertion(robot, act, load, bracket=(lo, hi))``."""
    deprecated("tdct.insertion_optimum", "tdct.optimal_insertion(robot, act, load, bracket=(lo, hi))")
    return optimal_insertion(robot, act, load, bracket=(lo, hi), **options)
