"""Measured shapes (e.g. FBG shape-sensor data) and the conditions they were measured under: the shape-file format, its reader and writer.

One shape file holds one measured shape: a few ``#`` header lines with the conditions, then a
CSV table of points. It is plain UTF-8 text that any FBG software or spreadsheet can produce::

    # tdct_jax shape v1
    # name: t1-6N_d80mm_m20g
    # tensions_N: 6, 0, 0, 0
    # insertion_mm: 80
    # tip_mass_g: 20
    # tip_force_N: 0, 0, 0
    # tip_moment_Nmm: 0, 0, 0
    s_mm,x_mm,y_mm,z_mm
    0,0,0,0
    5,0.01,-0.02,4.999
    10,0.02,-0.08,9.997

Header lines start with ``#`` and read ``key: value``; values with several numbers are separated
by commas (or spaces). The keys:

    tensions_N      required: the tension of each tendon [N], tendon 1 first, one per tendon.
    insertion_mm    Nitinol tube insertion from the base [mm], 0 to the robot length; default 0
                    (a robot without a tube: 0 or absent; the format holds one tube's depth).
    tip_mass_g      mass hanging at the tip [g], >= 0; default 0. Its weight is added by
                    ``Experiment.tip_load``, so do not count it in tip_force_N as well.
    tip_force_N     other tip force [N], world frame (x, y, z); default 0, 0, 0.
    tip_moment_Nmm  tip moment [N mm], world frame (x, y, z); default 0, 0, 0.
    name            a label for the shape; default: the file name without its extension.

The first line ``# tdct_jax shape v1`` is written by ``write_experiment`` and optional when
reading. ``#`` lines that do not start with ``word:`` are free comments and ignored; an unknown
or repeated key is an error. Blank lines are ignored.

The first other line names the columns. It must contain ``s_mm``, ``x_mm``, ``y_mm`` and
``z_mm`` in any order; other columns are allowed and ignored. Every following line is one point:
its arc length from the base [mm], strictly increasing from >= 0, and its position [mm] in the
robot base frame, which is the world frame: base at the origin, robot axis along +z, gravity
along -y. At least 2 points are needed.

Units at the file edge are mm, g, N and N mm; an ``Experiment`` holds SI units (m, kg, N, N m).
An ``Experiment`` read from a file holds an ``Actuation`` (the tensions and the one tube's
insertion) and ``Loads`` (tip force and moment). The reader checks the file against the robot
(tendon count, insertion, arc length and point distance within the robot length plus 2% + 1 mm) and every error names the file and line
(``path:line: ...``), the value and what is allowed.

Several shapes: ``read_experiments`` reads files and folders into a list (the names stay there),
``stack`` pads and stacks them into one ``Experiment`` with a leading batch axis for ``jax.vmap``.
"""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import difflib
import math
import os
import re
from collections.abc import Iterable, Sequence
from pathlib import Path

import jax.numpy as jnp
import numpy as np

from .checks import as_array, check_range, is_concrete
from .description import Robot
from .inputs import STANDARD_GRAVITY, Actuation, Loads, gravity_vector
from .tree import pytree, set_fields, static, unchecked

VERSION = "1"
COLUMNS = ("s_mm", "x_mm", "y_mm", "z_mm")
HEADER_KEYS = ("name", "tensions_N", "insertion_mm", "tip_mass_g", "tip_force_N", "tip_moment_Nmm")
LENGTH_SLACK = (0.02, 1.0)
"""Arc lengths and point distances may exceed the robot length by 2% + 1 mm (sensor and fixture)."""

FORMAT = """\
# tdct_jax shape v1
# name: t1-6N_d80mm_m20g
# tensions_N: 6, 0, 0, 0
# insertion_mm: 80
# tip_mass_g: 20
# tip_force_N: 0, 0, 0
# tip_moment_Nmm: 0, 0, 0
s_mm,x_mm,y_mm,z_mm
0,0,0,0
5,0.01,-0.02,4.999
10,0.02,-0.08,9.997
"""
"""A complete shape file to copy; the module docstring explains each line."""


