"""Batched sweeps: many solves through one compiled ``vmap``, in chunks of bounded size, with a
progress bar, sharded over this process's devices and split over JAX's processes.

A sweep varies named inputs around a base configuration: the actuation ("tensions" [N],
"insertion" [m]), the tip load ("force" [N], "moment" [N m], "tip_mass" [kg], whose weight adds
to the force) and any scalar Robot field ("E_silicone" [Pa], "tendon_offset" [m], ...). A
``grid`` takes the product of axes; a ``batch`` zips columns of equal length. Results come back
whole (``sweep``), chunk by chunk (``sweep_chunks``), or streamed to an .npz file (``sweep(out=)``,
one part per process after ``jax.distributed.initialize``, read back by ``gather``).
"""

from __future__ import annotations

import csv
import dataclasses
import math
import os
import re
import tempfile
import zipfile
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from time import perf_counter
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax
from jax.sharding import Mesh
from jax.sharding import PartitionSpec as P
from numpy.lib.format import open_memmap
from tqdm import tqdm

from ._checks import as_array, check_range
from .loads import STANDARD_GRAVITY, Actuation, TipLoad
from .mechanics import compliance_and_solution
from .robot import SCALAR_FIELDS, Robot
from .shooting import MAX_ITER, STEPS, TOL, check_inputs, gravity_vector, solve, solver_options
from .so3 import tip_angle

CHUNK_SIZES = {"cpu": 64, "gpu": 8192}
"""Default configurations per compiled call, by device platform (``chunk_size=`` overrides; a
smaller sweep rounds up to a power of two; other platforms take the cpu value). cpu: 64 measured
fastest on one device of the 2-core CPU (664 solves/s against 569, 650 and 440 at 16, 256 and
1,024; benchmarks/sweep_throughput.py). gpu: provisional, near the best batch of a batch-last prototype
on one H100 (874,000 solves/s at 10,000 lanes, 2-8x less at 10^5-10^6; ../shared/perf-notes.md),
to be replaced by what benchmarks/gpu_throughput.py measures."""
DEFAULT_CHUNK = CHUNK_SIZES["cpu"]
"""The default chunk size on the CPU, where the CPU benchmarks measure."""
AXIS = "batch"
"""Name of the device-mesh axis the batch is sharded over."""


def _point_shape(name: str, robot: Robot) -> tuple[int, ...]:
    shapes = {"tensions": (robot.n_tendons,), "insertion": (), "force": (3,), "moment": (3,), "tip_mass": ()}
    if name in shapes:
        return shapes[name]
    if name in SCALAR_FIELDS:
        return ()
    raise ValueError(f"cannot sweep {name!r}: allowed names are {sorted(shapes)} and the Robot fields {list(SCALAR_FIELDS)}")


def _check_values(name: str, values, robot: Robot, act: Actuation) -> np.ndarray:
    """Validates one column (leading axis = points); errors name the field, the point and the range."""
    shape = _point_shape(name, robot)
    v = np.asarray(values, dtype=np.float64) if np.ndim(values) else np.reshape(values, (1,)).astype(np.float64)
    if v.ndim == 0 or v.shape[1:] != shape:
        raise ValueError(f"{name}: each point must have shape {shape}, got values of shape {np.shape(values)}")
    v = as_array(name, v, v.shape)

    def first_outside(lo, hi, unit, **kw):
        bad = np.flatnonzero(((v < lo) | (v > hi)).reshape(len(v), -1).any(axis=1))
        if bad.size:
            check_range(f"{name}[{bad[0]}]", v[bad[0]], lo, hi, unit=unit, **kw)

    if name in ("tensions", "tip_mass"):
        first_outside(0.0, math.inf, " N" if name == "tensions" else " kg")
    elif name == "insertion":
        first_outside(0.0, float(robot.length), f" m (0 to the robot length {float(robot.length):g} m)")
    elif name in SCALAR_FIELDS:
        for x in (v.min(), v.max()):
            dataclasses.replace(robot, **{name: x})
    return v


