"""Sweeps: many solves over a grid or batch of inputs, run by the batch engine.

A sweep varies named inputs around a base configuration: the actuation ("tensions" [N],
"insertions" [m], one per tube, or "insertion" for a robot with one tube, "displacements" [m],
one per displacement-driven tendon of the base Actuation), the loads (tip "force" [N], "moment"
[N m], "tip_mass" [kg], whose weight adds to the force, the base Loads' "point_force" and
"point_moment") and the robot's fields by name (fields.py: "sections[*].E" [Pa],
"tendons[3].offset" [m], ...). A
``grid`` takes the product of axes; a ``batch`` zips columns of equal length. Results come back
whole (``sweep``), chunk by chunk (``sweep_chunks``), or streamed to an .npz file (``sweep(out=)``,
one part per process after ``jax.distributed.initialize``, read back by ``tdct.gather``).
"""

from __future__ import annotations

import dataclasses
import inspect
import math
import os
import sys
from collections.abc import Collection, Iterator, Mapping
from pathlib import Path
from time import perf_counter
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from . import fields, status
from .batch import Kernel, batch_solver, chunk_lanes, iter_batched, joined, mesh_for
from .checkpoint import Partial, complete, digest
from .checks import as_array, check_output, check_range
from .description import Robot
from .inputs import STANDARD_GRAVITY, Actuation, Loads, gravity_vector
from .mechanics import compliance_and_solution
from .options import DEFAULT_SOLVER, SolverOptions
from .results import SweepChunk, SweepResult, part_path
from .shooting import RootInfo, compliance_at, force_scale, quick_root, unscaled
from .solve import problem, solution_at, solve, tip_angle
from .version import __version__

INPUTS = ("tensions", "insertions", "insertion", "displacements", "force", "moment", "tip_mass", "point_force", "point_moment")
"""A sweep's input names besides the robot's fields ("insertion": the one tube's depth of a robot with one)."""


LOADS = {"tip_moment": "moment", "point_force": "point_force", "point_moment": "point_moment"}
"""Loads fields a sweep sets by name (the tip force: "force" plus the tip mass's weight)."""


def _point_shape(name: str, robot, act, load) -> tuple[int, ...]:
    k = load.n_points
    shapes = dict(
        tensions=(robot.n_tendons,), insertions=(robot.n_tubes,), displacements=(len(act.driven),),
        point_force=(k, 3), point_moment=(k, 3),
    )  # fmt: skip
    if robot.n_tubes == 1:
        shapes["insertion"] = ()
    elif name == "insertion":
        raise ValueError(f"cannot sweep 'insertion': the robot has {robot.n_tubes} tubes; sweep 'insertions', one depth each")
    if name in ("point_force", "point_moment") and not k:
        raise ValueError(f"cannot sweep {name!r}: the base load has no point loads (give tdct.Loads(point_s=...))")
    if name == "displacements" and not act.driven:
        raise ValueError("cannot sweep 'displacements': no tendon is displacement-driven (the base act's driven=())")
    shapes |= dict(force=(3,), moment=(3,), tip_mass=())
    if name in shapes:
        return shapes[name]
    try:
        fields.check(robot, name)
    except ValueError as e:
        raise ValueError(f"cannot sweep {name!r}: not an input ({', '.join(INPUTS)}) and {e}") from None
    return ()


