"""The batch engine: a per-point function run as one compiled ``jax.vmap`` over chunks of points,
sharded over this process's devices, with a progress bar; lanes that have not converged after a
short first pass are solved again apart, so that they do not hold up their chunk. No physics:
sweeps, load capacities and optimal insertions bring their own per-point kernels."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Collection, Iterator

import jax
import numpy as np
from jax.sharding import Mesh
from jax.sharding import PartitionSpec as P
from tqdm import tqdm

from . import status
from .checks import check_integer

CHUNK_SIZES = {"cpu": 128, "gpu": 65536}
"""Default configurations per device per compiled call, by device platform (``chunk_size=``, the
total per call, overrides; a smaller batch rounds up to a power of two; other platforms take the
cpu value). cpu: measured for the engine on the 2-core CPU (benchmarks/sweep_throughput.py,
2026-11-25, 2,048 points): 128 lanes per device was the fastest or within the noise of it, on one
device (804 solves/s; 64: 670, 256: 738, 512: 458) and on two (chunks of 256: 1,576; 512: 1,584;
128: 1,525). gpu: measured on one H100 (benchmarks/gpu_throughput.py, 2026-11-26): 10^6 points
streamed at 45,200 solves/s with 65,536 lanes (262,144: 44,700; on 131,072 points 32,768: 41,800,
8,192: 23,700, 2,048: 10,000), 301 MB of GPU memory at its peak."""
FIRST_PASS = 12
"""Quasi-Newton steps each lane gets in a chunk's first pass, for kernels that allow it
(``Kernel.retire``): one Jacobian pass, then Broyden updates, one integration per step, no load
continuation. A vmapped loop runs until its slowest lane stops, so lanes that need more (or fail)
would hold every lane of their chunk through all continuation stages; instead they are solved
again from the start with the full solver, RETRY_LANES at a time, and their answers are the single
solve's. None: one pass with the full solver. benchmarks/sweep_throughput.py measures both."""
RETRY_LANES = 32
"""Most configurations per compiled call of the second pass (fewer lanes, rounded up to a power of
two, when fewer need it: a padded lane costs a whole solve). With 1% of the points failing, 32
against 8 lanes measured 487 against 438 solves/s at 1,024 points and 511 against 480 at 4,096
(one CPU device, 2026-11-25), tips and result codes bit for bit the same."""
RETRY_CHUNKS = 4
"""Most chunks whose unconverged points wait to be solved again together (``iter_batched``): more
fill the second pass's lanes better, but hold back finished chunks (and their durable saves). With
1% of 1,024 points failing, 4 against 1 (each chunk's stragglers alone) measured 470 against 411
solves/s (one CPU device, 2026-11-25); without failures 749 against 760, within the noise."""
AXIS = "batch"
"""Name of the device-mesh axis the batch is sharded over."""


@dataclasses.dataclass(frozen=True)
class Kernel:
    """What runs per point (static: each distinct value compiles once per chunk size).

    ``function(base, point, kernel)`` returns a dict of arrays for one point; ``base`` is the
    pytree every point shares (robot, actuation, load, gravity, solver options, ...).
    ``options`` are hashable settings the function reads (e.g. which outputs to return).
    ``retire``: the function returns a per-point ``result`` code and, given the option
    ``first_pass`` (a number of steps), makes a quick first try with at most that many; the
    engine then runs it in two passes (``FIRST_PASS``).
    """

    function: Callable
    options: tuple = ()
    mesh: Mesh | None = None
    retire: bool = False

    def option(self, name: str, default=None):
        return dict(self.options).get(name, default)


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


BATCH_ROTATIONS = {"cpu": "matrix"}
"""``SolverOptions.rotation`` of a batch by its devices' platform (others: "columns") where the
solver leaves it None (benchmarks/README.md, "R by its columns in the RK4 scan")."""


def batch_solver(solver, mesh: Mesh | None = None):
    """``solver`` with the rotation layout of a batch on the mesh's devices (``BATCH_ROTATIONS``;
    no mesh: the default backend)."""
    if solver.rotation is not None:
        return solver
    return dataclasses.replace(solver, rotation=BATCH_ROTATIONS.get(_platform(mesh), "columns"))


def _platform(mesh: Mesh | None) -> str:
    return jax.default_backend() if mesh is None else mesh.devices.flat[0].platform


def default_chunk_size(mesh: Mesh | None = None) -> int:
    """Configurations per compiled call by default: ``CHUNK_SIZES`` for the platform of the mesh's
    devices, times their number (no mesh: one device of the default backend)."""
    return CHUNK_SIZES.get(_platform(mesh), CHUNK_SIZES["cpu"]) * (1 if mesh is None else mesh.size)


