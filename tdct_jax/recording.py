"""Recorded experiments: what was commanded (tendon displacements, tensions, tube insertions) and
what was measured (tip positions), one sample a CSV row, read and checked into SI units.

A recording is a plain UTF-8 CSV file as a lab's logger writes it: a first line naming the
columns, then one sample per line, in the order recorded::

    timestamp,pattern_label,servo_4_mm,servo_3_mm,servo_9_mm,tip_x,tip_y,tip_z
    1778538602.52,rep1_seg1_dir0,-0.06,-0.03,-0.02,-2.09,8.17,187.96
    1778538603.17,rep1_seg1_dir0,0.69,-0.67,-0.60,-2.24,9.73,188.10

``read_recording`` is told which columns play which role: ``displacements`` (commanded tendon
displacements, one column per tendon in tendon order, positive pulls), ``tensions`` (one per
tendon), ``insertions`` (one per tube), ``tip`` (exactly three: x, y, z of the measured tip in
the measurement frame), ``time`` and a text ``label`` (the motion pattern a sample belongs to).
Other columns are ignored. Blank lines and lines starting with ``#`` are skipped.

Every column read must state its unit: by the end of its name (``_mm``, ``_m``, ``_um``, ``_N``,
``_deg``, ``_rad``, ``_s``: ``servo_4_mm``) or in ``units`` (``{"tip_x": "mm"}``). Lengths may be
in m, mm or um, tensions in N, time in s. A ``Recording`` holds SI units (m, N, s).

A data set is a small TOML description next to its CSV files (paths relative to it)::

    robot = "robot.toml"           # the robot file (optional; read for its length only)
    train = "train.csv"            # required
    validation = "val.csv"         # optional; must have the same columns as train
    label = "pattern_label"        # optional
    time = "timestamp"             # optional
    displacements = ["servo_4_mm", "servo_3_mm", "servo_9_mm"]   # tendon order
    tip = ["tip_x", "tip_y", "tip_z"]
    # tensions = [...], insertions = [...] likewise

    [units]                        # for columns whose names do not carry their unit
    timestamp = "s"
    tip_x = "mm"

Every error is a ValueError whose message starts with ``path:line:`` (``path:`` for the whole
file) and names the column, the value and what is allowed. Where the data set names a robot file,
tips that lie on average nearer the base than ``checks.TARGET_REACH`` robot lengths in a recording
in mm (metres labelled mm), or farther in one in m, get a UnitWarning.
"""

from __future__ import annotations

import csv
import dataclasses
import difflib
import io
import math
import os
import re
import warnings
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from .checks import UnitWarning, reach_note, read_toml, warn_user
from .data import _error, _number, _read_text
from .description import Robot

UNITS = {"m": 1.0, "mm": 1e3, "um": 1e6, "N": 1.0, "s": 1.0, "deg": 180 / math.pi, "rad": 1.0}
"""Each unit a column may state, and how many of it make one SI unit (m, N, s, rad): a value in mm
is divided by 1000, which is exact to the last bit where multiplying by 1e-3 is not."""
ROLES = {
    "time": ("s",),
    "displacements": ("m", "mm", "um"),
    "tensions": ("N",),
    "insertions": ("m", "mm", "um"),
    "tip": ("m", "mm", "um"),
}
"""The roles of numeric columns, in the order ``Recording.columns`` lists them, and the units each allows."""
SUFFIX = re.compile(r"_(mm|um|m|N|deg|rad|s)$")
PER_SAMPLE = ("labels", "time", "displacements", "tensions", "insertions", "tip", "lines")
DATASET_KEYS = (
    "robot",
    "train",
    "validation",
    "pulls",
    "label",
    "time",
    "displacements",
    "tensions",
    "insertions",
    "tip",
    "units",
)