@pytree
class Experiment:
    """One measured shape and the conditions it was measured under, SI units.

    A pytree: every array is a leaf (``name`` is static), so experiments pass through
    ``jax.jit``, and a ``stack`` of them (a leading batch axis on every leaf) through ``jax.vmap``.

    Attributes:
        s: arc length of each measured point from the base [m], shape (n,), strictly increasing,
            >= 0 (a repeat is allowed only for padding points of weight 0, see ``stack``).
        position: measured positions [m], shape (n, 3), robot base frame = world frame (base at
            the origin, axis +z, gravity -y).
        act: tendon tensions [N], displacements and each tube's insertion [m] (an Actuation;
            the shape-file format holds tensions and one tube's insertion).
        load: the loads, world frame, without the tip mass (a Loads: tip force [N] and moment
            [N m], point loads along the body; the shape-file format holds the tip's); none by
            default.
        tip_mass: mass hanging at the tip [kg], >= 0 (shape (...) of a stack; one number for all).
        weight: weight of each point, shape (n,), >= 0; None means all ones (0 marks padding).
        name: a label (static: experiments with different names do not share one compilation).
    """

    s: object
    position: object
    act: Actuation
    load: Loads = dataclasses.field(default_factory=Loads)
    tip_mass: float = 0.0
    weight: object = None
    name: str = static(default="")

    def __post_init__(self):
        if not isinstance(self.act, Actuation):
            raise TypeError(f"act must be a tdct.Actuation, got {type(self.act).__name__}")
        load = Loads() if self.load is None else self.load
        if not isinstance(load, Loads):
            raise TypeError(f"load must be a tdct.Loads, got {type(load).__name__}")
        if not isinstance(self.name, str):
            raise TypeError(f"name must be a str, got {type(self.name).__name__}")
        s = as_array("s", self.s)
        batch = np.shape(self.act.tensions)[:-1] if is_concrete(self.act.tensions) else None
        if is_concrete(s) and batch is not None and (s.shape[:-1] != batch or s.shape[-1:] == (0,)):
            stacked = f" (a stack of {batch[0]}: {batch + ('n',)}, like its actuation)" if batch else ""
            raise ValueError(f"s must have shape (n,) with n >= 1, one arc length [m] per point{stacked}, got shape {s.shape}")
        shape = s.shape if is_concrete(s) else None
        weight, tip_mass = self.weight, self.tip_mass
        if shape is not None and len(shape) > 1 and is_concrete(tip_mass) and np.ndim(tip_mass) == 0:
            tip_mass = np.full(shape[:-1], float(tip_mass))  # one tip mass for every experiment of a stack
        if weight is None:
            weight = np.ones(s.shape) if is_concrete(s) else jnp.ones_like(s)
        set_fields(
            self,
            load=load,
            s=s,
            position=as_array("position", self.position, None if shape is None else shape + (3,)),
            weight=as_array("weight", weight, shape),
            tip_mass=as_array("tip_mass", tip_mass, None if shape is None else shape[:-1]),
        )
        check_range("tip_mass", self.tip_mass, 0.0, unit=" kg")
        check_range("weight", self.weight, 0.0)
        check_range("s", s, 0.0, unit=" m")
        if is_concrete(s) and is_concrete(self.weight):
            _check_increasing(s.reshape(-1, s.shape[-1]), self.weight.reshape(-1, s.shape[-1]))

    @property
    def n_points(self) -> int:
        return int(np.shape(self.s)[-1])

    def tip_load(self, gravity=STANDARD_GRAVITY) -> Loads:
        """The whole load: ``load`` plus the weight of ``tip_mass`` under ``gravity`` [m/s^2]
        (None: no weight) at the tip. Works under jit and vmap, and on a stack."""
        weight = jnp.einsum("...,i->...i", jnp.asarray(self.tip_mass), gravity_vector(gravity))
        rest = {f.name: getattr(self.load, f.name) for f in dataclasses.fields(Loads) if f.name != "tip_force"}
        return unchecked(Loads, tip_force=jnp.asarray(self.load.tip_force) + weight, **rest)


