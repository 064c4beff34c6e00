"""Robot fields by name: the scalars that sweeps vary, calibrations fit and ``--set`` changes.

A robot names ``length`` and the fields of its items by position, ``sections[1].E``,
``tendons[0].offset``, ``tubes[0].E``, ``masses[2].mass``; ``[*]`` stands for every item of its
kind with one shared value (``sections[*].E``: one modulus for the whole body,
``tendons[*].stiffness``: one EA for every tendon), ``[a-b]`` for items a to b
(``tendons[0-2].stiffness``: one EA for a segment's three tendons). Items count from 0 here, as
in Python; tendons are numbered from 1 only where a person reads or types a tendon number (the
CLI's ``--tendons``, sweep specs' column names). SI units: tendon angles and twists in rad; where
a person types them (robot files, ``tdct --set``: ``typed``) in degrees, under the robot file's
key names ``angle_deg`` and ``twist_deg_per_m``.

The paper's robot formerly had names of its own (``E_silicone``, ``tendon_offset``, ...): they
still resolve, to the names in ``PAPER_NAMES``, with a FutureWarning once each.
"""

from __future__ import annotations

import dataclasses
import math
import re
from collections.abc import Mapping

from .checks import deprecated, relabelled_notes

PAPER_NAMES = {
    "outer_diameter": "sections[*].outer_diameter",
    "channel_diameter": "sections[*].inner_diameter",
    "tendon_offset": "tendons[*].offset",
    "tendon_channel_diameter": "sections[*].tendon_channel_diameter",
    "E_silicone": "sections[*].E",
    "nu_silicone": "sections[*].nu",
    "density_silicone": "sections[*].density",
    "tube_outer_diameter": "tubes[0].outer_diameter",
    "tube_inner_diameter": "tubes[0].inner_diameter",
    "E_tube": "tubes[0].E",
    "nu_tube": "tubes[0].nu",
    "density_tube": "tubes[0].density",
}
"""The paper robot's former field names and the names they stand for now."""
LINEAR = ("nu", "angle", "twist", "friction", "guide_spacing", "damping")
"""Field names whose values may be zero or negative; every other field is positive."""
DEGREES = {"angle": "angle_deg", "twist": "twist_deg_per_m"}
"""Fields in rad (rad/m) and the names under which a person types them in degrees (per m)."""
_NAME = re.compile(r"^(\w+)\[(\d+|\*|\d+-\d+)\]\.(\w+)$")


def names(robot) -> tuple[str, ...]:
    """Every scalar field name of ``robot`` (without the ``[*]`` forms)."""
    out = ["length"]
    for kind, cls in robot.ITEMS.items():
        out += [f"{kind}[{i}].{f.name}" for i in range(len(getattr(robot, kind))) for f in dataclasses.fields(cls)]
    return tuple(out)


def resolve(name: str) -> str:
    """The field name ``name`` stands for: itself, or a former paper name's replacement (warning once)."""
    if name in PAPER_NAMES:
        deprecated(f"the field name {name!r}", repr(PAPER_NAMES[name]))
        return PAPER_NAMES[name]
    return name


def _parse(robot, name: str) -> tuple[str, tuple[int, ...], str] | None:
    """(kind, item indices, field) of an item field's name; None for a top-level field. Raises
    ValueError, with the allowed names, for a name the robot does not have."""
    if name == "length":
        return None
    items = robot.ITEMS
    if (m := _NAME.match(resolve(name))) and m[1] in items and m[3] in {f.name for f in dataclasses.fields(items[m[1]])}:
        n = len(getattr(robot, m[1]))
        if m[2] == "*" and n:
            return m[1], tuple(range(n)), m[3]
        lo, _, hi = m[2].partition("-")
        if m[2] != "*" and int(lo) <= int(hi or lo) < n:
            return m[1], tuple(range(int(lo), int(hi or lo) + 1)), m[3]
        raise ValueError(f"{name!r}: the robot has {n} {m[1]} (indices 0 to {n - 1}, or a range a-b with a <= b)")
    kinds = (f"{k}[i, * or a-b].{{{', '.join(f.name for f in dataclasses.fields(c))}}}" for k, c in items.items())
    raise ValueError(f"{name!r} is not a scalar robot field; allowed: {', '.join(['length', *kinds])}")


def typed(name: str, value: float) -> tuple[str, float]:
    """A field as a person types it (``tdct --set``), as (name, SI value): angles in degrees under
    the robot file's names (``tendons[0].angle_deg=90``, ``tendons[*].twist_deg_per_m=360``);
    the radian names are refused there, so 90 never passes as 90 rad."""
    head, _, field = name.rpartition(".")
    for si, deg in DEGREES.items():
        if field == deg:
            return f"{head}.{si}", math.radians(value)
        if field == si:
            unit = "degrees per metre" if si == "twist" else "degrees"
            raise ValueError(f"{name} = {value:g}: angles are typed in {unit} here; write {head}.{deg}={value:g}")
    return name, value


def check(robot, name: str) -> None:
    """Raises ValueError unless ``name`` is one of the robot's fields (``[*]`` forms included)."""
    _parse(robot, name)


def is_linear(name: str) -> bool:
    """Whether the field may be zero or negative (fitted as it is, not in log space)."""
    return name.rsplit(".", 1)[-1] in LINEAR


def get(robot, name: str):
    """The field's value as the robot holds it (a tracer inside jit); for ``[*]``, the first
    item's (``value`` checks that they all agree)."""
    where = _parse(robot, name)
    if where is None:
        return getattr(robot, name)
    kind, index, field = where
    return getattr(getattr(robot, kind)[index[0]], field)


def value(robot, name: str) -> float:
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


def replace(robot, values: Mapping[str, object]):
    """The robot with the named fields set to ``values`` (concrete or traced; concrete values
    are checked as a user-built robot's are)."""
    if not values:
        return robot
    top, groups = {}, {kind: list(getattr(robot, kind)) for kind in robot.ITEMS}
    with relabelled_notes():  # those of tendons[*] as one
        for name, v in values.items():
            where = _parse(robot, name)
            if where is None:
                top[name] = v
                continue
            kind, index, field = where
            for i in index:
                old, new = f"{robot.ITEMS[kind].__name__}.", f"{kind}[{i}]."
                try:
                    with relabelled_notes(lambda note, old=old, new=new: note.replace(old, new, 1)):
                        groups[kind][i] = dataclasses.replace(groups[kind][i], **{field: v})
                except ValueError as e:
                    raise ValueError(str(e).replace(old, new, 1)) from e
    changed = {
        kind: tuple(items)
        for kind, items in groups.items()
        if any(a is not b for a, b in zip(items, getattr(robot, kind), strict=True))
    }
    if "length" in top and "sections" not in changed:  # the last section ends at the length
        last = len(robot.sections) - 1
        changed["sections"] = (*robot.sections[:last], dataclasses.replace(robot.sections[last], end=top["length"]))
    return dataclasses.replace(robot, **top, **changed)
