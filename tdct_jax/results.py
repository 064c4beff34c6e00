"""Results over many points (sweeps, load capacities, optimal insertions): their types, .npz and
.csv files, streaming a sweep to disk chunk by chunk, and joining the parts of a multi-process sweep."""

from __future__ import annotations

import csv
import dataclasses
import math
import os
import re
import tempfile
import zipfile
from collections.abc import Iterator, Mapping
from pathlib import Path

import jax
import numpy as np
from numpy.lib.format import open_memmap

from . import status
from .solve import tip_angle

UNITS = {
    "tensions": "N",
    "insertion": "m",
    "force": "N",
    "moment": "Nm",
    "tip_mass": "kg",
    "E_silicone": "Pa",
    "E_tube": "Pa",
}


def unit_of(name: str) -> str:
    """The SI unit of a sweepable input or Robot field, as written in CSV column names."""
    if name in UNITS:
        return UNITS[name]
    return "kg_per_m3" if name.startswith("density") else "1" if name.startswith("nu") else "m"


@dataclasses.dataclass(frozen=True, kw_only=True)
class GridResult:
    """Per-point outputs (numpy) over a grid or batch of inputs.

    Attributes:
        shape: grid shape (one axis per grid name, in order) or (n_points,) for a batch.
        axes: the grid's axis values by name (None for a batch).
        inputs: each swept input at every point, shape ``shape + point shape``.
        result: a ``tdct_jax.status`` code per point (0: converged).
        seconds: wall time, compiles included (NaN when read from a file).
    """

    shape: tuple
    axes: dict | None
    inputs: dict
    result: np.ndarray
    seconds: float = float("nan")

    CSV_COLUMNS = {}  # output field -> CSV column name with its unit, for per-point scalar outputs

    @property
    def converged(self) -> np.ndarray:
        """result == SUCCESS, per point."""
        return self.result == status.SUCCESS

    @property
    def n_failed(self) -> int:
        return int(np.count_nonzero(self.result != status.SUCCESS))

    def outputs(self) -> dict:
        """Every output array by name (the computed ones included), without inputs and axes."""
        skip = {"shape", "axes", "inputs", "seconds"}
        out = {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.name not in skip}
        return {k: v for k, v in out.items() if isinstance(v, np.ndarray)} | {"converged": self.converged}

    def save_npz(self, path) -> Path:
        """Writes every array to a compressed .npz (inputs as ``input_<name>``, axes as ``axis_<name>``)."""
        path = Path(path)
        arrays = {f"input_{k}": v for k, v in self.inputs.items()}
        arrays.update({f"axis_{k}": v for k, v in (self.axes or {}).items()})
        np.savez_compressed(path, shape=np.asarray(self.shape), **arrays, **self.outputs())
        return path

    def csv_columns(self) -> dict:
        """Per-point output columns for ``save_csv``, named with their units."""
        return {column: getattr(self, name) for name, column in self.CSV_COLUMNS.items()}

    def save_csv(self, path) -> Path:
        """Writes one row per point: the inputs and the per-point outputs, SI units in the header."""
        path = Path(path)
        n = math.prod(self.shape)
        columns: dict[str, np.ndarray] = {}
        for k, v in self.inputs.items():
            v = v.reshape(n, -1)
            labels = [k] if v.shape[1] == 1 else [f"{k}_{i + 1}" for i in range(v.shape[1])]
            columns.update({f"{label}_{unit_of(k)}": v[:, i] for i, label in enumerate(labels)})
        columns.update({k: np.asarray(v).reshape(n) * 1 for k, v in self.csv_columns().items()})
        with path.open("w", newline="") as f:
            w = csv.writer(f)
            w.writerow(columns)
            w.writerows(zip(*(c.tolist() for c in columns.values()), strict=True))
        return path


@dataclasses.dataclass(frozen=True, kw_only=True)
class SweepResult(GridResult):
    """Outputs of ``tdct.sweep``, numpy arrays whose leading axes have the sweep's ``shape``.

    Attributes (besides GridResult's):
        tip_position [m], tip_rotation, iterations, stages, residual_norm, base_wrench (N(0) [N],
            M(0) [N m]): as on ``Solution``.
        s, position: arc length [m] and shape [m] at the RK4 nodes (with ``shapes=True``).
        compliance: 3x3 tip compliance [m/N] (with ``compliance=True``; NaN where not converged).
    """

    tip_position: np.ndarray
    tip_rotation: np.ndarray
    iterations: np.ndarray
    stages: np.ndarray
    residual_norm: np.ndarray
    base_wrench: np.ndarray
    s: np.ndarray | None = None
    position: np.ndarray | None = None
    compliance: np.ndarray | None = None

    CSV_COLUMNS = dict(tip_angle="tip_angle_rad", converged="converged", result="result", iterations="iterations")

    @property
    def tip_angle(self) -> np.ndarray:
        """theta_tip [rad] (see ``Solution.tip_angle``)."""
        return np.asarray(tip_angle(self.tip_rotation))

    def outputs(self) -> dict:
        return super().outputs() | {"tip_angle": self.tip_angle}

    def csv_columns(self) -> dict:
        tip = {f"tip_{c}_m": self.tip_position[..., i] for i, c in enumerate("xyz")}
        return tip | super().csv_columns() | {"residual_norm": self.residual_norm}