def _check_increasing(s: np.ndarray, weight: np.ndarray) -> None:
    """Each row of s (experiments, points) increases strictly where the weight is positive."""
    step = np.diff(s, axis=-1)
    bad = (step < 0) | ((step == 0) & (weight[:, 1:] > 0))
    if np.any(bad):
        row, i = np.unravel_index(int(np.argmax(bad)), bad.shape)
        where = f"experiment {row}: " if len(s) > 1 else ""
        raise ValueError(
            f"{where}s must be strictly increasing, got s[{i}] = {s[row, i]:g} m then s[{i + 1}] = {s[row, i + 1]:g} m"
            " (a repeat is allowed only for padding points of weight 0)"
        )


# ----------------------------------------------------------------------------- reading


def read_experiment(path: str | os.PathLike, robot: Robot | None = None) -> Experiment:
    """Reads one shape file (format: module docstring, example: ``FORMAT``) into SI units.

    Args:
        path: the shape file.
        robot: the robot that was measured, to check tendon count, insertion and lengths;
            default ``Robot.paper()``. Its tube count sets the actuation's insertions: one tube's
            depth ``insertion_mm``; none for a robot without a tube (``insertion_mm`` 0).

    Raises:
        ValueError: the file cannot be read or breaks the format; the message starts with
            ``path:line:`` (or ``path:`` for the whole file) and names value and allowed range.
    """
    path = Path(path)
    robot = Robot.paper() if robot is None else robot
    if not isinstance(robot, Robot):
        raise TypeError(f"robot must be a tdct.Robot, got {type(robot).__name__}")
    length_mm = 1000 * float(robot.length)
    header, points, lines = _parse(path, _read_text(path))
    if len(points) < 2:
        raise _error(path, 0, f"{len(points)} data row(s); a shape needs at least 2 points (rows after the column line)")
    s_mm, xyz_mm = points[:, 0], points[:, 1:]
    s_max, mm = float(s_mm.max()), "the columns must be in millimetres"
    _check_extent(path, lines, s_mm, length_mm, "s_mm", f"{mm} (s_mm)", (length_mm, f"on a {length_mm:g} mm robot"))
    _check_extent(
        path,
        lines,
        np.linalg.norm(xyz_mm, axis=1),
        length_mm,
        "distance of a point from the base",
        f"{mm} (x_mm, y_mm, z_mm), in the robot base frame (base at the origin, axis +z)",
        (s_max, f"although s_mm reaches {s_max:g} mm"),
    )
    values = _header_values(path, header, robot, length_mm)
    return Experiment(
        s=s_mm / 1000,
        position=xyz_mm / 1000,
        act=Actuation(values["tensions_N"], values["insertion_mm"][: robot.n_tubes] / 1000),
        load=Loads(tip_force=values["tip_force_N"], tip_moment=values["tip_moment_Nmm"] / 1000),
        tip_mass=values["tip_mass_g"][0] / 1000,
        name=values["name"] or path.stem,
    )


def read_experiments(paths: Iterable[str | os.PathLike] | str | os.PathLike, robot: Robot | None = None) -> list[Experiment]:
    """Reads shape files; a folder in ``paths`` contributes its ``*.csv`` files in sorted order.

    Raises:
        ValueError: nothing found, or a file is bad (see ``read_experiment``).
    """
    paths = [paths] if isinstance(paths, (str, os.PathLike)) else list(paths)
    files = []
    for p in map(Path, paths):
        files += sorted(f for f in p.glob("*.csv") if f.is_file()) if p.is_dir() else [p]
    if not files:
        raise ValueError(f"no shape files found in {[str(p) for p in paths]} (a folder contributes its *.csv files)")
    return [read_experiment(f, robot) for f in files]


def _error(path: Path, line: int, message: str) -> ValueError:
    return ValueError(f"{path}:{line}: {message}" if line else f"{path}: {message}")


@contextlib.contextmanager
def _at(path: Path, line: int):
    """Prefixes the ValueErrors raised inside with ``path:line:``."""
    try:
        yield
    except ValueError as e:
        raise _error(path, line, str(e)) from e


def _read_text(path: Path, what: str = "shape file") -> str:
    try:
        return path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as e:
        raise _error(path, 0, f"cannot read {what}: not UTF-8 text ({e.reason} at byte {e.start}); save it as UTF-8") from e
    except OSError as e:
        raise _error(path, 0, f"cannot read {what}: {e}") from e