@dataclasses.dataclass(frozen=True, eq=False)
class Recording:
    """One recorded file, SI units, samples in recorded order.

    Attributes:
        name: the file name without its extension.
        path: the file.
        labels: the motion-pattern label of each sample, shape (n,) str ('' when the file has none).
        time: the time of each sample [s], shape (n,), or None.
        displacements: commanded tendon displacements [m], shape (n, k), columns in the order
            given (tendon order), or None.
        tensions: tendon tensions [N], shape (n, k_t), or None.
        insertions: tube insertions [m], shape (n, n_tubes), or None.
        tip: measured tip positions [m] in the measurement frame, shape (n, 3), or None.
        columns: the columns read as (role, name, unit) triples, role "label" with unit "" first.
        lines: the 1-based line in the file of each sample, shape (n,) int.
        header: every column name in the file, in file order.
    """

    name: str
    path: Path
    labels: np.ndarray
    time: np.ndarray | None
    displacements: np.ndarray | None
    tensions: np.ndarray | None
    insertions: np.ndarray | None
    tip: np.ndarray | None
    columns: tuple
    lines: np.ndarray
    header: tuple = ()

    def __len__(self) -> int:
        return len(self.lines)

    def subset(self, index) -> Recording:
        """The samples at a numpy ``index`` (slice, int array, bool mask, int), in that order."""
        rows = np.atleast_1d(np.arange(len(self))[index])
        picked = {k: None if getattr(self, k) is None else getattr(self, k)[rows] for k in PER_SAMPLE}
        return dataclasses.replace(self, **picked)

    def patterns(self) -> np.ndarray:
        """Each sample's motion pattern, shape (n,) str: its label without a leading ``rep<digits>_``
        and a trailing ``_hold`` ('rep1_all3_same_dir0_hold' -> 'all3_same_dir0')."""
        return np.asarray([re.sub(r"_hold$", "", re.sub(r"^rep\d+_", "", t)) for t in self.labels], dtype=str)


@dataclasses.dataclass(frozen=True, eq=False)
class Dataset:
    """A data set's recordings, as its TOML description names them (module docstring).

    Attributes:
        train: the recording to fit on.
        validation: the held-out recording, with the same columns, or None.
        pulls: a recording of single-tendon pulls (each tendon pulled alone, the others let go),
            with the same columns, or None: the geometry step of a rig calibration
            (``calibrate_rig.identify_geometry``).
        robot: the robot file the description names, relative to it, resolved (``read_dataset`` reads
            only its length), or None.
        description: the TOML description.
        roles: ``read_recording``'s keyword arguments from the description (``read`` uses them).
    """

    train: Recording
    validation: Recording | None
    robot: Path | None
    description: Path
    roles: dict = dataclasses.field(default_factory=dict)
    pulls: Recording | None = None

    def read(self, path: str | os.PathLike) -> Recording:
        """Another recording with the description's columns and units, ``path`` relative to the description."""
        return read_recording(self.description.parent / path, **self.roles)


# ----------------------------------------------------------------------------- reading


def read_recording(
    path: str | os.PathLike,
    *,
    displacements=(),
    tensions=(),
    insertions=(),
    tip=(),
    label: str | None = None,
    time: str | None = None,
    units: Mapping[str, str] | None = None,
) -> Recording:
    """Reads one recording (format: module docstring) into SI units.

    Args:
        path: the CSV file.
        displacements: the columns of commanded tendon displacements, in tendon order.
        tensions: the columns of tendon tensions, in tendon order.
        insertions: the columns of tube insertions, one per tube.
        tip: the three columns of the measured tip position (x, y, z).
        label: the column of motion-pattern labels (text), if any.
        time: the column of sample times, if any.
        units: the unit of each column whose name does not end in it, e.g. ``{"tip_x": "mm"}``.

    Raises:
        ValueError: the file cannot be read, lacks a column, a column's unit is not stated or does
            not fit its role, a cell is not a finite number, or there are no samples; the message
            starts with ``path:line:`` and names the column, the value and what is allowed.
    """
    path = Path(path)
    roles = _roles(path, displacements=displacements, tensions=tensions, insertions=insertions, tip=tip)
    return _recording(path, _table(path), roles, label, time, _units(path, units))


def read_dataset(path: str | os.PathLike) -> Dataset:
    """Reads a data set's TOML description (module docstring) and the recordings it names.

    Raises:
        ValueError: the description cannot be read, has an unknown key or a value of the wrong
            type, or lacks ``train``; a recording is bad (``read_recording``); or the validation file's
            columns differ from the training file's (both files and the differing columns named).
    """
    path = Path(path)
    spec = read_toml(path, "dataset description")
    for key, value in spec.items():
        if key not in DATASET_KEYS:
            close = difflib.get_close_matches(key, DATASET_KEYS, n=1)
            guess = f" (did you mean {close[0]!r}?)" if close else ""
            raise _error(path, 0, f"unknown key {key!r}{guess}; allowed keys: {', '.join(DATASET_KEYS)}")
        if key in ROLES and key != "time":
            if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
                raise _error(path, 0, f'{key} = {value!r} must be a list of column names, e.g. {key} = ["a_mm", "b_mm"]')
        elif key == "units":
            if not isinstance(value, dict):
                raise _error(path, 0, f"units = {value!r} must be a table: a line '[units]', then lines such as tip_x = \"mm\"")
        elif not isinstance(value, str):
            raise _error(path, 0, f"{key} = {value!r} must be a string (a file or column name in quotes)")
    if "train" not in spec:
        raise _error(path, 0, 'missing key train: the training recording, e.g. train = "train.csv"')
    roles = {k: spec[k] for k in ("displacements", "tensions", "insertions", "tip", "label", "time", "units") if k in spec}
    fields = {k: v for k, v in roles.items() if k not in ("label", "time", "units")}
    role_columns = _roles(path, **fields)
    named = [c for k in ROLES if k != "time" for c in roles.get(k, ())] + [roles[k] for k in ("label", "time") if k in roles]
    strays = [c for c in roles.get("units", {}) if c not in named]
    if strays:
        raise _error(path, 0, f"[units] names column(s) {strays} that the description does not read; columns read: {named}")
    units = _units(path, roles.get("units"))

    def recording(p, table):
        return _recording(p, table, role_columns, roles.get("label"), roles.get("time"), units)

    folder = path.parent
    train_path = folder / spec["train"]
    train = _table(train_path)
    train_recording = recording(train_path, train)  # a column the description names but a file lacks: that file's error

    def beside_train(key: str) -> Recording | None:
        """The recording under ``key`` (optional), with the training file's columns."""
        if key not in spec:
            return None
        other_path = folder / spec[key]
        other = _table(other_path)
        read = recording(other_path, other)
        _check_same_columns((train_path, train), (other_path, other), key)
        return read

    dataset = Dataset(
        train=train_recording,
        validation=beside_train("validation"),
        robot=folder / spec["robot"] if "robot" in spec else None,
        description=path,
        roles=roles,
        pulls=beside_train("pulls"),
    )
    _check_tips(dataset)
    return dataset