def _check_values(name: str, values, robot, act, load) -> np.ndarray:
    """Validates one column (leading axis = points); errors name the field, the point and the range."""
    shape = _point_shape(name, robot, act, load)
    v = np.asarray(values, dtype=np.float64) if np.ndim(values) else np.reshape(values, (1,)).astype(np.float64)
    if len(v) == 0:
        raise ValueError(f"{name}: no values (an empty list); give at least one point")
    if v.ndim == 0 or v.shape[1:] != shape:
        raise ValueError(f"{name}: each point must have shape {shape}, got values of shape {np.shape(values)}")
    v = as_array(name, v, v.shape)

    def first_outside(lo, hi, unit, **kw):
        bad = np.flatnonzero(((v < lo) | (v > hi)).reshape(len(v), -1).any(axis=1))
        if bad.size:
            check_range(f"{name}[{bad[0]}]", v[bad[0]], lo, hi, unit=unit, **kw)

    L = float(robot.length)
    if name in ("tensions", "tip_mass"):
        first_outside(0.0, math.inf, " N" if name == "tensions" else " kg")
    if name == "tensions":
        for j, t in enumerate(robot.tendons):
            bad = np.flatnonzero(v[:, j] > (math.inf if t.max_tension is None else float(t.max_tension)))
            if bad.size:
                check_range(
                    f"tensions[{bad[0]}][{j}]", v[bad[0], j], 0.0, float(t.max_tension), unit=f" N (tendons[{j}].max_tension)"
                )
    elif name in ("insertion", "insertions"):
        first_outside(0.0, L, f" m (0 to the robot length {L:g} m)")
    elif name not in INPUTS:
        for i in (int(np.argmin(v)), int(np.argmax(v))):
            try:
                fields.replace(robot, {name: v[i]})
            except ValueError as e:
                raise ValueError(f"{name}[{i}]: {e}") from None
    return v


class Points(NamedTuple):
    """A checked base configuration and the points of a grid or batch around it."""

    base: tuple  # (robot, act, load, gravity, solver): shared by every point
    points: dict  # each input with a leading point axis
    shape: tuple  # the grid's shape, or (n,) for a batch
    axes: dict | None  # the grid's axes, None for a batch


def prepare(robot, act, load, grid, batch, *, gravity, solver, single=False, outputs: int = 0, scene=None) -> Points:
    """Defaults for the base configuration, its checks, and the points of ``grid`` or ``batch``.

    A ``scene`` goes into the base Loads (``solve.with_scene``).

    With ``single`` and neither grid nor batch, the base configuration is the one point (shape ()).
    ``outputs``: bytes per point the caller keeps in memory (for ``check_points``).
    """
    robot = Robot.paper() if robot is None else robot
    robot, act, load = problem(robot, act, load, solver, scene)
    base = (robot, act, load, gravity_vector(gravity), solver)
    if single and grid is None and batch is None:
        points = Points(base, {"insertions": np.asarray(act.insertions)[None]}, (), None)
    else:
        points = Points(base, *_columns(robot, act, load, grid, batch, outputs))
    p, g = points.points, base[3]
    force = np.asarray(p.get("force", load.tip_force)) + np.multiply.outer(p.get("tip_mass", 0.0), np.asarray(g))
    robot.warn_outside_calibration(p.get("tensions", act.tensions), force)
    return points


def unflatten(arrays: dict, shape: tuple, lead: int = 1) -> dict:
    """Replaces the ``lead`` leading (point) axes of each array by the sweep's ``shape``."""
    return {k: v.reshape(shape + v.shape[lead:]) for k, v in arrays.items()}


def check_points(robot, act, load, grid, batch, outputs: int = 0) -> tuple[dict, tuple]:
    """Checks the values of ``grid`` or ``batch`` (each axis or column, the batch's lengths; the
    shapes and names that depend on the base ``act`` and ``load``, checked ones) and
    that the points fit in host memory, before any is made: returns (the checked axes or
    columns, the sweep's shape). ``outputs``: bytes per point the caller keeps in memory besides
    the inputs."""
    if (grid is None) == (batch is None):
        raise ValueError("give exactly one of grid= (a product of axes) and batch= (columns zipped point by point)")
    named = grid if grid is not None else batch
    if not isinstance(named, Mapping) or not named:
        raise ValueError("grid / batch must be a non-empty mapping from input names to arrays of values")
    values = {k: _check_values(k, v, robot, act, load) for k, v in named.items()}
    if batch is not None:
        lengths = {k: len(v) for k, v in values.items()}
        if len(set(lengths.values())) != 1:
            raise ValueError(f"batch columns must have the same number of points, got {lengths}")
        shape = (next(iter(lengths.values())),)
    else:
        shape = tuple(len(v) for v in values.values())
    # each input at every point, float64, held twice (the points and the fingerprint's copy); a
    # grid's index arrays (int64, one per axis)
    per_point = 16 * sum(v[0].size for v in values.values()) + (8 * len(shape) if grid is not None else 0) + outputs
    _check_memory(shape, per_point, "grid" if grid is not None else "batch")
    return values, shape