def _parse(path: Path, text: str):
    """(header {key: (line, text)}, points (n, 4) [mm] in COLUMNS order, line of each point)."""
    header, columns, points, lines = {}, None, [], []
    for number, line in enumerate(text.splitlines(), start=1):
        if not line.strip():
            continue
        if line.lstrip().startswith("#"):
            _header_line(path, number, line.lstrip()[1:].strip(), header)
        elif columns is None:
            columns = _columns(path, number, line)
        else:
            points.append(_row(path, number, line, columns, points[-1][0] if points else None, lines[-1] if lines else 0))
            lines.append(number)
    if columns is None:
        raise _error(path, 0, f"no column line: after the '#' header a line must name the columns {','.join(COLUMNS)}")
    return header, np.array(points, dtype=float).reshape(-1, 4), lines


def _header_line(path: Path, number: int, body: str, header: dict) -> None:
    version = re.fullmatch(r"tdct_jax shape v(\S+)", body)
    if version and version[1] != VERSION:
        raise _error(path, number, f"shape file version {version[1]!r} is not supported; this reader reads v{VERSION}")
    entry = re.fullmatch(r"([A-Za-z_]\w*)\s*:(.*)", body)
    if entry is None:
        return  # a free comment
    key, value = entry[1], entry[2].strip()
    if key not in HEADER_KEYS:
        close = difflib.get_close_matches(key, HEADER_KEYS, n=1)
        guess = f" (did you mean {close[0]!r}?)" if close else ""
        raise _error(
            path,
            number,
            f"unknown header key {key!r}{guess}; allowed keys: {', '.join(HEADER_KEYS)}"
            " (a free comment must not start with 'word:')",
        )
    if key in header:
        raise _error(path, number, f"duplicate header key {key!r}, first given on line {header[key][0]}")
    header[key] = (number, value)


def _columns(path: Path, number: int, line: str) -> list[str]:
    """The names in the column line, which has each of COLUMNS once."""
    names = [c.strip() for c in next(csv.reader([line]))]
    missing = [c for c in COLUMNS if c not in names]
    if missing:
        hint = "; separate the columns by commas" if ";" in line or "\t" in line else ""
        raise _error(path, number, f"missing column(s) {missing}; found columns {names}; required: {', '.join(COLUMNS)}{hint}")
    twice = [c for c in COLUMNS if names.count(c) > 1]
    if twice:
        raise _error(path, number, f"column(s) {twice} appear more than once in {names}")
    return names


def _row(path: Path, number: int, line: str, columns: list, last_s, last_line: int) -> list[float]:
    """One point [mm]: s and position, checked against the row before."""
    fields = next(csv.reader([line]))
    if len(fields) != len(columns):
        raise _error(
            path, number, f"row has {len(fields)} fields, the column line has {len(columns)} {columns}: {line.strip()!r}"
        )
    point = [_number(path, number, c, fields[columns.index(c)]) for c in COLUMNS]
    s = point[0]
    if s < 0:
        raise _error(path, number, f"s_mm = {s:g} is negative; arc length must be >= 0")
    if last_s is not None and s <= last_s:
        raise _error(
            path,
            number,
            f"s_mm = {s:g} does not increase on line {last_line}'s s_mm = {last_s:g}; arc length must be strictly increasing",
        )
    return point