@dataclasses.dataclass(frozen=True, kw_only=True)
class CapacityResult(GridResult):
    """Outputs of ``tdct.load_capacity``: mass [kg] (0 where unreachable), reachable, iterations
    (safeguarded Newton steps on the mass), per point."""

    mass: np.ndarray
    reachable: np.ndarray
    iterations: np.ndarray

    CSV_COLUMNS = dict(mass="mass_kg", reachable="reachable", converged="converged", result="result", iterations="iterations")


@dataclasses.dataclass(frozen=True, kw_only=True)
class OptimumResult(GridResult):
    """Outputs of ``tdct.optimal_insertion``: insertion [m] that maximises the tip height, the
    height [m] and its slope dy/dd there, iterations, whether the optimum is interior, and the
    curve it was bracketed on: curve_insertion (n_curve,) [m], curve_height (shape + (n_curve,)) [m]."""

    insertion: np.ndarray
    height: np.ndarray
    slope: np.ndarray
    iterations: np.ndarray
    interior: np.ndarray
    curve_insertion: np.ndarray
    curve_height: np.ndarray

    CSV_COLUMNS = dict(
        insertion="insertion_m", height="height_m", slope="slope", converged="converged", result="result", iterations="iterations"
    )


@dataclasses.dataclass(frozen=True)
class SweepChunk:
    """One chunk of a sweep, as ``sweep_chunks`` yields it.

    Attributes:
        start, stop: the chunk holds points [start, stop) of the sweep's points in C order (a
            grid's last axis fastest; ``np.unravel_index(i, shape)`` gives a point's grid index).
        shape: the whole sweep's shape.
        inputs: each swept input at the chunk's points, leading axis stop - start.
        outputs: tip_position, tip_rotation, result, ... as on ``SweepResult``, leading axis stop - start.
    """

    start: int
    stop: int
    shape: tuple
    inputs: dict
    outputs: dict


def part_path(path, k: int, n: int) -> Path:
    """Where process k of n writes its part of ``sweep(..., out=path)``: ``<stem>.partK-of-N<suffix>``."""
    path = Path(path)
    return path.with_name(f"{path.stem}.part{k}-of-{n}{path.suffix}")


def stream_npz(path, shape: tuple, axes: dict | None, inputs: dict, lead: int, chunks: Iterator[SweepChunk]) -> Path:
    """Writes each chunk into .npy files (memory-mapped) beside ``path`` as it comes, then stores
    them in one uncompressed .npz: the whole sweep, or after ``jax.distributed.initialize`` this
    process's part (flat, with ``points`` = [start, stop)). ``inputs`` are this process's rows,
    with ``lead`` leading axes per row."""
    path, k, n_proc = Path(path), jax.process_index(), jax.process_count()
    whole = n_proc == 1
    if not whole:
        path = part_path(path, k, n_proc)
    n = len(next(iter(inputs.values()))) * (shape[-1] if lead == 2 else 1)
    flat = shape if whole else (n,)
    with tempfile.TemporaryDirectory(dir=path.parent, prefix=f".{path.name}.") as tmp:
        files = []

        def save(name, array):
            files.append(Path(tmp) / f"{name}.npy")
            np.save(files[-1], array)

        save("shape", np.asarray(shape))
        for name, v in (axes or {}).items():
            save(f"axis_{name}", v)
        for name, v in inputs.items():
            save(f"input_{name}", v.reshape(flat + v.shape[lead:]))
        outputs, first = {}, None
        for c in chunks:
            first = c.start if first is None else first
            derived = dict(tip_angle=np.asarray(tip_angle(c.outputs["tip_rotation"])), converged=c.outputs["result"] == 0)
            for name, v in dict(c.outputs, **derived).items():
                if name not in outputs:
                    files.append(Path(tmp) / f"{name}.npy")
                    outputs[name] = open_memmap(files[-1], mode="w+", dtype=v.dtype, shape=flat + v.shape[1:])
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


def sweep_result(arrays: Mapping) -> SweepResult:
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
        return sweep_result(arrays)
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
    return sweep_result(joined)