def _check_tips(dataset: Dataset) -> None:
    """A UnitWarning (``checks.reach_note``) for each recording whose tips lie, on average, too near
    the base or too far from it for the robot's length, where the robot file can be read."""
    if dataset.robot is None:
        return
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # its own notes come where it is used
            length = float(Robot.from_toml(dataset.robot).length)
    except ValueError:
        return
    for rec in (dataset.train, dataset.validation, dataset.pulls):
        if rec is None or rec.tip is None:
            continue
        tip = [(name, unit) for role, name, unit in rec.columns if role == "tip"]
        units = {unit for _, unit in tip}
        if units in ({"m"}, {"mm"}):
            unit = units.pop()
            name = f"{rec.path}: the tips ({', '.join(n for n, _ in tip)} in {unit}) on average"
            note = reach_note(name, np.linalg.norm(rec.tip, axis=-1), length, typed_in_mm=unit == "mm", mean=True)
            if note:
                warn_user(note, UnitWarning)


def check_tendons(rec: Recording, n_tendons: int) -> None:
    """Checks that ``rec`` has one displacement column and one tension column (where it has
    either) per tendon of a robot with ``n_tendons`` tendons.

    Raises:
        ValueError: naming the file, the columns and the robot's tendon count.
    """
    for role in ("displacements", "tensions"):
        values = getattr(rec, role)
        if values is not None and values.shape[1] != n_tendons:
            names = [name for r, name, _ in rec.columns if r == role]
            raise _error(
                rec.path,
                0,
                f"{len(names)} {role} column(s) {names}, but the robot has {n_tendons} tendons:"
                " name one column per tendon, in the robot file's tendon order",
            )


# ----------------------------------------------------------------------------- helpers


@dataclasses.dataclass(frozen=True)
class _Table:
    """A CSV file's column line (its line number and the names) and its data rows (line, fields)."""

    line: int
    names: list
    rows: list


def _table(path: Path, what: str = "recording") -> _Table:
    """A CSV file's columns and rows (``what`` it is, for the message when it cannot be read):
    blank lines and lines starting with '#' skipped; duplicate column names, rows with another
    field count, an empty file and no data rows refused with ``path:line``."""
    text = _read_text(path, what)
    reader = csv.reader(io.StringIO(text))
    line, names, rows = 0, None, []
    try:
        for fields in reader:
            if not fields or (len(fields) == 1 and not fields[0].strip()) or fields[0].lstrip().startswith("#"):
                continue
            if names is None:
                line, names = reader.line_num, [f.strip() for f in fields]
                twice = sorted({n for n in names if names.count(n) > 1})
                if twice:
                    raise _error(path, line, f"duplicate column name(s) {twice} in the column line {names}; each name once")
            elif len(fields) != len(names):
                raise _error(
                    path,
                    reader.line_num,
                    f"row has {len(fields)} fields, the column line (line {line}) has {len(names)} {names}",
                )
            else:
                rows.append((reader.line_num, fields))
    except csv.Error as e:
        raise _error(path, reader.line_num, f"not a CSV file: {e}") from None
    if names is None:
        raise _error(path, 0, "empty file: no column line (a first line naming the columns, separated by commas)")
    if not rows:
        raise _error(path, line, f"no samples: the column line {names} is followed by no data rows")
    return _Table(line, names, rows)