def _number(path: Path, number: int, name: str, text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise _error(path, number, f"{name} = {text.strip()!r} is not a number") from None
    if not math.isfinite(value):
        raise _error(path, number, f"{name} = {text.strip()} is not finite; every value must be a finite number")
    return value


def _check_extent(path: Path, lines: list, values: np.ndarray, length: float, what: str, hint: str, reference: tuple):
    """The largest of ``values`` [mm] is at most the robot ``length`` [mm] plus slack, and at least
    1 mm unless the size it should have, ``reference`` = (value [mm], words), is below 1 mm: that
    catches columns in metres."""
    i = int(np.argmax(values))
    largest, limit = float(values[i]), length * (1 + LENGTH_SLACK[0]) + LENGTH_SLACK[1]
    if largest > limit:
        raise _error(
            path,
            lines[i],
            f"{what} = {largest:g} mm is beyond the robot length {length:g} mm (at most {limit:g} mm: 2% + 1 mm slack); {hint}",
        )
    if largest < 1.0 < reference[0]:
        raise _error(path, lines[i], f"the largest {what} is {largest:g} mm {reference[1]}; {hint}; these look like metres")


def _header_values(path: Path, header: dict, robot: Robot, length_mm: float) -> dict:
    """The header values as float arrays (name as text), checked against the robot, defaults filled in."""
    n, tubes = robot.n_tendons, robot.n_tubes
    if tubes > 1:
        raise _error(path, 0, f"the robot has {tubes} tubes: a shape file holds one tube's insertion (insertion_mm)")
    if "tensions_N" not in header:
        raise _error(path, 0, f"missing header line '# tensions_N: ...' with one tension [N] per tendon ({n} for this robot)")
    specs = {  # key: (number of values, default, lower bound, upper bound, unit)
        "tensions_N": (n, None, 0.0, math.inf, " N"),
        "insertion_mm": (1, 0.0, 0.0, length_mm, " mm (0 to the robot length)") if tubes else (1, 0.0, 0.0, 0.0, " mm (no tube)"),
        "tip_mass_g": (1, 0.0, 0.0, math.inf, " g"),
        "tip_force_N": (3, 0.0, -math.inf, math.inf, " N"),
        "tip_moment_Nmm": (3, 0.0, -math.inf, math.inf, " N mm"),
    }
    values = {"name": header.get("name", (0, ""))[1]}
    for key, (count, default, lo, hi, unit) in specs.items():
        if key not in header:
            values[key] = np.full(count, default)
            continue
        number, text = header[key]
        items = [t for t in re.split(r"[,\s]+", text) if t]
        if len(items) != count:
            why = f" (the robot has {n} tendons, one tension each)" if key == "tensions_N" else ""
            raise _error(path, number, f"{key} = {text!r} has {len(items)} value(s), expected {count}{why}")
        values[key] = np.array([_number(path, number, key, t) for t in items])
        with _at(path, number):
            check_range(key, values[key] if count > 1 else values[key][0], lo, hi, unit=unit)
    return values


# ----------------------------------------------------------------------------- writing


def write_experiment(path: str | os.PathLike, exp: Experiment) -> Path:
    """Writes one experiment as a shape file (see the module docstring and ``FORMAT``) in mm, g,
    N and N mm, creating parent folders; ``read_experiment`` gives it back to 1e-11 relative.

    Raises:
        ValueError: a stacked experiment, weights other than 1 (the file has no weight column),
            or a name with line breaks or surrounding spaces.
        ValueError: what the format does not hold: displacement-driven tendons, more than one
            tube, point or distributed loads, a scene.
    """
    act, load = exp.act, exp.load
    beyond = [
        what
        for what, there in (
            (f"displacement-driven tendons (driven = {act.driven})", act.driven),
            (f"{np.shape(act.insertions)[-1]} tube insertions", np.shape(act.insertions)[-1] > 1),
            (f"{np.size(load.point_s)} point load(s)", np.size(load.point_s)),
            ("a distributed force", np.any(np.asarray(load.distributed_force) != 0)),
            ("a scene", load.scene is not None),
        )
        if there
    ]
    if beyond:
        raise ValueError(
            "the shape file holds the tensions, one tube's insertion and the tip's force and moment; "
            f"this experiment has {', '.join(beyond)} besides"
        )
    path = Path(path)
    s = np.asarray(exp.s, dtype=float)
    if s.ndim != 1:
        raise ValueError(f"write_experiment writes one experiment, got s of shape {s.shape}: index the stack first")
    if not np.all(np.asarray(exp.weight) == 1):
        raise ValueError(f"the shape file has no weight column; weights must all be 1, got {np.asarray(exp.weight)}")
    if exp.name != exp.name.strip() or any(c in exp.name for c in "\r\n"):
        raise ValueError(f"name = {exp.name!r} must be one line without surrounding spaces")
    header = {
        "name": exp.name,
        "tensions_N": exp.act.tensions,
        "insertion_mm": 1000 * np.asarray(act.insertion) if np.size(act.insertions) else 0.0,
        "tip_mass_g": 1000 * np.asarray(exp.tip_mass),
        "tip_force_N": load.tip_force,
        "tip_moment_Nmm": 1000 * np.asarray(load.tip_moment),
    }
    lines = [f"# tdct_jax shape v{VERSION}"]
    lines += [f"# {key}: {value if key == 'name' else _numbers(value, ', ')}" for key, value in header.items()]
    lines.append(",".join(COLUMNS))
    lines += [_numbers(row, ",") for row in 1000 * np.column_stack([s, np.asarray(exp.position, dtype=float)])]
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def _numbers(values, separator: str) -> str:
    """12 significant digits: 1e-11 relative, and 0.1 * 1000 reads 100, not 100.00000000000001."""
    return separator.join(f"{v:.12g}" for v in np.ravel(np.asarray(values, dtype=float)))


# ----------------------------------------------------------------------------- batches


def stack(experiments: Sequence[Experiment]) -> Experiment:
    """One Experiment whose leaves have a leading batch axis (E, ...), for ``jax.vmap``.

    Shapes with fewer points are padded to the longest by repeating their last point with
    weight 0. The stack's ``name`` is "": the names stay with the caller's list, in order.

    Actuations stack when they have the same ``driven`` and tube count, loads when they have the
    same number of point loads (a scene is not stacked).

    Raises:
        ValueError: no experiments, a stacked one among them, different numbers of tendons or
            tubes, different ``driven``, or different numbers of point loads.
    """
    experiments = list(experiments)
    if not experiments:
        raise ValueError("stack needs at least one experiment, got none")
    labels = [f"#{i} {e.name!r}" for i, e in enumerate(experiments)]
    for label, e in zip(labels, experiments, strict=True):
        if not isinstance(e, Experiment) or np.ndim(e.s) != 1:
            raise ValueError(f"stack takes single experiments; {label} is {type(e).__name__} with s of shape {np.shape(e.s)}")
    tendons = [np.shape(e.act.tensions)[0] for e in experiments]
    if len(set(tendons)) > 1:
        counts = ", ".join(f"{label} has {t}" for label, t in zip(labels, tendons, strict=True))
        raise ValueError(f"cannot stack experiments with different numbers of tendons: {counts}")
    tubes = [np.shape(e.act.insertions)[-1] for e in experiments]
    if len(set(tubes)) > 1:
        counts = ", ".join(f"{label} has {t}" for label, t in zip(labels, tubes, strict=True))
        raise ValueError(f"cannot stack experiments with different numbers of tube insertions: {counts}")
    if len({e.act.driven for e in experiments}) > 1:
        kinds = ", ".join(f"{label} has driven = {e.act.driven}" for label, e in zip(labels, experiments, strict=True))
        raise ValueError(f"cannot stack these actuations: all must have the same driven tendons; {kinds}")
    loads = [e.load for e in experiments]
    counts = [load.n_points for load in loads]
    if len(set(counts)) > 1:
        listed = ", ".join(f"{label} has {c}" for label, c in zip(labels, counts, strict=True))
        raise ValueError(f"cannot stack experiments with different numbers of point loads: {listed}")
    n = max(e.n_points for e in experiments)

    def pad(x, fill=None):
        x = np.asarray(x, dtype=float)
        extra = np.repeat(x[-1:], n - len(x), axis=0) if fill is None else np.full(n - len(x), fill)
        return np.concatenate([x, extra])

    def stacked(get):
        return np.stack([np.asarray(get(e), dtype=float) for e in experiments])

    def leaves(items, cls):
        names = [f.name for f in dataclasses.fields(cls) if not f.metadata.get("static") and f.name != "scene"]
        return {k: np.stack([np.asarray(getattr(x, k), dtype=float) for x in items]) for k in names}

    return Experiment(
        s=stacked(lambda e: pad(e.s)),
        position=stacked(lambda e: pad(e.position)),
        act=unchecked(Actuation, driven=experiments[0].act.driven, **leaves([e.act for e in experiments], Actuation)),
        load=unchecked(Loads, scene=None, **leaves(loads, Loads)),
        tip_mass=stacked(lambda e: e.tip_mass),
        weight=stacked(lambda e: pad(e.weight, fill=0.0)),
        name="",
    )