def prepare(robot, act, load, grid, batch, *, single=False):
    """Defaults for the base configuration, its checks, and the points of ``grid`` or ``batch``.

    Returns (robot, act, load, points with a leading axis, shape, grid axes or None). With
    ``single`` and neither grid nor batch, the base configuration is the one point (shape ()).
    """
    robot = Robot() if robot is None else robot
    act = Actuation(np.zeros(robot.n_tendons)) if act is None else act
    load = TipLoad() if load is None else load
    check_inputs(robot, act, load)
    if single and grid is None and batch is None:
        return robot, act, load, {"insertion": np.asarray(act.insertion).reshape(1)}, (), None
    return robot, act, load, *_columns(robot, act, grid, batch)


def unflatten(arrays: dict, shape: tuple, lead: int = 1) -> dict:
    """Replaces the ``lead`` leading (point) axes of each array by the sweep's ``shape``."""
    return {k: v.reshape(shape + v.shape[lead:]) for k, v in arrays.items()}


def _columns(robot, act, grid, batch):
    """(columns with a leading point axis, sweep shape, grid axes or None)."""
    if (grid is None) == (batch is None):
        raise ValueError("give exactly one of grid= (a product of axes) and batch= (columns zipped point by point)")
    named = grid if grid is not None else batch
    if not isinstance(named, Mapping) or not named:
        raise ValueError("grid / batch must be a non-empty mapping from input names to arrays of values")
    values = {k: _check_values(k, v, robot, act) for k, v in named.items()}
    if batch is not None:
        lengths = {k: len(v) for k, v in values.items()}
        if len(set(lengths.values())) != 1:
            raise ValueError(f"batch columns must have the same number of points, got {lengths}")
        return values, (next(iter(lengths.values())),), None
    shape = tuple(len(v) for v in values.values())
    index = np.meshgrid(*(np.arange(n) for n in shape), indexing="ij")
    return {k: v[i.ravel()] for (k, v), i in zip(values.items(), index, strict=True)}, shape, values


def configure(base, point):
    """The robot, actuation and load of one point: the base with the point's values swapped in."""
    robot, act, load, gravity = base
    fields = {k: v for k, v in point.items() if k in SCALAR_FIELDS}
    robot = dataclasses.replace(robot, **fields) if fields else robot
    act = Actuation(point.get("tensions", act.tensions), point.get("insertion", act.insertion))
    force = point.get("force", load.force) + point.get("tip_mass", 0.0) * gravity
    return robot, act, TipLoad(force, point.get("moment", load.moment))


@dataclasses.dataclass(frozen=True)
class Kernel:
    """What runs per point (static: each distinct value compiles once per chunk size).

    ``function(base, point, kernel)`` returns a dict of arrays; ``solve_options`` are keyword
    arguments for ``tdct.solve`` (gravity excepted: it is part of ``base`` and traced).
    """

    function: Callable
    solve_options: tuple = ()
    shapes: bool = False
    compliance: bool = False
    mesh: Mesh | None = None

    @property
    def options(self) -> dict:
        return dict(self.solve_options)


@jax.jit(static_argnames=("kernel",))
def _run_chunk(base, points, kernel: Kernel):
    def lanes(base, points):
        return jax.vmap(lambda p: kernel.function(base, p, kernel))(points)

    if kernel.mesh is None or kernel.mesh.size == 1:
        return lanes(base, points)
    sharded = jax.shard_map(lanes, mesh=kernel.mesh, in_specs=(P(), P(AXIS)), out_specs=P(AXIS), check_vma=False)
    return sharded(base, points)


def mesh_for(devices) -> Mesh:
    """A 1-D mesh over ``devices`` (default: this process's devices, ``jax.local_devices()``)."""
    return Mesh(np.asarray(jax.local_devices() if devices is None else list(devices)), (AXIS,))


def default_chunk_size(mesh: Mesh | None = None) -> int:
    """``CHUNK_SIZES`` for the platform of the mesh's devices (default: the default backend's)."""
    platform = jax.default_backend() if mesh is None else mesh.devices.flat[0].platform
    return CHUNK_SIZES.get(platform, CHUNK_SIZES["cpu"])


