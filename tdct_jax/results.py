"""Results over many points (sweeps, load capacities, optimal insertions): their types, .npz and
.csv files, and reading back a sweep's file or joining the parts of a multi-process sweep."""

from __future__ import annotations

import csv
import dataclasses
import math
import re
import zipfile
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from . import status
from .checkpoint import partial_path, progress
from .solve import tip_angle

UNITS = {
    "tensions": "N",
    "insertion": "m",
    "force": "N",
    "moment": "Nm",
    "tip_mass": "kg",
    "point_force": "N",
    "point_moment": "Nm",
    "E_silicone": "Pa",  # the former paper names (fields.PAPER_NAMES), still accepted with a FutureWarning
    "E_tube": "Pa",
    "E": "Pa",
    "mass": "kg",
    "angle": "rad",
    "twist": "rad_per_m",
    "max_tension": "N",
    "stiffness": "N",
}


def unit_of(name: str) -> str:
    """The SI unit of a sweepable input or robot field (``sections[*].E`` by its last part), as
    written in CSV column names."""
    name = name.rsplit(".", 1)[-1]
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
        tensions: the tendon tensions [N], (n_tendons,): the given ones and those found for
            displacement-driven tendons (slack: exactly 0).
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
    tensions: np.ndarray | None = None

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
    """Outputs of ``tdct.capacity`` over a grid: mass [kg] (0 where unreachable, with result
    UNREACHABLE), reachable, iterations (safeguarded Newton steps on the mass), per point."""

    mass: np.ndarray
    reachable: np.ndarray
    iterations: np.ndarray

    CSV_COLUMNS = dict(mass="mass_kg", reachable="reachable", converged="converged", result="result", iterations="iterations")


@dataclasses.dataclass(frozen=True, kw_only=True)
class OptimumResult(GridResult):
    """Outputs of ``tdct.optimal_insertion`` without a bracket: insertion [m] that maximises the tip height, the
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


def _read_npz(path: Path) -> dict:
    """The arrays of a sweep's .npz file; a ValueError says so when it is not one."""
    what = "not a tdct sweep result (an .npz, as sweep(out=) or SweepResult.save_npz write it)"
    if not zipfile.is_zipfile(path):
        raise ValueError(f"{path}: {what}: it is not an .npz (zip) archive")
    try:
        with np.load(path) as data:
            arrays = dict(data)
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as e:
        raise ValueError(f"{path}: {what}: numpy cannot read its arrays ({e})") from None
    missing = sorted({"shape", "result", "tip_position"} - set(arrays))
    if missing:
        raise ValueError(f"{path}: {what}: it lacks the arrays {missing}")
    return arrays


def gather(path) -> SweepResult:
    """Reads what ``sweep(..., out=path)`` wrote: the file itself or, after a sweep over N
    processes, its parts ``<stem>.partK-of-N.npz`` joined in order.

    Returns:
        SweepResult equal to the one a single-process sweep returns (``seconds`` NaN).

    Raises:
        ValueError: when the file is not there (naming every missing or unfinished part, and
            how far each partial folder got), is not a sweep's .npz, or its parts come from
            different sweeps or from sweeps over different process counts.
    """
    path = Path(path)
    if path.exists():
        arrays = _read_npz(path)
        if "points" in arrays:
            raise ValueError(
                f"{path} holds one part of a sweep (points {arrays['points'].tolist()}); gather the path given as out="
            )
        return sweep_result(arrays)
    pattern = re.compile(rf"{re.escape(path.stem)}\.part(\d+)-of-(\d+)({re.escape(path.suffix)}|\.partial)")
    found, partial = {}, {}
    for f in path.parent.glob(f"{path.stem}.part*"):
        if m := pattern.fullmatch(f.name):
            (partial if m.group(3) == ".partial" else found)[int(m.group(1)), int(m.group(2))] = f
    counts = sorted({n for _, n in found | partial})
    if not counts:
        single = progress(partial_path(path))
        if single is None:
            raise ValueError(f"{path}: no such file, nor any part (<stem>.partK-of-N{path.suffix})")
        raise ValueError(
            f"{path}: not finished: its partial folder {partial_path(path).name} holds {single[0]} of {single[1]} chunks; "
            "rerun the same sweep to finish it"
        )
    if len(counts) > 1:
        raise ValueError(f"{path}: no such file, and its parts come from sweeps over {counts} processes")
    n_proc = counts[0]
    unfinished = []
    for k in range(n_proc):
        if (k, n_proc) in found:
            continue
        done = progress(partial[k, n_proc]) if (k, n_proc) in partial else None
        where = "no file, no partial folder" if done is None else f"{partial[k, n_proc].name}: {done[0]} of {done[1]} chunks"
        unfinished.append(f"part {k} ({where})")
    if unfinished:
        raise ValueError(
            f"{path}: {len(unfinished)} of {n_proc} parts are missing or unfinished: {', '.join(unfinished)}; "
            f"rerun the same sweep over {n_proc} processes to finish them"
        )
    parts = [_read_npz(found[k, n_proc]) for k in range(n_proc)]
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