def _check_memory(shape: tuple, per_point: int, kind: str) -> None:
    """Refuses a sweep whose points need more host memory than the machine has."""
    n, memory = math.prod(shape), host_memory()
    if memory is None or n * per_point <= memory:
        return
    points = " x ".join(map(str, shape)) + f" = {n:,}" if len(shape) > 1 else f"{n:,}"
    raise ValueError(
        f"a {kind} of {points} points needs about {_bytes(n * per_point)} of host memory, more than this machine's "
        f"{_bytes(memory)}: use fewer points, or split it into several sweeps (each with its own out=)"
    )


def host_memory() -> int | None:
    """The machine's physical memory [bytes], or None where the OS does not say."""
    try:
        return os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (AttributeError, ValueError, OSError):
        return None


def _bytes(n: float) -> str:
    for unit in ("B", "KiB", "MiB", "GiB", "TiB", "PiB"):
        if n < 1024 or unit == "PiB":
            return f"{n:.3g} {unit}"
        n /= 1024
    raise AssertionError  # unreachable


def _columns(robot, act, load, grid, batch, outputs: int = 0):
    """(columns with a leading point axis, sweep shape, grid axes or None)."""
    values, shape = check_points(robot, act, load, grid, batch, outputs)
    if batch is not None:
        return values, shape, None
    index = np.meshgrid(*(np.arange(n) for n in shape), indexing="ij")
    return {k: v[i.ravel()] for (k, v), i in zip(values.items(), index, strict=True)}, shape, values


def configure(base, point):
    """The robot, actuation and load of one point: the base with the point's values swapped in."""
    robot, act, load, gravity, _ = base
    robot = fields.replace(robot, {k: v for k, v in point.items() if _is_field(robot, k)})
    got = {k: point.get(k, getattr(act, k)) for k in ("tensions", "insertions", "displacements")}
    if "insertion" in point:
        got["insertions"] = jnp.reshape(point["insertion"], (1,))
    act = Actuation._rebuild(got["tensions"], got["insertions"], got["displacements"], act.driven)
    force = point.get("force", load.tip_force) + point.get("tip_mass", 0.0) * gravity
    loads = {k: point.get(name, getattr(load, k)) for k, name in LOADS.items()}
    return robot, act, dataclasses.replace(load, tip_force=force, **loads)


def _is_field(robot, name: str) -> bool:
    """Whether ``name`` is a robot field (a point may also carry inputs and its caller's own values)."""
    try:
        fields.check(robot, name)
    except ValueError:
        return False
    return True


def _solve_point(base, point, kernel: Kernel, guess=None):
    robot, act, load = configure(base, point)
    if kernel.option("first_pass") is not None:
        return _first_pass(robot, act, load, base[3], base[4], kernel)
    options = dict(gravity=base[3], solver=base[4], guess=guess, throw=False)
    if kernel.option("compliance"):
        C, sol = compliance_and_solution(robot, act, load, **options)
    else:
        sol = solve(robot, act, load, **options)
    out = dict(
        tip_position=sol.tip_position,
        tip_rotation=sol.tip_rotation,
        result=sol.result,
        iterations=sol.iterations,
        stages=sol.stages,
        residual_norm=sol.residual_norm,
        base_wrench=sol.base_wrench,
    )
    if kernel.option("shapes"):
        out.update(s=sol.s, position=sol.position)
    if kernel.option("compliance"):
        out["compliance"] = C[:3, :3]
    out["tensions"] = sol.tensions
    return out