def lanes_per_call(n: int, chunk_size: int, n_devices: int = 1) -> int:
    """Configurations per compiled call for n points: ``chunk_size``, or the power of two at or
    above n when that is smaller, rounded up to a multiple of the device count."""
    chunk = min(chunk_size, 1 << max(n - 1, 0).bit_length())
    return -(-chunk // n_devices) * n_devices


def iter_batched(
    kernel: Kernel, base, points: dict, *, chunk_size=None, progress=True, desc="solving", per_point=1
) -> Iterator[tuple[int, dict]]:
    """Runs ``kernel`` over the leading axis of ``points`` in chunks, yielding each chunk's
    (first row, numpy outputs) as soon as it is computed, with the next chunk already dispatched.

    Every chunk has the same static shape (the last is padded by repeating its final point), so
    one compile serves the whole sweep and any later sweep with the same chunk size.
    ``chunk_size`` None takes ``default_chunk_size`` for the kernel's devices. ``per_point`` is
    the number of solves each point stands for (the progress bar counts solves).
    """
    if chunk_size is None:
        chunk_size = default_chunk_size(kernel.mesh)
    if not isinstance(chunk_size, (int, np.integer)) or chunk_size < 1:
        raise ValueError(f"chunk_size = {chunk_size!r} must be an integer >= 1 (or None for the backend's default)")
    n = len(next(iter(points.values())))
    chunk = lanes_per_call(n, chunk_size, 1 if kernel.mesh is None else kernel.mesh.size)
    # one device: commit the points to it, so jit runs there and not on the default device
    device = kernel.mesh.devices.flat[0] if kernel.mesh is not None and kernel.mesh.size == 1 else None

    def fetched(start, out):
        m = min(chunk, n - start)
        out = {k: v[:m] for k, v in jax.device_get(out).items()}
        bar.update(m * per_point)
        bar.set_postfix_str("")
        return start, out

    with tqdm(total=n * per_point, unit="solve", desc=desc, disable=not progress, dynamic_ncols=True) as bar:
        bar.set_postfix_str("compiling")
        pending = None
        for start in range(0, n, chunk):
            index = np.minimum(np.arange(start, start + chunk), n - 1)
            chunk_points = {k: v[index] for k, v in points.items()}
            if device is not None:
                chunk_points = jax.device_put(chunk_points, device)
            out = _run_chunk(base, chunk_points, kernel)  # dispatched: runs while the last chunk is fetched
            if pending is not None:
                yield fetched(*pending)
            pending = start, out
        yield fetched(*pending)


def run_batched(kernel: Kernel, base, points: dict, **options) -> dict:
    """``iter_batched``'s chunks joined: numpy outputs over the whole leading axis of ``points``."""
    return _joined([out for _, out in iter_batched(kernel, base, points, **options)])


def _joined(parts: list[dict]) -> dict:
    """Chunks' outputs (dicts of arrays with a leading point axis) concatenated along that axis."""
    return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}


def _solve_point(base, point, kernel: Kernel, guess=None):
    robot, act, load = configure(base, point)
    options = dict(kernel.options, gravity=base[3], guess=guess)
    if kernel.compliance:
        J, sol = compliance_and_solution(robot, act, load, throw=False, **options)
    else:
        sol = solve(robot, act, load, **options)
    out = dict(
        tip_position=sol.tip_position,
        tip_rotation=sol.tip_rotation,
        converged=sol.converged,
        iterations=sol.iterations,
        residual_norm=sol.residual_norm,
        base_wrench=sol.base_wrench,
    )
    if kernel.shapes:
        out.update(s=sol.s, position=sol.position)
    if kernel.compliance:
        out["compliance"] = J[:3, :3]
    return out


def _solve_path(base, path, kernel: Kernel):
    """Solves the points of a path in order, each started from the last converged neighbour."""

    def step(guess, point):
        out = _solve_point(base, point, kernel, guess)
        return jnp.where(out["converged"], out["base_wrench"], guess), out

    return lax.scan(step, jnp.full(6, jnp.nan), path)[1]