def _roles(path: Path, **given) -> list[tuple[str, str]]:
    """(role, column) pairs of the numeric roles but time, in ROLES order, checked."""
    pairs = []
    for role in ROLES:
        if role == "time":
            continue
        names = given.get(role, ())
        names = [names] if isinstance(names, str) else list(names)
        if not all(isinstance(n, str) for n in names):
            raise TypeError(f"{role} must be column names (str), got {names!r}")
        if role == "tip" and len(names) not in (0, 3):
            raise _error(path, 0, f"tip needs 3 columns (x, y, z of the measured tip), got {len(names)}: {names}")
        pairs += [(role, n) for n in names]
    if not pairs:
        raise _error(path, 0, "no columns to read: name the columns of displacements, tensions, insertions or tip")
    return pairs


def _units(path: Path, units) -> dict:
    units = {} if units is None else dict(units)
    for column, unit in units.items():
        if unit not in UNITS:
            raise _error(path, 0, f"unknown unit {unit!r} for column {column!r}; known units: {', '.join(UNITS)}")
    return units


def _recording(path: Path, table: _Table, roles: list, label: str | None, time: str | None, units: dict) -> Recording:
    """The recording of ``table``: the columns of ``roles`` (and ``label``, ``time``) checked and in SI."""
    used = ([("time", time)] if time is not None else []) + roles
    named = ([label] if label is not None else []) + [n for _, n in used]
    twice = sorted({n for n in named if named.count(n) > 1})
    if twice:
        raise _error(path, 0, f"column(s) {twice} given for more than one role; each column has one role")
    missing = [n for n in named if n not in table.names]
    if missing:
        hint = (
            "; separate the columns by commas"
            if len(table.names) == 1 and (";" in table.names[0] or "\t" in table.names[0])
            else ""
        )
        raise _error(path, table.line, f"missing column(s) {missing}; columns present: {table.names}{hint}")
    strays = [c for c in units if c not in named]
    if strays:
        raise _error(path, 0, f"units given for column(s) {strays} that are not read; columns read: {named}")
    lines = np.array([line for line, _ in table.rows], dtype=int)
    values, columns = {}, [("label", label, "")] if label is not None else []
    for role, name in used:
        unit = _unit(path, table.line, role, name, units.get(name))
        i = table.names.index(name)
        column = np.array([_number(path, line, name, fields[i]) for line, fields in table.rows]) / UNITS[unit]
        values.setdefault(role, []).append(column)
        columns.append((role, name, unit))
    if label is None:
        labels = np.full(len(lines), "", dtype=str)
    else:
        labels = np.asarray([fields[table.names.index(label)].strip() for _, fields in table.rows], dtype=str)
    arrays = {role: np.stack(values[role], axis=1) if role in values else None for role in ROLES}
    return Recording(
        name=path.stem,
        path=path,
        labels=labels,
        time=None if arrays["time"] is None else arrays["time"][:, 0],
        displacements=arrays["displacements"],
        tensions=arrays["tensions"],
        insertions=arrays["insertions"],
        tip=arrays["tip"],
        columns=tuple(columns),
        lines=lines,
        header=tuple(table.names),
    )


def _unit(path: Path, line: int, role: str, name: str, stated: str | None) -> str:
    """The unit of column ``name``: ``stated`` (from ``units``) or its name's suffix, fit for ``role``."""
    allowed, example = ", ".join(ROLES[role]), "mm" if "mm" in ROLES[role] else ROLES[role][0]
    suffix = SUFFIX.search(name)
    if stated is not None and suffix and suffix[1] != stated:
        raise _error(
            path, line, f"column {name!r} ({role}) is in {suffix[1]} by its name but units gives {stated!r}; give one unit"
        )
    unit = stated or (suffix[1] if suffix else None)
    if unit is None:
        raise _error(
            path,
            line,
            f"column {name!r} ({role}): units not stated; end its name with the unit (e.g. {name}_{example}) "
            f'or give it in units (e.g. {name} = "{example}"); allowed for {role}: {allowed}',
        )
    if unit not in ROLES[role]:
        raise _error(path, line, f"column {name!r} is in {unit}, which does not fit {role}; allowed for {role}: {allowed}")
    return unit


def _check_same_columns(train: tuple, other: tuple, what: str = "validation") -> None:
    (train_path, a), (val_path, b) = train, other
    only_train = [n for n in a.names if n not in b.names]
    only_val = [n for n in b.names if n not in a.names]
    if only_train or only_val:
        raise _error(
            val_path,
            b.line,
            f"the {what} file's columns differ from the training file {train_path}'s: only in {train_path.name}: "
            f"{only_train}; only in {val_path.name}: {only_val}; both files must have the same columns",
        )