def _first_pass(robot, act, load, gravity, solver, kernel: Kernel):
    """The batch engine's first pass: Broyden from the straight rod (``shooting.quick_root``), at
    most ``batch.FIRST_PASS`` steps and no more than the solver's ``max_iter``; shapes come from one
    integration along the path at its root, the compliance from one Jacobian pass there. Lanes it
    leaves unconverged are solved again by ``_solve_point`` without the option."""
    found = quick_root(robot, act, load, gravity, solver, jnp.minimum(kernel.option("first_pass"), solver.max_iter))
    F_c = force_scale(robot, act, load, gravity)
    out = dict(
        tip_position=found.tip_position,
        tip_rotation=found.tip_rotation,
        result=found.result,
        iterations=found.iterations,
        stages=jnp.ones((), jnp.int32),
        residual_norm=jnp.max(jnp.abs(found.residual)),
        base_wrench=unscaled(robot, found.x, F_c)[:6],
    )
    if kernel.option("shapes") or act.driven:
        sol = solution_at(
            robot, act, load, gravity, solver, found.x, RootInfo(found.iterations, out["stages"], found.result, None)
        )
    if kernel.option("shapes"):
        out.update(s=sol.s, position=sol.position)
    # the tensions found for displacement-driven tendons, slack ones exactly 0
    out["tensions"] = sol.tensions if act.driven else jnp.asarray(act.tensions, float)
    if kernel.option("compliance"):
        C = compliance_at(robot, act, load, gravity, solver, found.x)[:3, :3]
        out["compliance"] = jnp.where(found.result == status.SUCCESS, C, jnp.nan)
    return out


def _solve_path(base, path, kernel: Kernel):
    """Solves the points of a path in order, each started from the last converged neighbour."""

    def step(guess, point):
        out = _solve_point(base, point, kernel, guess)
        return jnp.where(out["result"] == status.SUCCESS, out["base_wrench"], guess), out

    return lax.scan(step, jnp.full(6, jnp.nan), path)[1]


class _Plan(NamedTuple):
    """A checked sweep: what to run, and on which part of the points."""

    kernel: Kernel
    base: tuple
    points: dict  # this process's rows
    shape: tuple
    axes: dict | None
    lead: int  # leading axes of a row: 1, or 2 with warm starts (path, point along it)
    first: int  # this process's first row


def _plan(
    robot, act, load, grid, batch, warm_start, shapes, compliance, devices, gravity, solver, outputs=0, scene=None
) -> _Plan:
    """Checks a sweep's arguments and keeps this process's share of the rows (paths with warm
    starts): the k-th of ``jax.process_count()`` contiguous parts. ``outputs``: bytes per point
    kept in host memory besides the inputs (none when streamed)."""
    base, points, shape, axes = prepare(
        robot, act, load, grid, batch, gravity=gravity, solver=solver, outputs=outputs, scene=scene
    )
    function = _solve_point
    if warm_start:
        if grid is None:
            raise ValueError("warm_start=True needs grid=: the solves run in order along the grid's last axis")
        points = {k: v.reshape(-1, shape[-1], *v.shape[1:]) for k, v in points.items()}
        function = _solve_path
    rows, k, n_proc = len(next(iter(points.values()))), jax.process_index(), jax.process_count()
    first, last = k * rows // n_proc, (k + 1) * rows // n_proc
    if first == last:
        raise ValueError(f"{rows} {'paths' if warm_start else 'points'} cannot be split over jax.process_count() = {n_proc}")
    kernel = Kernel(function, (("shapes", shapes), ("compliance", compliance)), mesh_for(devices), retire=not warm_start)
    base = (*base[:4], batch_solver(base[4], kernel.mesh))
    mine = {name: v[first:last] for name, v in points.items()}
    return _Plan(kernel, base, mine, shape, axes, 1 + warm_start, first)