@dataclasses.dataclass(frozen=True)
class SweepResult:
    """Outputs of ``sweep``, numpy arrays whose leading axes have the sweep's ``shape``.

    Attributes:
        shape: grid shape (one axis per grid name, in order) or (n_points,) for a batch.
        axes: the grid's axis values by name (None for a batch).
        inputs: each swept input at every point, shape ``shape + point shape``.
        tip_position [m], tip_rotation, converged, iterations, residual_norm, base_wrench
            (N(0) [N], M(0) [N m]): as on ``Solution``.
        s, position: arc length [m] and shape [m] at the RK4 nodes (with ``shapes=True``).
        compliance: 3x3 tip compliance [m/N] (with ``compliance=True``; NaN where not converged).
        seconds: wall time of the sweep, compiles included.
    """

    shape: tuple
    axes: dict | None
    inputs: dict
    tip_position: np.ndarray
    tip_rotation: np.ndarray
    converged: np.ndarray
    iterations: np.ndarray
    residual_norm: np.ndarray
    base_wrench: np.ndarray
    s: np.ndarray | None = None
    position: np.ndarray | None = None
    compliance: np.ndarray | None = None
    seconds: float = float("nan")

    @property
    def tip_angle(self) -> np.ndarray:
        """theta_tip [rad] (see ``Solution.tip_angle``)."""
        return np.asarray(tip_angle(self.tip_rotation))

    @property
    def n_failed(self) -> int:
        return int(np.size(self.converged) - np.count_nonzero(self.converged))

    def save_npz(self, path) -> Path:
        """Writes every array to a compressed .npz (inputs as ``input_<name>``, axes as ``axis_<name>``)."""
        outputs = {
            f.name: getattr(self, f.name) for f in dataclasses.fields(self) if isinstance(getattr(self, f.name), np.ndarray)
        }
        return write_npz(path, self.shape, self.axes, self.inputs, dict(outputs, tip_angle=self.tip_angle))

    def save_csv(self, path) -> Path:
        """Writes one row per point: the swept inputs and the tip outputs, SI units in the header."""
        tip = self.tip_position
        outputs = {f"tip_{c}_m": tip[..., i] for i, c in enumerate("xyz")}
        outputs.update(tip_angle_rad=self.tip_angle, converged=self.converged, iterations=self.iterations)
        return write_csv(path, self.shape, self.inputs, dict(outputs, residual_norm=self.residual_norm))


def write_npz(path, shape, axes, inputs: dict, outputs: dict) -> Path:
    """Saves a sweep-like result: outputs by name, inputs as ``input_<name>``, axes as ``axis_<name>``."""
    path = Path(path)
    arrays = {f"input_{k}": v for k, v in inputs.items()}
    arrays.update({f"axis_{k}": v for k, v in (axes or {}).items()})
    np.savez_compressed(path, shape=np.asarray(shape), **arrays, **outputs)
    return path


def write_csv(path, shape, inputs: dict, outputs: dict) -> Path:
    """One row per point: input columns named with their SI unit, then the per-point ``outputs``
    (arrays of the sweep's shape, named with their units by the caller)."""
    path = Path(path)
    n = int(np.prod(shape))
    columns: dict[str, np.ndarray] = {}
    for k, v in inputs.items():
        v = v.reshape(n, -1)
        labels = [k] if v.shape[1] == 1 else [f"{k}_{i + 1}" for i in range(v.shape[1])]
        columns.update({f"{label}_{unit_of(k)}": v[:, i] for i, label in enumerate(labels)})
    columns.update({k: np.asarray(v).reshape(n) * 1 for k, v in outputs.items()})
    with path.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(columns)
        w.writerows(zip(*(c.tolist() for c in columns.values()), strict=True))
    return path


def unit_of(name: str) -> str:
    """The SI unit of a sweepable input or Robot field, as written in CSV column names."""
    units = {
        "tensions": "N",
        "insertion": "m",
        "force": "N",
        "moment": "Nm",
        "tip_mass": "kg",
        "E_silicone": "Pa",
        "E_tube": "Pa",
    }
    if name in units:
        return units[name]
    return "kg_per_m3" if name.startswith("density") else "1" if name.startswith("nu") else "m"


