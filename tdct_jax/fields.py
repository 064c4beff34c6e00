"""Robot fields by name: the scalars that sweeps vary, calibrations fit and ``--set`` changes.

The paper's ``Robot`` names its scalar fields (``robot.SCALAR_FIELDS``: "E_silicone",
"tendon_offset", ...). A ``GeneralRobot`` names ``length`` and the fields of its items by position,
``sections[1].E``, ``tendons[0].offset``, ``tubes[0].E``, ``masses[2].mass``; ``[*]`` stands for
every item of its kind with one shared value (``sections[*].E``: one modulus for the whole body,
``tendons[*].stiffness``: one EA for every tendon), ``[a-b]`` for items a to b (``tendons[0-2].stiffness``:
one EA for a segment's three tendons). SI units: tendon angles and twists in rad.
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Mapping

from .description import GeneralRobot, PointMass, Section, Tendon, Tube
from .robot import SCALAR_FIELDS, Robot

ITEMS = {"sections": Section, "tendons": Tendon, "tubes": Tube, "masses": PointMass}
"""The item kinds of a GeneralRobot and their classes (every dataclass field is a scalar field)."""
LINEAR = ("nu", "angle", "twist", "nu_silicone", "nu_tube")
"""Field names whose values may be zero or negative; every other field is positive."""
_NAME = re.compile(r"^(\w+)\[(\d+|\*|\d+-\d+)\]\.(\w+)$")


def names(robot: Robot | GeneralRobot) -> tuple[str, ...]:
    """Every scalar field name of ``robot`` (without the ``[*]`` forms)."""
    if isinstance(robot, Robot):
        return SCALAR_FIELDS
    out = ["length"]
    for kind, cls in ITEMS.items():
        out += [f"{kind}[{i}].{f.name}" for i in range(len(getattr(robot, kind))) for f in dataclasses.fields(cls)]
    return tuple(out)


def _parse(robot: Robot | GeneralRobot, name: str) -> tuple[str, tuple[int, ...], str] | None:
    """(kind, item indices, field) of an item field's name; None for a top-level field. Raises
    ValueError, with the allowed names, for a name the robot does not have."""
    if isinstance(robot, Robot) or name == "length":
        if name in names(robot) or name == "length":
            return None
    elif (m := _NAME.match(name)) and m[1] in ITEMS and m[3] in {f.name for f in dataclasses.fields(ITEMS[m[1]])}:
        n = len(getattr(robot, m[1]))
        if m[2] == "*" and n:
            return m[1], tuple(range(n)), m[3]
        lo, _, hi = m[2].partition("-")
        if m[2] != "*" and int(lo) <= int(hi or lo) < n:
            return m[1], tuple(range(int(lo), int(hi or lo) + 1)), m[3]
        raise ValueError(f"{name!r}: the robot has {n} {m[1]} (indices 0 to {n - 1}, or a range a-b with a <= b)")
    kind = "Robot" if isinstance(robot, Robot) else "GeneralRobot"
    if isinstance(robot, Robot):
        allowed = ", ".join(SCALAR_FIELDS)
    else:
        items = (f"{k}[i, * or a-b].{{{', '.join(f.name for f in dataclasses.fields(c))}}}" for k, c in ITEMS.items())
        allowed = ", ".join(["length", *items])
    raise ValueError(f"{name!r} is not a scalar {kind} field; allowed: {allowed}")


def check(robot: Robot | GeneralRobot, name: str) -> None:
    """Raises ValueError unless ``name`` is one of the robot's fields (``[*]`` forms included)."""
    _parse(robot, name)


def is_linear(name: str) -> bool:
    """Whether the field may be zero or negative (fitted as it is, not in log space)."""
    return name.rsplit(".", 1)[-1] in LINEAR


def get(robot: Robot | GeneralRobot, name: str):
    """The field's value as the robot holds it (a tracer inside jit); for ``[*]``, the first
    item's (``value`` checks that they all agree)."""
    where = _parse(robot, name)
    if where is None:
        return getattr(robot, name)
    kind, index, field = where
    return getattr(getattr(robot, kind)[index[0]], field)


def value(robot: Robot | GeneralRobot, name: str) -> float:
    """The field's present value (for ``[*]``: the one value all items share).

    Raises:
        ValueError: an unknown name, an optional field that is not set (None), or items of a
            ``[*]`` name whose values differ.
    """
    where = _parse(robot, name)
    if where is None:
        return float(getattr(robot, name))
    kind, index, field = where
    values = [getattr(getattr(robot, kind)[i], field) for i in index]
    if any(v is None for v in values):
        raise ValueError(f"{name} is not set (None) in this robot: give it a value in the robot first")
    values = [float(v) for v in values]
    if len(set(values)) > 1:
        raise ValueError(f"{name}: the items' values differ ({values}); name one item, e.g. {kind}[{index[0]}].{field}")
    return values[0]


def replace(robot: Robot | GeneralRobot, values: Mapping[str, object]) -> Robot | GeneralRobot:
    """The robot with the named fields set to ``values`` (concrete or traced; concrete values
    are checked as a user-built robot's are)."""
    if not values:
        return robot
    if isinstance(robot, Robot):
        for name in values:
            _parse(robot, name)
        return dataclasses.replace(robot, **values)
    top, groups = {}, {kind: list(getattr(robot, kind)) for kind in ITEMS}
    for name, v in values.items():
        where = _parse(robot, name)
        if where is None:
            top[name] = v
            continue
        kind, index, field = where
        for i in index:
            try:
                groups[kind][i] = dataclasses.replace(groups[kind][i], **{field: v})
            except ValueError as e:
                raise ValueError(str(e).replace(f"{ITEMS[kind].__name__}.", f"{kind}[{i}].", 1)) from e
    changed = {
        kind: tuple(items)
        for kind, items in groups.items()
        if any(a is not b for a, b in zip(items, getattr(robot, kind), strict=True))
    }
    return dataclasses.replace(robot, **top, **changed)