def _per_row(plan: _Plan) -> int:
    """Points per row of the plan: one, or a warm-started path's length."""
    return plan.shape[-1] if plan.lead == 2 else 1


def _chunks(plan: _Plan, chunk_size, progress, skip: Collection[int] = ()) -> Iterator[SweepChunk]:
    per_row = _per_row(plan)
    k, n_proc = jax.process_index(), jax.process_count()
    desc = "solving" if n_proc == 1 else f"solving (process {k + 1} of {n_proc})"
    options = dict(chunk_size=chunk_size, progress=progress, desc=desc, per_point=per_row, skip=skip)
    for row, out in iter_batched(plan.kernel, plan.base, plan.points, **options):
        outputs = {name: v.reshape(-1, *v.shape[plan.lead :]) for name, v in out.items()}
        rows = slice(row, row + len(next(iter(out.values()))))
        inputs = {name: v[rows].reshape(-1, *v.shape[plan.lead :]) for name, v in plan.points.items()}
        start = (plan.first + row) * per_row
        yield SweepChunk(start, start + (rows.stop - row) * per_row, plan.shape, inputs, outputs)


class _Failures:
    """Counts the points and the failed points of a stream of chunks and keeps the first failing
    chunk, so that ``throw`` can name the first failure of a sweep that was never whole in memory."""

    def __init__(self):
        self.points, self.count, self.first, self.written = 0, 0, None, None

    def watch(self, chunks: Iterator[SweepChunk]) -> Iterator[SweepChunk]:
        for c in chunks:
            failed = int(np.count_nonzero(c.outputs["result"] != status.SUCCESS))
            if failed and (self.first is None or c.start < self.first.start):
                self.first = c
            self.points += c.stop - c.start
            self.count += failed
            yield c

    def summary(self, seconds: float, done_before: bool = False) -> str:
        """One line: points, failures, time (``8,000 points, 0 failed, 18 s``)."""
        line = f"{self.points:,} points, {self.count:,} failed"
        if done_before:
            return f"{line}: {self.written} was complete already, nothing computed (overwrite=True, tdct sweep --overwrite, recomputes it)"
        return line + (f", {seconds:.2g} s" if seconds < 10 else f", {seconds:,.0f} s")

    def check(self, solver: SolverOptions, throw: bool) -> None:
        if not (throw and self.count):
            return
        c = self.first
        i = int(np.flatnonzero(c.outputs["result"] != status.SUCCESS)[0])
        out = {k: c.outputs[k][i] for k in ("result", "iterations", "stages", "residual_norm")}
        total = math.prod(c.shape)
        written = "" if self.written is None else f"; {self.written} was still written with every point's result code"
        what = f"the sweep's point {c.start + i} (of {total}; {self.count} failed, {{keep_failures}}{written})"
        status.check(
            out["result"],
            throw=True,
            what=what,
            iterations=out["iterations"],
            stages=out["stages"],
            residual_norm=out["residual_norm"],
            max_iter=solver.max_iter,
            tol=solver.tol,
        )


def _fingerprint(plan: _Plan, lanes: int) -> dict:
    """Everything that determines the file a sweep (or this process's part of it) writes, named
    as a reader knows it, for ``checkpoint.Partial``'s resume check."""
    robot, act, load, gravity, solver = plan.base

    def plain(v):
        return v if isinstance(v, str) else np.asarray(v).tolist()

    kind, columns = ("grid axis", plan.axes) if plan.axes is not None else ("batch column", plan.points)
    devices = plan.kernel.mesh.devices.flat
    return {
        "tdct_jax": __version__,
        "jax": jax.__version__,
        **{
            name: plain(v) for obj, prefix in ((robot, "robot"), (act, "act"), (load, "load")) for name, v in _leaves(obj, prefix)
        },
        "gravity": plain(gravity),
        **{f"solver.{f.name}": plain(getattr(solver, f.name)) for f in dataclasses.fields(solver)},
        f"{kind}s": list(columns),
        **{f"{kind} {name}": digest(v) for name, v in columns.items()},
        "warm_start": plan.lead == 2,
        **{name: plain(value) for name, value in plan.kernel.options},
        "chunk_size": lanes,
        "devices": f"{len(devices)} {devices[0].platform}",
        "process": f"{jax.process_index()} of {jax.process_count()}",
    }