@dataclasses.dataclass(frozen=True)
class SweepChunk:
    """One chunk of a sweep, as ``sweep_chunks`` yields it.

    Attributes:
        start, stop: the chunk holds points [start, stop) of the sweep's points in C order (a
            grid's last axis fastest; ``np.unravel_index(i, shape)`` gives a point's grid index).
        shape: the whole sweep's shape.
        inputs: each swept input at the chunk's points, leading axis stop - start.
        outputs: tip_position, tip_rotation, ... as on ``SweepResult``, leading axis stop - start.
    """

    start: int
    stop: int
    shape: tuple
    inputs: dict
    outputs: dict


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
    robot,
    act,
    load,
    *,
    grid=None,
    batch=None,
    warm_start=False,
    shapes=False,
    compliance=False,
    devices=None,
    steps=STEPS,
    gravity=STANDARD_GRAVITY,
    transition="balanced",
    tendon_model="exact",
    tol=TOL,
    max_iter=MAX_ITER,
) -> _Plan:
    """Checks a sweep's arguments and keeps this process's share of the rows (paths with warm
    starts): the k-th of ``jax.process_count()`` contiguous parts."""
    solver_options(steps, transition, tendon_model, tol, max_iter)
    robot, act, load, points, shape, axes = prepare(robot, act, load, grid, batch)
    options = (("steps", steps), ("transition", transition), ("tendon_model", tendon_model), ("tol", tol), ("max_iter", max_iter))
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
    kernel = Kernel(function, options, shapes, compliance, mesh_for(devices))
    mine = {name: v[first:last] for name, v in points.items()}
    return _Plan(kernel, (robot, act, load, gravity_vector(gravity)), mine, shape, axes, 1 + warm_start, first)


def _chunks(plan: _Plan, chunk_size, progress) -> Iterator[SweepChunk]:
    per_row = plan.shape[-1] if plan.lead == 2 else 1
    k, n_proc = jax.process_index(), jax.process_count()
    desc = "solving" if n_proc == 1 else f"solving (process {k + 1} of {n_proc})"
    options = dict(chunk_size=chunk_size, progress=progress, desc=desc, per_point=per_row)
    for row, out in iter_batched(plan.kernel, plan.base, plan.points, **options):
        outputs = {name: v.reshape(-1, *v.shape[plan.lead :]) for name, v in out.items()}
        rows = slice(row, row + len(next(iter(out.values()))))
        inputs = {name: v[rows].reshape(-1, *v.shape[plan.lead :]) for name, v in plan.points.items()}
        start = (plan.first + row) * per_row
        yield SweepChunk(start, start + (rows.stop - row) * per_row, plan.shape, inputs, outputs)


def sweep_chunks(robot=None, act=None, load=None, *, chunk_size=None, progress=True, **options) -> Iterator[SweepChunk]:
    """``sweep``'s results chunk by chunk, each yielded as soon as it is computed, so that host
    memory holds one chunk's outputs. After ``jax.distributed.initialize`` each process gets the
    chunks of its own part of the points.

    Args:
        robot, act, load, chunk_size, progress, **options: as for ``sweep`` (``out`` excepted).
            Bad input raises here, before the first chunk.

    Returns:
        An iterator of SweepChunk, in order of ``start``.
    """
    return _chunks(_plan(robot, act, load, **options), chunk_size, progress)


