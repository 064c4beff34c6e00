"""Object manipulation (paper Sec. V.A): tip load capacity (Fig. 14) and optimal insertion (Fig. 13).

``capacity`` and ``insertion_optimum`` are pure JAX (jit, vmap; ``capacity`` also grad, by
implicit differentiation of its root). ``load_capacity`` and ``optimal_insertion`` run them over
grids in chunks with progress, like ``tdct.sweep``.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from pathlib import Path
from time import perf_counter
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from .loads import STANDARD_GRAVITY, Actuation, TipLoad
from .robot import Robot
from .shooting import gravity_vector, nested_solve_options, solve
from .sweep import Kernel, configure, mesh_for, prepare, run_batched, sweep, unflatten, write_csv, write_npz

HEIGHT_TOL = 1e-9
"""Default tolerance on the tip height [m] for the load capacity."""
SLOPE_TOL = 1e-9
"""Default tolerance on d y_tip / d insertion (dimensionless) at the optimal insertion."""


class Capacity(NamedTuple):
    """Largest tip mass [kg] that the tip lifts to the target height; ``reachable`` is False (and
    mass 0) when even the unloaded tip stays below it."""

    mass: jax.Array
    reachable: jax.Array
    converged: jax.Array
    iterations: jax.Array


def _tip_height(robot, act, load, mass, depth, options):
    """Tip height y(L) [m] and the solution, with ``mass`` [kg] hung at the tip and the tube ``depth`` [m] deeper."""
    act = Actuation(act.tensions, act.insertion + depth)
    load = TipLoad(load.force + mass * options["gravity"], load.moment)
    sol = solve(robot, act, load, **options)
    return sol.tip_position[1], sol


def _height_and_slope(height_at, x):
    """height_at(x) = (y, solution); returns y, dy/dx (forward-mode autodiff), ok, solution."""
    y, dy, sol = jax.jvp(height_at, (x,), (jnp.ones_like(x),), has_aux=True)
    return y, dy, sol.converged & jnp.isfinite(y) & jnp.isfinite(dy), sol


def capacity(
    robot: Robot,
    act: Actuation,
    *,
    height: float = 0.0,
    gravity=STANDARD_GRAVITY,
    tol: float = HEIGHT_TOL,
    max_iter: int = 30,
    **solve_options,
) -> Capacity:
    """Load capacity (Fig. 14): the tip mass m at which the tip height y(L) falls to ``height`` [m].

    Safeguarded Newton on m with the exact derivative dy/dm from forward-mode autodiff; a
    bracket [lo, hi] with y(lo) > height >= y(hi) catches steps that overshoot or fail to
    converge. The root is differentiable (``lax.custom_root``): d m / d(robot, act) comes from
    the implicit function theorem, so robot parameters can be fitted to measured capacities.

    Args:
        robot, act: the robot and its actuation (the tip mass replaces any tip load).
        height: target tip height y [m] (world frame, base at 0).
        gravity: world gravity [m/s^2]; the tip mass weighs m * gravity.
        tol: tolerance on the tip height [m].
        max_iter: most Newton steps.
        **solve_options: steps, transition, tendon_model, solve_tol, solve_max_iter for ``tdct.solve``.

    Returns:
        Capacity (mass [kg], reachable, converged, iterations).
    """
    options = dict(nested_solve_options(solve_options), gravity=gravity_vector(gravity))
    load = TipLoad()

    def f(m):
        return _tip_height(robot, act, load, m, 0.0, options)[0] - height

    def search(_, m0):
        def probe(m, guess):
            y, dy, ok, sol = _height_and_slope(lambda m: _tip_height(robot, act, load, m, 0.0, dict(options, guess=guess)), m)
            return y - height, dy, ok, jnp.where(ok, sol.base_wrench, guess)

        def not_done(c):
            m, y, dy, lo, hi, w, it, y0, ok0 = c
            return (it == 0) | ((y0 > 0) & ok0 & (it <= max_iter) & (jnp.abs(y) > tol))

        def body(c):
            m, y, dy, lo, hi, w, it, y0, ok0 = c
            newton = m - y / dy
            inside = (dy < 0) & (newton > lo) & (newton < hi)
            widen = jnp.where(jnp.isfinite(hi), (lo + hi) / 2, 2 * jnp.maximum(m, 1e-3))
            m_new = jnp.where(it == 0, m0, jnp.where(inside, newton, widen))
            y_new, dy_new, ok, w = probe(m_new, w)
            y0, ok0 = jnp.where(it == 0, y_new, y0), jnp.where(it == 0, ok, ok0)
            above = ok & (y_new > 0)
            lo, hi = jnp.where(above, m_new, lo), jnp.where(above, hi, m_new)
            m, y, dy = (jnp.where(ok | (it == 0), a, b) for a, b in ((m_new, m), (y_new, y), (dy_new, dy)))
            return m, y, dy, lo, hi, w, it + 1, y0, ok0

        init = (m0, jnp.inf, -1.0, m0, jnp.inf, jnp.full(6, jnp.nan), 0, jnp.inf, True)
        m, y, _, _, _, _, it, y0, ok0 = lax.while_loop(not_done, body, init)
        reachable = ok0 & (y0 > 0)
        converged = ~reachable & ok0 | (jnp.abs(y) <= tol)
        return m, (reachable.astype(float), converged.astype(float), (it - 1).astype(float))

    m, (reachable, converged, it) = lax.custom_root(f, jnp.zeros(()), search, lambda g, y: y / g(jnp.ones_like(y)), has_aux=True)
    reachable = reachable > 0.5
    return Capacity(jnp.where(reachable, m, 0.0), reachable, converged > 0.5, it.astype(jnp.int32))


class Optimum(NamedTuple):
    """Insertion depth [m] that maximises the tip height, the height there [m] and its slope."""

    insertion: jax.Array
    height: jax.Array
    slope: jax.Array
    converged: jax.Array
    iterations: jax.Array


def insertion_optimum(
    robot, act, load, lo, hi, *, gravity=STANDARD_GRAVITY, tol=SLOPE_TOL, max_iter=30, **solve_options
) -> Optimum:
    """Refines the insertion that maximises y_tip inside a bracket [lo, hi] [m] of the slope's sign change.

    The Illinois (modified regula falsi) method on the exact slope dy/dd from autodiff: no
    second derivatives, superlinear convergence, never leaves the bracket. With lo == hi (an
    optimum at d = 0 or d = L) it evaluates that end.
    """
    options = dict(nested_solve_options(solve_options), gravity=gravity_vector(gravity))
    act = Actuation(act.tensions, jnp.zeros(()))

    def probe(d):
        y, dy, ok, _ = _height_and_slope(lambda d: _tip_height(robot, act, load, 0.0, d, options), d)
        return y, dy, ok

    def not_done(c):
        a, ga, b, gb, y, ok, it = c
        return (it < 2) | (ok & (it < max_iter + 2) & (jnp.abs(gb) > tol) & (jnp.abs(b - a) > 1e-12) & (ga * gb < 0))

    def body(c):
        a, ga, b, gb, y, ok, it = c
        x = jnp.where(it == 0, lo, jnp.where(it == 1, hi, (a * gb - b * ga) / (gb - ga)))
        y, g, ok_x = probe(x)
        keep = (it == 1) | (g * gb > 0)
        a, ga = (
            jnp.where(it == 0, x, jnp.where(keep, a, b)),
            jnp.where(it == 0, g, jnp.where(keep, ga / jnp.where(it == 1, 1, 2), gb)),
        )
        b, gb = jnp.where(it == 0, b, x), jnp.where(it == 0, gb, g)
        return a, ga, b, gb, y, ok & ok_x, it + 1

    init = (lo, jnp.nan, hi, jnp.nan, jnp.nan, True, 0)
    _, ga, d, g, y, ok, it = lax.while_loop(not_done, body, init)
    converged = ok & ((hi <= lo) | (jnp.abs(g) <= tol))
    it = it - 2
    return Optimum(d, y, g, converged, it)


@dataclasses.dataclass(frozen=True)
class GridResult:
    """Per-point outputs (numpy) of ``load_capacity`` or ``optimal_insertion`` over a grid.

    Attributes:
        shape, axes, inputs: as on ``SweepResult``.
        values: the outputs by name, each with leading axes ``shape`` (Capacity or Optimum fields;
            ``optimal_insertion`` adds ``curve_insertion`` [m] and ``curve_height`` [m]).
        seconds: wall time, compiles included.
    """

    shape: tuple
    axes: dict | None
    inputs: dict
    values: dict
    seconds: float

    def save_npz(self, path) -> Path:
        """Writes every array to a compressed .npz (inputs as ``input_<name>``, axes as ``axis_<name>``)."""
        return write_npz(path, self.shape, self.axes, self.inputs, self.values)

    def save_csv(self, path) -> Path:
        """Writes one row per point: the inputs and the per-point values, SI units in the header."""
        units = dict(mass="kg", insertion="m", height="m", slope="1")
        per_point = {k: v for k, v in self.values.items() if np.shape(v) == self.shape}
        return write_csv(path, self.shape, self.inputs, {f"{k}_{units[k]}" if k in units else k: v for k, v in per_point.items()})

    def __getattr__(self, name):
        values = self.__dict__.get("values", {})
        if name in values:
            return values[name]
        raise AttributeError(name)


def _capacity_point(base, point, kernel: Kernel):
    robot, act, _ = configure(base, point)
    return capacity(robot, act, gravity=base[3], **kernel.options)._asdict()


def _optimum_point(base, point, kernel: Kernel):
    robot, act, load = configure(base, point)
    return insertion_optimum(robot, act, load, point["lo"], point["hi"], gravity=base[3], **kernel.options)._asdict()


def _batch(robot, act, load, grid, batch, solve_options):
    """``sweep.prepare`` for one configuration or a grid / batch, plus the checked solve options."""
    return *prepare(robot, act, load, grid, batch, single=True), nested_solve_options(solve_options)


def load_capacity(
    robot: Robot | None = None,
    act: Actuation | None = None,
    *,
    grid: Mapping | None = None,
    batch: Mapping | None = None,
    height: float = 0.0,
    tol: float = HEIGHT_TOL,
    max_iter: int = 30,
    chunk_size: int | None = None,
    progress: bool = True,
    devices=None,
    gravity=STANDARD_GRAVITY,
    **solve_options,
) -> GridResult:
    """``capacity`` at one configuration or over a ``grid`` / ``batch`` of inputs (see ``tdct.sweep``).

    ``solve_options``: steps, transition, tendon_model, solve_tol, solve_max_iter.

    Returns:
        GridResult with values mass [kg], reachable, converged, iterations.
    """
    robot, act, load, points, shape, axes, _ = _batch(robot, act, None, grid, batch, solve_options)
    kernel = Kernel(
        _capacity_point, tuple(dict(solve_options, height=height, tol=tol, max_iter=max_iter).items()), mesh=mesh_for(devices)
    )
    start = perf_counter()
    g = gravity_vector(gravity)
    out = run_batched(kernel, (robot, act, load, g), points, chunk_size=chunk_size, progress=progress, desc="load capacity")
    return GridResult(shape, axes, unflatten(points, shape), unflatten(out, shape), perf_counter() - start)


def optimal_insertion(
    robot: Robot | None = None,
    act: Actuation | None = None,
    load: TipLoad | None = None,
    *,
    grid: Mapping | None = None,
    n_curve: int = 33,
    tol: float = SLOPE_TOL,
    max_iter: int = 30,
    chunk_size: int | None = None,
    progress: bool = True,
    devices=None,
    gravity=STANDARD_GRAVITY,
    **solve_options,
) -> GridResult:
    """Insertion depth that maximises the tip height y_tip (Fig. 13), with the curve y_tip(d).

    First the curve on ``n_curve`` depths from 0 to L (one sweep); its highest point brackets
    the optimum, which ``insertion_optimum`` refines to a zero of the exact slope. ``grid``
    (optional) varies the other inputs, e.g. {"tip_mass": ..., "tensions": ...}.
    ``solve_options``: steps, transition, tendon_model, solve_tol, solve_max_iter.

    Returns:
        GridResult with values insertion [m], height [m], slope, converged, iterations,
        curve_insertion (n_curve,) [m] and curve_height (shape + (n_curve,)) [m].
    """
    if grid is not None and "insertion" in grid:
        raise ValueError("optimal_insertion: the insertion is what is optimised; do not put it in grid")
    if not isinstance(n_curve, (int, np.integer)) or n_curve < 3:
        raise ValueError(f"n_curve = {n_curve!r} must be an integer >= 3")
    robot, act, load, points, shape, axes, options = _batch(robot, act, load, grid, None, solve_options)
    start = perf_counter()
    depths = np.linspace(0.0, float(robot.length), n_curve)
    curve = sweep(
        robot,
        act,
        load,
        grid={**(grid or {}), "insertion": depths},
        chunk_size=chunk_size,
        progress=progress,
        devices=devices,
        gravity=gravity,
        **options,
    )
    heights = curve.tip_position[..., 1].reshape(-1, n_curve)
    k = np.argmax(heights, axis=1)
    interior = (k > 0) & (k < n_curve - 1)
    points["lo"] = np.where(interior, depths[np.maximum(k - 1, 0)], depths[k])
    points["hi"] = np.where(interior, depths[np.minimum(k + 1, n_curve - 1)], depths[k])
    kernel = Kernel(_optimum_point, tuple(dict(solve_options, tol=tol, max_iter=max_iter).items()), mesh=mesh_for(devices))
    g = gravity_vector(gravity)
    out = run_batched(kernel, (robot, act, load, g), points, chunk_size=chunk_size, progress=progress, desc="optimal insertion")
    values = unflatten(out, shape)
    values["converged"] = values["converged"] & curve.converged.reshape(*shape, n_curve).all(axis=-1)
    values.update(curve_insertion=depths, curve_height=heights.reshape(*shape, n_curve), interior=interior.reshape(shape))
    inputs = unflatten({k: v for k, v in points.items() if k not in ("lo", "hi")}, shape)
    return GridResult(shape, axes, inputs, values, perf_counter() - start)