def lanes_per_call(n: int, chunk_size: int, n_devices: int = 1) -> int:
    """Configurations per compiled call for n points: ``chunk_size``, or the power of two at or
    above n when that is smaller, rounded up to a multiple of the device count."""
    chunk = min(chunk_size, 1 << max(n - 1, 0).bit_length())
    return -(-chunk // n_devices) * n_devices


def chunk_lanes(kernel: Kernel, n: int, chunk_size=None) -> int:
    """Configurations per compiled call when ``iter_batched`` runs ``kernel`` over n points: its
    chunk i holds points [i * lanes, (i + 1) * lanes). ``chunk_size`` None: ``default_chunk_size``."""
    if chunk_size is None:
        chunk_size = default_chunk_size(kernel.mesh)
    check_integer("chunk_size", chunk_size)
    return lanes_per_call(n, chunk_size, 1 if kernel.mesh is None else kernel.mesh.size)


def iter_batched(
    kernel: Kernel,
    base,
    points: dict,
    *,
    chunk_size=None,
    progress=True,
    desc="solving",
    per_point=1,
    skip: Collection[int] = (),
) -> Iterator[tuple[int, dict]]:
    """Runs ``kernel`` over the leading axis of ``points`` in chunks, yielding each chunk's
    (first row, numpy outputs) in order, as soon as it is complete, with the next chunk already
    dispatched.

    Every chunk has the same static shape (the last is padded by repeating its final point), so
    one compile serves the whole batch and any later one with the same chunk size.
    ``chunk_size`` None takes ``default_chunk_size`` for the kernel's devices. ``per_point`` is
    the number of solves each point stands for (the progress bar counts solves). ``skip``: indices
    of chunks (see ``chunk_lanes``) not to compute, done before; the progress bar starts at them.

    Two passes (``Kernel.retire``): the points a chunk's first pass leaves unconverged wait, with
    their chunk, until RETRY_LANES of them (or RETRY_CHUNKS chunks) have gathered, then are solved
    again together, so that one call of the full solver serves the stragglers of several chunks.
    """
    n = len(next(iter(points.values())))
    chunk = chunk_lanes(kernel, n, chunk_size)
    n_devices = 1 if kernel.mesh is None else kernel.mesh.size
    # one device: commit the points to it, so jit runs there and not on the default device
    device = kernel.mesh.devices.flat[0] if kernel.mesh is not None and n_devices == 1 else None
    two_pass = kernel.retire and FIRST_PASS is not None
    first = dataclasses.replace(kernel, options=kernel.options + (("first_pass", FIRST_PASS),)) if two_pass else kernel

    def run(kernel, rows, lanes):
        index = np.concatenate([rows, np.full(lanes - len(rows), rows[-1])])
        chunk_points = {k: v[index] for k, v in points.items()}
        if device is not None:
            chunk_points = jax.device_put(chunk_points, device)
        return _run_chunk(base, chunk_points, kernel)

    waiting: list[tuple[int, dict, np.ndarray]] = []  # (first row, outputs, rows to solve again), in order

    def finished(start, out, last):
        """The chunks complete once this one joins the waiting ones, in order."""
        m = min(chunk, n - start)
        out = {k: np.array(v[:m]) for k, v in jax.device_get(out).items()}  # writable: retried lanes go in
        again = np.flatnonzero(out["result"] != status.SUCCESS) if two_pass else np.zeros(0, int)
        waiting.append((start, out, again))
        rows = np.concatenate([s + a for s, _, a in waiting])
        if rows.size and not (last or rows.size >= RETRY_LANES or len(waiting) >= RETRY_CHUNKS):
            return []
        if rows.size:
            bar.set_postfix_str(f"solving {rows.size} apart")
            lanes = min(chunk, lanes_per_call(rows.size, RETRY_LANES, n_devices))
            groups = np.array_split(rows, -(-rows.size // lanes))
            parts = [jax.device_get(run(kernel, g, lanes)) for g in groups]
            retried = joined([{k: v[: len(g)] for k, v in p.items()} for p, g in zip(parts, groups, strict=True)])
            offset = 0
            for _, o, a in waiting:
                for k, v in o.items():
                    v[a] = retried[k][offset : offset + len(a)]
                offset += len(a)
        done = [(s, o) for s, o, _ in waiting]
        waiting.clear()
        bar.update(sum(min(chunk, n - s) for s, _ in done) * per_point)
        bar.set_postfix_str("")
        return done

    starts = [start for start in range(0, n, chunk) if start // chunk not in skip]
    done = n - sum(min(chunk, n - start) for start in starts)
    with tqdm(
        total=n * per_point, initial=done * per_point, unit="solve", desc=desc, disable=not progress, dynamic_ncols=True
    ) as bar:
        bar.set_postfix_str("compiling")
        pending = None
        for start in starts:
            out = run(first, np.arange(start, min(start + chunk, n)), chunk)  # runs while the last chunk is fetched
            if pending is not None:
                yield from finished(*pending, last=False)
            pending = start, out
        if pending is not None:
            yield from finished(*pending, last=True)


def run_batched(kernel: Kernel, base, points: dict, **options) -> dict:
    """``iter_batched``'s chunks joined: numpy outputs over the whole leading axis of ``points``."""
    return joined([out for _, out in iter_batched(kernel, base, points, **options)])


def batch_options(*, chunk_size=None, progress=True, devices=None):
    """The batching options of the grid entry points (as for ``tdct.sweep``), checked; returns
    run(kernel, base, points, desc) -> joined numpy outputs, with those options applied."""
    if chunk_size is not None:
        check_integer("chunk_size", chunk_size)
    mesh = mesh_for(devices)

    def run(kernel: Kernel, base, points: dict, desc: str) -> dict:
        kernel = dataclasses.replace(kernel, mesh=mesh)
        return run_batched(kernel, base, points, chunk_size=chunk_size, progress=progress, desc=desc)

    return run


def joined(parts: list[dict]) -> dict:
    """Chunks' outputs (dicts of arrays with a leading point axis) concatenated along that axis."""
    return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