def sweep(
    robot: Robot | None = None,
    act: Actuation | None = None,
    load: TipLoad | None = None,
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
    steps: int = STEPS,
    gravity=STANDARD_GRAVITY,
    transition: str = "balanced",
    tendon_model: str = "exact",
    tol: float = TOL,
    max_iter: int = MAX_ITER,
):
    """Solves many configurations at once: ``jax.vmap`` of ``tdct.solve`` in bounded chunks.

    Args:
        robot, act, load: the base configuration (defaults: Robot(), no tension, no tube, no tip load).
        grid: {name: values}: every combination of the axes, first axis slowest. Values have a
            leading axis of points: "tensions" (k, n_tendons) [N], "insertion" (k,) [m], "force"
            and "moment" (k, 3) [N], [N m], "tip_mass" (k,) [kg] (weight added to the force),
            or any scalar Robot field (k,).
        batch: {name: values} with the same leading length, zipped point by point.
        warm_start: (grid only) solve along the last axis in order, each solve started from its
            neighbour's base wrench; the other axes run in parallel.
        shapes: also return the full shape of every solution (memory: 2 steps + 1 nodes each).
        compliance: also return the exact 3x3 tip compliance (eq. 41) at every point.
        chunk_size: configurations per compiled call; bounds device memory. None takes the
            default of the devices' platform (``CHUNK_SIZES``: cpu 64, gpu 8192). With several
            devices each chunk is split evenly over them.
        progress: show a progress bar on the terminal.
        devices: devices to shard each chunk over (default: this process's, ``jax.local_devices()``).
        out: an .npz path to stream the results to, chunk by chunk, with host memory bounded by
            a chunk (uncompressed; same arrays as ``SweepResult.save_npz``). After
            ``jax.distributed.initialize`` each process solves and writes its own contiguous part
            of the points, to ``<stem>.partK-of-N.npz``; ``out`` is then required.
            ``tdct.gather(out)`` reads the result back either way.
        steps, gravity, transition, tendon_model, tol, max_iter: as for ``tdct.solve``.

    Returns:
        SweepResult (check ``converged`` or ``n_failed``), or with ``out`` the path written.
    """
    if out is None and jax.process_count() > 1:
        raise ValueError(
            f"out = None: a sweep over jax.process_count() = {jax.process_count()} processes needs out=, "
            "the .npz path each process writes its part to (tdct.gather(out) joins them)"
        )
    plan = _plan(
        robot,
        act,
        load,
        grid=grid,
        batch=batch,
        warm_start=warm_start,
        shapes=shapes,
        compliance=compliance,
        devices=devices,
        steps=steps,
        gravity=gravity,
        transition=transition,
        tendon_model=tendon_model,
        tol=tol,
        max_iter=max_iter,
    )
    start = perf_counter()
    chunks = _chunks(plan, chunk_size, progress)
    if out is not None:
        return _stream_npz(out, plan, chunks)
    outputs = _joined([c.outputs for c in chunks])
    inputs = unflatten(plan.points, plan.shape, plan.lead)
    return SweepResult(plan.shape, plan.axes, inputs, seconds=perf_counter() - start, **unflatten(outputs, plan.shape))


def part_path(path, k: int, n: int) -> Path:
    """Where process k of n writes its part of ``sweep(..., out=path)``: ``<stem>.partK-of-N<suffix>``."""
    path = Path(path)
    return path.with_name(f"{path.stem}.part{k}-of-{n}{path.suffix}")


def _stream_npz(path, plan: _Plan, chunks: Iterator[SweepChunk]) -> Path:
    """Writes each chunk into .npy files (memory-mapped) beside ``path`` as it comes, then stores
    them in one uncompressed .npz: the whole sweep, or this process's part (flat, with ``points``
    = [start, stop))."""
    path, k, n_proc = Path(path), jax.process_index(), jax.process_count()
    whole = n_proc == 1
    if not whole:
        path = part_path(path, k, n_proc)
    n = len(next(iter(plan.points.values()))) * (plan.shape[-1] if plan.lead == 2 else 1)
    lead = plan.shape if whole else (n,)
    with tempfile.TemporaryDirectory(dir=path.parent, prefix=f".{path.name}.") as tmp:
        files = []

        def save(name, array):
            files.append(Path(tmp) / f"{name}.npy")
            np.save(files[-1], array)

        save("shape", np.asarray(plan.shape))
        for name, v in (plan.axes or {}).items():
            save(f"axis_{name}", v)
        for name, v in plan.points.items():
            save(f"input_{name}", v.reshape(lead + v.shape[plan.lead :]))
        outputs, first = {}, None
        for c in chunks:
            first = c.start if first is None else first
            for name, v in dict(c.outputs, tip_angle=np.asarray(tip_angle(c.outputs["tip_rotation"]))).items():
                if name not in outputs:
                    files.append(Path(tmp) / f"{name}.npy")
                    outputs[name] = open_memmap(files[-1], mode="w+", dtype=v.dtype, shape=lead + v.shape[1:])
                outputs[name].reshape(-1, *v.shape[1:])[c.start - first : c.stop - first] = v
        for v in outputs.values():
            v.flush()
        if not whole:
            save("points", np.asarray([first, first + n]))
        partial = Path(tmp) / "sweep.npz"
        with zipfile.ZipFile(partial, "w", zipfile.ZIP_STORED) as archive:
            for f in files:
                archive.write(f, f.name)
        os.replace(partial, path)
    return path


