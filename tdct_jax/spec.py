"""Sweep specs: a TOML file that says what ``tdct sweep`` solves, read into ``tdct.sweep``'s arguments.

A spec, SI units throughout (every key but one table of points is optional)::

    # robot = "robot.toml"    # a robot file beside the spec (it must exist), or a [robot] table; default Table II
    gravity = true            # true (standard, -y), false, or [gx, gy, gz] in m/s^2
    chunk_size = 64           # configurations per compiled call (default: the platform's)
    shapes = false            # also keep every shape / the 3x3 tip compliance
    compliance = false
    warm_start = false        # grid only: solve along the last axis in order

    [base]                    # what every point shares: tensions [N], insertion(s) [m], force [N], moment [N m]
    tensions = [0.0, 0.0, 0.0, 2.0]

    [solver]                  # SolverOptions fields: steps, transition, tendon_model, tol, max_iter
    steps = 16

    [grid]                    # or [batch], columns zipped point by point; names as in tdct.sweep
    insertion = {linspace = [0.0, 0.16, 17]}                 # first, last, count
    tensions = {linspace = [0.0, 10.0, 11], tendons = [1]}   # tendon 1 swept, the others as in [base]
    tip_mass = [0.0, 0.02, 0.05]                             # explicit values; vectors as lists of lists

The robot file is a robot file (``[[sections]]``, ``[[tendons]]``, ...; read by
``tdct.Robot.from_toml``), or the paper's robot with Table II values by name; a [robot] table in
the spec holds the latter (``E_silicone = 1.1e6``, as ``tdct.Robot.paper`` takes them). [base]
takes "tensions" (one per tendon), "insertions" (one per tube; "insertion" for a robot with one
tube), "driven" (the displacement-driven tendons, numbered from 1 as ``tendons = [...]`` is) and
their "displacements" [m], "force", "moment", and point loads "point_s" [m], "point_force",
"point_moment" (lists of [x, y, z]); [grid] or [batch] the names of ``tdct.sweep`` (a linspace of
"displacements" picks driven tendons by number, ``tendons = [1]``), fields quoted as TOML keys:
``"sections[*].E" = [50e9, 60e9]``.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from . import rod
from .checks import check_integer, read_toml
from .description import PAPER, Robot
from .inputs import STANDARD_GRAVITY, Actuation, Loads
from .options import SolverOptions
from .sweep import check_points

OPTIONS = ("chunk_size", "shapes", "compliance", "warm_start", "gravity")
TABLES = ("robot", "base", "solver", "grid", "batch")
BASE = (
    "tensions",
    "insertion",
    "insertions",
    "driven",
    "displacements",
    "force",
    "moment",
    "point_s",
    "point_force",
    "point_moment",
)
"""[base] keys ("insertion": the depth of a robot's one tube)."""
PICKS = {"tensions": "tendons", "displacements": "tendons", "force": "components", "moment": "components"}
"""Vector inputs a linspace can sweep part of: the key that names the entries it sets."""
COMPONENTS = ("x", "y", "z")


def read_spec(path) -> dict:
    """Reads a sweep spec (see the module docstring).

    Returns:
        ``tdct.sweep``'s keyword arguments: robot, act, load, grid or batch, gravity, solver and
        the options the spec sets.

    Raises:
        ValueError: the file cannot be read, or a key is unknown or has a bad value (the message
            names the file, the table, the key, the value and what is allowed), or the points
            would not fit in host memory.
    """
    path = Path(path)
    data = read_toml(path, "sweep spec")
    try:
        return _arguments(data, path.parent)
    except ValueError as e:
        raise ValueError(f"{path}: {e}") from None


def _known(where: str, table: dict, allowed) -> None:
    unknown = sorted(set(table) - set(allowed))
    if unknown:
        raise ValueError(f"{where}unknown key(s) {unknown}; allowed: {list(allowed)}")


def _table(data: dict, name: str) -> dict:
    table = data.get(name, {})
    if not isinstance(table, dict):
        raise ValueError(f"{name} = {table!r} must be a table ([{name}])")
    return table


def _built(where: str, build, **fields):
    """``build(**fields)``, its bad-value errors prefixed with the table they come from."""
    try:
        return build(**fields)
    except ValueError as e:
        raise ValueError(f"[{where}] {e}") from None


def _arguments(data: dict, folder: Path) -> dict:
    _known("", data, OPTIONS + TABLES)
    robot = data.get("robot", {})
    if isinstance(robot, str):
        robot = Robot.from_toml(folder / robot)
    elif isinstance(robot, dict):
        _known("[robot] ", robot, sorted(PAPER))
        robot = _built("robot", Robot.paper, **robot)
    else:
        raise ValueError(
            f'robot = {robot!r} must be a robot file (robot = "robot.toml") or a [robot] table of the paper\'s values'
        )
    base = _table(data, "base")
    zero = (0.0, 0.0, 0.0)
    _known("[base] ", base, BASE)
    if "insertion" in base and "insertions" in base:
        raise ValueError("[base] give insertion (the first and only tube) or insertions (one per tube), not both")
    driven, n = base.get("driven", []), robot.n_tendons
    if not (isinstance(driven, list) and all(i in range(1, n + 1) and not isinstance(i, bool) for i in driven)):
        raise ValueError(f"[base] driven = {driven!r} must list tendons numbered 1 to {n} (1 for the first)")
    act = _built(
        "base",
        Actuation,
        tensions=base.get("tensions", np.zeros(robot.n_tendons)),
        insertions=base.get("insertions", base.get("insertion", np.zeros(robot.n_tubes))),
        displacements=base.get("displacements", np.zeros(len(driven))),
        driven=tuple(i - 1 for i in driven),
    )
    point_loads = {k: base[k] for k in ("point_s", "point_force", "point_moment") if k in base}
    load = _built("base", Loads, tip_force=base.get("force", zero), tip_moment=base.get("moment", zero), **point_loads)
    solver = _table(data, "solver")
    _known("[solver] ", solver, [f.name for f in dataclasses.fields(SolverOptions)])
    args = dict(robot=robot, act=act, load=load, solver=_built("solver", SolverOptions, **solver))
    _built("base", rod.check_arguments, robot=robot, act=act, load=load, solver=args["solver"])  # counts, ranges
    tables = [name for name in ("grid", "batch") if name in data]
    if len(tables) != 1:
        found = "both" if tables else "neither"
        raise ValueError(
            f"give one table of points, [grid] (a product of axes) or [batch] (columns zipped point by point): found {found}"
        )
    kind = tables[0]
    columns = _table(data, kind)
    if not columns:
        raise ValueError(f"[{kind}] is empty: give at least one input name = values")
    tendons = tuple(range(1, robot.n_tendons + 1))
    defaults = dict(
        tensions=(act.tensions, tendons),
        force=(base.get("force", zero), COMPONENTS),
        moment=(base.get("moment", zero), COMPONENTS),
    )
    defaults["displacements"] = (act.displacements, tuple(i + 1 for i in act.driven))
    args[kind] = {name: _values(f"{kind}.{name}", v, *defaults.get(name, (None, None))) for name, v in columns.items()}
    _built(kind, lambda: check_points(robot, act, load, args.get("grid"), args.get("batch")))  # values, host memory
    for name in ("shapes", "compliance", "warm_start"):
        if name in data:
            if not isinstance(data[name], bool):
                raise ValueError(f"{name} = {data[name]!r} must be true or false")
            args[name] = data[name]
    if args.get("warm_start") and kind != "grid":
        raise ValueError("warm_start = true needs a [grid] table: the solves run in order along its last axis")
    if "chunk_size" in data:
        args["chunk_size"] = check_integer("chunk_size", data["chunk_size"])
    args["gravity"] = _gravity(data.get("gravity", True))
    return args


def _gravity(value):
    if value is True:
        return STANDARD_GRAVITY
    if value is False:
        return None
    if isinstance(value, list) and len(value) == 3 and all(_is_number(g) for g in value):
        return tuple(float(g) for g in value)
    raise ValueError(f"gravity = {value!r} must be true (standard, -y), false (none) or [gx, gy, gz] in m/s^2")


def _is_number(x) -> bool:
    return isinstance(x, int | float) and not isinstance(x, bool)


def _values(key: str, value, base, names) -> np.ndarray:
    """One axis or column: explicit values, or {linspace = [first, last, count]} (setting only the
    named entries of a vector input, the rest as in the base configuration; ``names``: its
    entries' names, tendons numbered from 1)."""
    if isinstance(value, list):
        try:
            return np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError):
            raise ValueError(f"{key} = {value!r} must be numbers (vectors as lists of lists of equal length)") from None
    if not isinstance(value, dict) or "linspace" not in value:
        raise ValueError(f"{key} = {value!r} must be a list of values or a table {{linspace = [first, last, count]}}")
    name = key.split(".", 1)[1]
    pick = PICKS.get(name) if names is not None else None  # None: not an input of this robot (check_points says so)
    _known(f"{key}: ", value, ("linspace", pick) if pick else ("linspace",))
    spaced = value["linspace"]
    if not (isinstance(spaced, list) and len(spaced) == 3 and all(_is_number(x) for x in spaced[:2])):
        raise ValueError(f"{key}.linspace = {spaced!r} must be [first, last, count]")
    values = np.linspace(float(spaced[0]), float(spaced[1]), check_integer(f"{key}.linspace count", spaced[2]))
    if pick is None:
        return values
    base = np.asarray(base, dtype=np.float64)
    chosen = value.get(pick)
    if not (isinstance(chosen, list) and chosen and all(c in names and not isinstance(c, bool) for c in chosen)):
        raise ValueError(f"{key}.{pick} = {chosen!r} must list the entries the linspace sets, from {list(names)}")
    vectors = np.tile(base, (len(values), 1))
    vectors[:, [names.index(c) for c in chosen]] = values[:, None]
    return vectors