def _leaves(obj, prefix: str) -> list:
    """(name, value) of every field of a robot, actuation or load, leaves by their paths
    (``robot.sections[0].E``), static fields by their names."""
    static = [f.name for f in dataclasses.fields(obj) if f.metadata.get("static")]
    leaves = jax.tree_util.tree_leaves_with_path(obj, is_leaf=lambda x: x is None)
    return [(f"{prefix}{jax.tree_util.keystr(p)}", v) for p, v in leaves] + [(f"{prefix}.{n}", getattr(obj, n)) for n in static]


OUT_SUFFIXES = (".npz",)
OUT_KIND = "a sweep's file format (for a CSV: tdct.gather(out).save_csv(path))"
"""What ``sweep(out=)`` and ``tdct sweep --out`` take."""
FAILURE_FIELDS = ("result", "iterations", "stages", "residual_norm")
"""The outputs ``throw`` reads of chunks an earlier run finished."""
_SWEEP_ONLY = ("out", "overwrite", "throw")
"""``sweep``'s arguments that ``sweep_chunks`` does not take."""


def _write(plan: _Plan, out, chunk_size, progress, overwrite: bool, failures: _Failures) -> tuple[Path, bool]:
    """Streams this process's chunks into the partial folder beside ``out``, each durable before
    the next counts (a rerun of the same sweep computes only the chunks not yet there), then
    assembles the .npz: the whole sweep, or after ``jax.distributed.initialize`` this process's
    part (flat, with ``points`` = [start, stop)). Returns the path and whether it was complete
    already (the same sweep wrote it): then nothing is computed; its failures count all the same."""
    whole = jax.process_count() == 1
    path = Path(out) if whole else part_path(out, jax.process_index(), jax.process_count())
    rows, per_row = len(next(iter(plan.points.values()))), _per_row(plan)
    lanes = chunk_lanes(plan.kernel, rows, chunk_size)
    fingerprint = _fingerprint(plan, lanes)
    failures.written = path
    if complete(path, fingerprint, overwrite=overwrite):
        with np.load(path) as data:
            outputs = {
                name: data[name].reshape(-1, *data[name].shape[len(plan.shape) if whole else 1 :]) for name in FAILURE_FIELDS
            }
        start = plan.first * per_row
        for _ in failures.watch([SweepChunk(start, start + rows * per_row, plan.shape, {}, outputs)]):
            pass
        return path, True
    store = Partial.open(path, fingerprint, -(-rows // lanes), overwrite=overwrite)

    def index(c: SweepChunk) -> int:
        return (c.start // per_row - plan.first) // lanes

    def finished(i: int) -> SweepChunk:
        outputs, start = store.read(i, FAILURE_FIELDS), (plan.first + i * lanes) * per_row
        return SweepChunk(start, start + len(outputs["result"]), plan.shape, {}, outputs)

    for _ in failures.watch(finished(i) for i in sorted(store.done)):
        pass
    for c in failures.watch(_chunks(plan, chunk_size, progress, skip=store.done)):
        derived = dict(
            tip_angle=np.asarray(tip_angle(c.outputs["tip_rotation"])), converged=c.outputs["result"] == status.SUCCESS
        )
        store.save(index(c), c.outputs | derived)
    flat = plan.shape if whole else (rows * per_row,)
    head = {"shape": np.asarray(plan.shape)} | {f"axis_{name}": v for name, v in (plan.axes or {}).items()}
    head |= {f"input_{name}": v.reshape(flat + v.shape[plan.lead :]) for name, v in plan.points.items()}
    tail = {} if whole else {"points": np.asarray([plan.first * per_row, (plan.first + rows) * per_row])}
    return store.finish(path, head, flat, tail), False


def sweep_chunks(robot=None, act=None, load=None, *, solver: SolverOptions = DEFAULT_SOLVER, **options) -> Iterator[SweepChunk]:
    """``sweep``'s results chunk by chunk, each yielded as soon as it is computed, so that host
    memory holds one chunk's outputs. After ``jax.distributed.initialize`` each process gets the
    chunks of its own part of the points. Failed points stay as result codes (no ``throw``).

    Args:
        robot, act, load, solver, **options: as for ``sweep``, with the same defaults (``out``,
            ``overwrite`` and ``throw`` excepted). Bad input raises here, before the first chunk.

    Returns:
        An iterator of SweepChunk, in order of ``start``.
    """
    for name in _SWEEP_ONLY:
        if name in options:
            raise TypeError(f"sweep_chunks takes no {name}= (it yields every chunk, failed points included); use sweep")
    defaults = {k: p.default for k, p in inspect.signature(sweep).parameters.items() if p.kind is p.KEYWORD_ONLY}
    unknown = sorted(set(options) - set(defaults))
    if unknown:
        raise TypeError(f"sweep_chunks: unknown argument(s) {unknown}; allowed: {sorted(set(defaults) - set(_SWEEP_ONLY))}")
    o = defaults | options | dict(solver=solver)
    plan = _plan(robot, act, load, **{k: v for k, v in o.items() if k not in ("chunk_size", "progress", *_SWEEP_ONLY)})
    return _chunks(plan, o["chunk_size"], o["progress"])


def sweep(
    robot: Robot | None = None,
    act: Actuation | None = None,
    load: Loads | None = None,
    *,
    grid: Mapping | None = None,
    batch: Mapping | None = None,
    warm_start: bool = False,
    shapes: bool = False,
    compliance: bool = False,
    chunk_size: int | None = None,
    progress: bool = True,
    devices=None,
    out=None,
    overwrite: bool = False,
    gravity=STANDARD_GRAVITY,
    solver: SolverOptions = DEFAULT_SOLVER,
    throw: bool = True,
    scene=None,
):
    """Solves many configurations at once: ``jax.vmap`` of ``tdct.solve`` in bounded chunks.

    Args:
        robot, act, load: the base configuration (defaults: ``Robot.paper()``, no tension, tubes
            withdrawn, no load).
        grid: {name: values}: every combination of the axes, first axis slowest. Values have a
            leading axis of points: "tensions" (k, n_tendons) [N], "insertions" (k, n_tubes)
            [m] ("insertion" (k,) for a robot with one tube), "displacements" (k,
            len(act.driven)) [m], "force" and "moment" (k, 3) [N], [N m], "tip_mass" (k,) [kg]
            (weight added to the force), "point_force" and "point_moment" (k, n, 3) (the base
            Loads' n point loads), and the robot's fields by name (``tdct_jax.fields``:
            "sections[*].E" (k,) [Pa], "tendons[3].offset" (k,) [m], ...); the result's
            ``tensions`` holds each point's tendon tensions.
        batch: {name: values} with the same leading length, zipped point by point.
        warm_start: (grid only) solve along the last axis in order, each solve started from its
            neighbour's base wrench; the other axes run in parallel.
        shapes: also return the full shape of every solution (memory: steps + 1 nodes per
            breakpoint interval each).
        compliance: also return the exact 3x3 tip compliance (eq. 41) at every point.
        chunk_size: configurations per compiled call; bounds device memory. None takes the
            default of the devices' platform per device (``tdct_jax.batch.CHUNK_SIZES``) times
            the number of devices. With several devices each chunk is split evenly over them.
        progress: show a progress bar on the terminal, and at the end one line on stderr:
            points, failures, seconds ("8,000 points, 0 failed, 18 s").
        devices: devices to shard each chunk over (default: this process's, ``jax.local_devices()``).
        out: an .npz path to stream the results to, chunk by chunk, with host memory bounded by
            a chunk (uncompressed; same arrays as ``SweepResult.save_npz``). Each finished chunk
            is kept on disk in the folder ``<stem>.partial`` beside it, so that the same call
            after any stop computes only the chunks not yet there (it says so on stderr); the
            folder goes once the file is written, equal byte for byte to an uninterrupted run's.
            The same call once the file is complete computes nothing (it says so on stderr).
            The name must end in .npz, and its folder exist and take new files. After ``jax.distributed.initialize`` each process solves and writes its own
            contiguous part of the points, to ``<stem>.partK-of-N.npz`` (and resumes from
            ``<stem>.partK-of-N.partial``); ``out`` is then required. ``tdct.gather(out)`` reads
            the result back either way.
        overwrite: discard a partial folder left by a different sweep (other inputs, robot,
            solver options, chunk size, devices or package version) instead of refusing it, and
            recompute a file already at ``out`` (a different sweep's is refused otherwise).
        gravity: world gravity [m/s^2] (None: none).
        solver: SolverOptions for every solve.
        throw: after the sweep (and after writing ``out``), raise ConvergenceError naming the
            first failed point and the number of failures, if any point failed (default, as for
            every entry point). With False, failures stay in ``result`` (per point) and ``n_failed``.
        scene: obstacles (as for ``tdct.solve``), the same for every point. To vary an obstacle, vmap ``tdct.solve`` over its numbers (docs/contact.md).

    Returns:
        SweepResult, or with ``out`` the path written.

    Raises:
        ValueError: bad input (also a grid or batch too large for host memory, with the
            estimate), or a partial folder or file at ``out`` of a different sweep (naming what
            differs).
        ConvergenceError: with ``throw``, when a point failed.
    """
    if out is None and jax.process_count() > 1:
        raise ValueError(
            f"out = None: a sweep over jax.process_count() = {jax.process_count()} processes needs out=, "
            "the .npz path each process writes its part to (tdct.gather(out) joins them)"
        )
    start = perf_counter()
    if out is not None:
        check_output("out", out, suffixes=OUT_SUFFIXES, kind=OUT_KIND)
    kept = 0 if out is not None else _output_bytes(shapes, compliance, solver)
    plan = _plan(robot, act, load, grid, batch, warm_start, shapes, compliance, devices, gravity, solver, kept, scene)
    failures = _Failures()
    if out is not None:
        path, done_before = _write(plan, out, chunk_size, progress, overwrite, failures)
        if progress or done_before:
            print(failures.summary(perf_counter() - start, done_before), file=sys.stderr)
        failures.check(solver, throw)
        return path
    outputs = unflatten(joined([c.outputs for c in failures.watch(_chunks(plan, chunk_size, progress))]), plan.shape)
    inputs = unflatten(plan.points, plan.shape, plan.lead)
    result = SweepResult(shape=plan.shape, axes=plan.axes, inputs=inputs, seconds=perf_counter() - start, **outputs)
    if progress:
        print(failures.summary(result.seconds), file=sys.stderr)
    failures.check(solver, throw)
    return result


def _output_bytes(shapes: bool, compliance: bool, solver: SolverOptions) -> int:
    """Host memory per point of an in-memory sweep's outputs (held twice: the chunks, then joined)."""
    tip = 8 * (3 + 9 + 6 + 1 + 1) + 4 * 3 + 1  # pose, base wrench, residual, tip angle; codes, counts; converged
    nodes = 2 * solver.steps + 1
    return 2 * (tip + (32 * nodes if shapes else 0) + (72 if compliance else 0))