def _result(arrays: Mapping) -> SweepResult:
    """A SweepResult from arrays named as in a sweep's .npz file."""
    fields = {f.name for f in dataclasses.fields(SweepResult)} - {"shape", "axes", "inputs", "seconds"}
    axes = {name[5:]: v for name, v in arrays.items() if name.startswith("axis_")}
    return SweepResult(
        shape=tuple(int(x) for x in arrays["shape"]),
        axes=axes or None,
        inputs={name[6:]: v for name, v in arrays.items() if name.startswith("input_")},
        **{name: v for name, v in arrays.items() if name in fields},
    )


def gather(path) -> SweepResult:
    """Reads what ``sweep(..., out=path)`` wrote: the file itself or, after a sweep over N
    processes, its parts ``<stem>.partK-of-N.npz`` joined in order.

    Returns:
        SweepResult equal to the one a single-process sweep returns (``seconds`` NaN).

    Raises:
        ValueError: when neither the file nor its parts are there, or parts are missing, from
            different sweeps or from sweeps over different process counts.
    """
    path = Path(path)
    if path.exists():
        with np.load(path) as data:
            arrays = dict(data)
        if "points" in arrays:
            raise ValueError(
                f"{path} holds one part of a sweep (points {arrays['points'].tolist()}); gather the path given as out="
            )
        return _result(arrays)
    pattern = re.compile(rf"{re.escape(path.stem)}\.part(\d+)-of-(\d+){re.escape(path.suffix)}")
    found = {tuple(map(int, m.groups())): f for f in path.parent.glob(f"{path.stem}.part*") if (m := pattern.fullmatch(f.name))}
    counts = sorted({n for _, n in found})
    if len(counts) != 1:
        problem = "nor any part" if not counts else f"and its parts come from sweeps over {counts} processes"
        raise ValueError(f"{path}: no such file, {problem} (<stem>.partK-of-N{path.suffix})")
    n_proc = counts[0]
    missing = sorted(set(range(n_proc)) - {k for k, _ in found})
    if missing:
        raise ValueError(f"{path}: part(s) {missing} of {n_proc} are missing")
    parts = []
    for k in range(n_proc):
        with np.load(found[k, n_proc]) as data:
            parts.append(dict(data))
    shape, stop = tuple(parts[0]["shape"]), 0
    for k, part in enumerate(parts):
        start, end = part.pop("points").tolist()
        if start != stop or tuple(part["shape"]) != shape:
            raise ValueError(
                f"{found[k, n_proc]}: points [{start}, {end}) of a sweep of shape {tuple(part['shape'])}, "
                f"expected points from {stop} of shape {shape}: parts of different sweeps"
            )
        stop = end
    if stop != math.prod(shape):
        raise ValueError(f"{path}: the parts hold {stop} points, the sweep's shape {shape} has {math.prod(shape)}")
    joined = {k: v for k, v in parts[0].items() if k == "shape" or k.startswith("axis_")}
    for k in parts[0].keys() - joined.keys():
        column = np.concatenate([p[k] for p in parts])
        joined[k] = column.reshape(shape + column.shape[1:])
    return _result(joined)
