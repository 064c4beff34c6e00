"""Any tendon-driven continuum robot as data (issue 23): sections, tendons, tubes and point masses,
every number a differentiable leaf, and the TOML robot file that describes one.

``tdct.Robot`` stays the paper's robot with its own field names (calibration, sweeps, the CLI and
the paper studies use them) and its own solver path; ``Robot.to_general()`` gives the same robot as
a ``GeneralRobot``, and ``Robot.from_toml`` returns a ``GeneralRobot`` for a file with
``[[sections]]``. ``tdct.solve`` and ``tdct.compliance`` take either (docs/architecture.md).

Counts (sections, tendons, tubes, masses) are static: they are the lengths of tuples, part of the
tree structure. A tendon anchored at the tip (``end=None``) adds no integration breakpoint; one
with a numeric ``end`` does, at that (traced, differentiable) arc length.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import jax.numpy as jnp
import numpy as np

from .checks import as_array, check_range, is_concrete, read_toml
from .tree import pytree, set_fields

NU_RANGE = (-1.0, 0.5)
"""Poisson ratio: (-1, 0.5], open below."""


def _scalars(obj, units: dict, optional=()):
    """Converts the scalar fields of ``obj`` (a pytree being built) with ``as_array``; None stays
    None for the fields in ``optional``."""
    where = type(obj).__name__
    for name, unit in units.items():
        value = getattr(obj, name)
        if value is None and name in optional:
            continue
        set_fields(obj, **{name: as_array(f"{where}.{name}", value, (), unit=unit)})


@pytree
class Section:
    """One stretch of the body, from the previous section's end (or the base) to ``end``.

    Attributes:
        end: arc length where it ends [m]; the last section's end is the robot's length.
        outer_diameter: body diameter [m].
        E: Young's modulus [Pa]. nu: Poisson ratio (G = E / (2 (1 + nu))). density: [kg/m^3].
        inner_diameter: central channel the tubes slide in [m] (0: none).
        tendon_channel_diameter: diameter of the channel cut for each tendon that passes through
            the section [m] (0: tendons run outside the body, e.g. through spacer disks).
    """

    end: float
    outer_diameter: float
    E: float
    nu: float
    density: float
    inner_diameter: float = 0.0
    tendon_channel_diameter: float = 0.0

    def __post_init__(self):
        units = dict(end=" m", outer_diameter=" m", E=" Pa", nu="", density=" kg/m^3", inner_diameter=" m")
        _scalars(self, units | dict(tendon_channel_diameter=" m"))
        check_range("Section.end", self.end, 0.0, lo_open=True, unit=" m")
        check_range("Section.outer_diameter", self.outer_diameter, 0.0, lo_open=True, unit=" m")
        check_range("Section.E", self.E, 0.0, lo_open=True, unit=" Pa")
        check_range("Section.nu", self.nu, *NU_RANGE, lo_open=True)
        check_range("Section.density", self.density, 0.0, unit=" kg/m^3")
        check_range("Section.tendon_channel_diameter", self.tendon_channel_diameter, 0.0, unit=" m")
        if is_concrete(self.outer_diameter):
            check_range("Section.inner_diameter", self.inner_diameter, 0.0, float(self.outer_diameter), hi_open=True, unit=" m")


@pytree
class Tendon:
    """One tendon: its routing in the body frame, where it is anchored, its limits.

    The tendon passes through the cross-section at r_t(s) = offset (cos a(s), sin a(s), 0) with
    a(s) = angle + twist s (straight without a twist) and carries its tension from
    the base to the anchor, where it pulls the body back along its own tangent.

    Attributes:
        offset: distance from the axis [m].
        angle: angle about +z from body +x at the base [rad] (the file gives ``angle_deg``).
        twist: helical twist rate [rad/m] (the file gives ``twist_deg_per_m``); None (default):
            straight, and the solver skips the helical terms unless some tendon is helical.
        end: arc length of the anchor [m], in (0, L]; None (default): the tip, and no breakpoint.
        max_tension: highest allowed tension [N]; None: unbounded.
        stiffness: axial stiffness EA [N] (displacement control); None: inextensible.
    """

    offset: float
    angle: float
    twist: float | None = None
    end: float | None = None
    max_tension: float | None = None
    stiffness: float | None = None

    def __post_init__(self):
        units = dict(offset=" m", angle=" rad", twist=" rad/m", end=" m", max_tension=" N", stiffness=" N")
        _scalars(self, units, optional=("twist", "end", "max_tension", "stiffness"))
        check_range("Tendon.offset", self.offset, 0.0, unit=" m")
        for name, unit in (("end", " m"), ("max_tension", " N"), ("stiffness", " N")):
            if getattr(self, name) is not None:
                check_range(f"Tendon.{name}", getattr(self, name), 0.0, lo_open=True, unit=unit)

    def position(self, s):
        """r_t(s) and its derivative r_t'(s), body frame [m] and [1], each (..., 3)."""
        twist = 0.0 if self.twist is None else self.twist
        a = self.angle + twist * s
        c, sn = jnp.cos(a), jnp.sin(a)
        r = self.offset * jnp.stack([c, sn, jnp.zeros_like(c)], axis=-1)
        dr = (self.offset * twist) * jnp.stack([-sn, c, jnp.zeros_like(c)], axis=-1)
        return r, dr


@pytree
class Tube:
    """A stiffening tube in the central channel, inserted from the base to a depth the actuation
    sets (``GeneralActuation.insertions``). It slides freely: it adds bending stiffness and weight,
    forbids shear where it is (eqs. 14-16), and nothing axially or in torsion.

    Attributes:
        outer_diameter, inner_diameter: the annulus [m].
        E: Young's modulus [Pa]. nu: Poisson ratio (enters no equation, eq. 16). density: [kg/m^3].
    """

    outer_diameter: float
    inner_diameter: float
    E: float
    nu: float
    density: float

    def __post_init__(self):
        units = dict(outer_diameter=" m", inner_diameter=" m", E=" Pa", nu="", density=" kg/m^3")
        _scalars(self, units)
        check_range("Tube.outer_diameter", self.outer_diameter, 0.0, lo_open=True, unit=" m")
        check_range("Tube.E", self.E, 0.0, lo_open=True, unit=" Pa")
        check_range("Tube.nu", self.nu, *NU_RANGE, lo_open=True)
        check_range("Tube.density", self.density, 0.0, unit=" kg/m^3")
        if is_concrete(self.outer_diameter):
            check_range("Tube.inner_diameter", self.inner_diameter, 0.0, float(self.outer_diameter), hi_open=True, unit=" m")

    @property
    def area(self):
        return jnp.pi / 4 * (self.outer_diameter**2 - self.inner_diameter**2)

    @property
    def second_moment(self):
        return jnp.pi / 64 * (self.outer_diameter**4 - self.inner_diameter**4)


@pytree
class PointMass:
    """A mass attached at arc length ``s`` [m] in [0, L] (a spacer disk, a camera), ``mass`` [kg]:
    a point force m g, a dead load."""

    s: float
    mass: float

    def __post_init__(self):
        _scalars(self, dict(s=" m", mass=" kg"))
        check_range("PointMass.s", self.s, 0.0, unit=" m")
        check_range("PointMass.mass", self.mass, 0.0, unit=" kg")


@pytree
class GeneralRobot:
    """A tendon-driven continuum robot: sections along the arc length, tendons, tubes, point masses.

    Every number is a differentiable leaf; the counts are static. The sections run from the base
    in order, each to its own ``end``; the last must end at ``length`` (the solver uses ``length``).

    Attributes:
        length: L [m].
        sections: tuple of Section, at least one.
        tendons: tuple of Tendon, in actuation order (none is valid).
        tubes: tuple of Tube, outermost first, each inside the one before (none is valid).
        masses: tuple of PointMass.

    Raises:
        ValueError: bad values, naming the field (``sections[1].end``), the value and the range.
    """

    length: float
    sections: tuple
    tendons: tuple = ()
    tubes: tuple = ()
    masses: tuple = ()

    def __post_init__(self):
        set_fields(self, length=as_array("length", self.length, (), unit=" m"))
        check_range("length", self.length, 0.0, lo_open=True, unit=" m")
        for name, cls in (("sections", Section), ("tendons", Tendon), ("tubes", Tube), ("masses", PointMass)):
            items = tuple(getattr(self, name))
            for i, item in enumerate(items):
                if not isinstance(item, cls):
                    raise TypeError(f"{name}[{i}] must be a tdct.{cls.__name__}, got {type(item).__name__}")
            set_fields(self, **{name: items})
        if not self.sections:
            raise ValueError("sections: a robot needs at least one section, got none")
        if is_concrete_tree(self):
            self._check()

    def _check(self):
        L = float(self.length)
        ends = [float(sec.end) for sec in self.sections]
        for i, (a, b) in enumerate(zip([0.0, *ends[:-1]], ends, strict=True)):
            if b <= a:
                raise ValueError(
                    f"sections[{i}].end = {b:g} m must be greater than {a:g} m, where the section starts "
                    f"({'the base' if i == 0 else f'sections[{i - 1}].end'}): sections run from the base in order"
                )
        if not math.isclose(ends[-1], L, rel_tol=1e-12, abs_tol=0.0):
            raise ValueError(
                f"sections[{len(ends) - 1}].end = {ends[-1]:g} m must equal length = {L:g} m: the sections cover [0, length]"
            )
        for i, t in enumerate(self.tendons):
            if t.end is not None:
                check_range(f"tendons[{i}].end", t.end, 0.0, L, lo_open=True, unit=" m (anchors lie in (0, length])")
        for i, m in enumerate(self.masses):
            check_range(f"masses[{i}].s", m.s, 0.0, L, unit=" m (0 to length)")
        for i, tube in enumerate(self.tubes):
            if i > 0:
                inner = float(self.tubes[i - 1].inner_diameter)
                where = f" m (inside tubes[{i - 1}], inner diameter {inner:g} m)"
                check_range(f"tubes[{i}].outer_diameter", tube.outer_diameter, 0.0, inner, lo_open=True, unit=where)
        for j, sec in enumerate(self.sections):
            self._check_section(j, sec)

    def _check_section(self, j: int, sec: Section) -> None:
        """Tubes fit the channel; tendon channels lie in the body and do not overlap; area > 0."""
        D, dc, dt = float(sec.outer_diameter), float(sec.inner_diameter), float(sec.tendon_channel_diameter)
        if self.tubes:
            where = f" m (the channel of sections[{j}], inner_diameter {dc:g} m)"
            check_range("tubes[0].outer_diameter", self.tubes[0].outer_diameter, 0.0, dc, lo_open=True, unit=where)
        start = 0.0 if j == 0 else float(self.sections[j - 1].end)
        through = [i for i, t in enumerate(self.tendons) if t.end is None or float(t.end) > start]
        if dt > 0:
            lo, hi = (dc + dt) / 2, (D - dt) / 2
            for i in through:
                where = f" m (tendon channels of sections[{j}] lie between its central channel and its surface)"
                check_range(f"tendons[{i}].offset", self.tendons[i].offset, lo, hi, unit=where)
            s = np.linspace(start, float(sec.end), 65)
            for a, b in ((a, b) for k, a in enumerate(through) for b in through[k + 1 :]):
                ra, rb = (np.asarray(self.tendons[i].position(s)[0]) for i in (a, b))
                gap = float(np.min(np.linalg.norm(ra - rb, axis=-1)))
                if gap <= dt:
                    raise ValueError(
                        f"tendons[{a}] and tendons[{b}]: their channels in sections[{j}] (tendon_channel_diameter {dt:g} m) "
                        f"overlap: centres {gap:.3g} m apart, more than {dt:g} m needed"
                    )
        area = float(section_area(sec, len(through)))
        if area <= 0:
            raise ValueError(f"sections[{j}]: cross-section area {area:g} m^2 is not positive: channels larger than the body")

    # ---- reading a robot file -----------------------------------------------------------------

    @classmethod
    def from_toml(cls, path: str | Path) -> GeneralRobot:
        """Reads a robot file (docs/robot-file.md), SI units.

        Raises:
            ValueError: the file cannot be read, has unknown or missing keys, or bad values; the
                message names the file, the field, the value and the allowed range.
        """
        path = Path(path)
        return cls.from_table(read_toml(path, "robot file"), path)

    @classmethod
    def from_table(cls, data: dict, path) -> GeneralRobot:
        """``from_dict`` of a robot file's table, its errors prefixed with the file's path."""
        try:
            return cls.from_dict(data)
        except (ValueError, TypeError) as e:
            raise ValueError(f"robot file {path}: {e}") from e

    @classmethod
    def from_dict(cls, data: dict) -> GeneralRobot:
        """A robot from the parsed robot file (the TOML's tables as dicts); see ``from_toml``."""
        # a [rig] table (how the robot sits on its test rig) is read by ``rig.Rig.from_toml``
        _keys("the file", data, required=("length", "sections"), optional=("tendons", "tubes", "masses", "rig"))
        length = data["length"]
        sections, previous = [], 0.0
        for i, raw in enumerate(_tables("sections", data)):
            _keys(f"sections[{i}]", raw, required=SECTION_KEYS, optional=("start", "inner_diameter", "tendon_channel_diameter"))
            if "start" in raw and not math.isclose(float(raw["start"]), previous, rel_tol=1e-12, abs_tol=1e-15):
                what = "a gap" if float(raw["start"]) > previous else "an overlap"
                raise ValueError(
                    f"sections[{i}].start = {raw['start']:g} m leaves {what}: it must equal {previous:g} m "
                    f"({'the base' if i == 0 else f'sections[{i - 1}].end'})"
                )
            previous = float(raw["end"]) if _number(f"sections[{i}].end", raw["end"]) else previous
            sections.append(_build(Section, f"sections[{i}]", {k: v for k, v in raw.items() if k != "start"}))
        tendons = []
        for i, raw in enumerate(_tables("tendons", data)):
            _keys(f"tendons[{i}]", raw, required=("offset", "angle_deg"), optional=TENDON_OPTIONAL)
            kw = dict(offset=raw["offset"], angle=_radians(f"tendons[{i}].angle_deg", raw["angle_deg"]))
            if "twist_deg_per_m" in raw:
                kw["twist"] = _radians(f"tendons[{i}].twist_deg_per_m", raw["twist_deg_per_m"])
            kw |= {k: raw[k] for k in ("max_tension", "stiffness") if k in raw}
            if "end" in raw:
                _number(f"tendons[{i}].end", raw["end"])
                # an anchor at the tip is the default: no breakpoint
                if not (_number("length", length) and math.isclose(float(raw["end"]), float(length), rel_tol=1e-12)):
                    kw["end"] = raw["end"]
            tendons.append(_build(Tendon, f"tendons[{i}]", kw))
        tubes = []
        for i, raw in enumerate(_tables("tubes", data)):
            _keys(f"tubes[{i}]", raw, required=("outer_diameter", "inner_diameter", "E", "nu", "density"))
            tubes.append(_build(Tube, f"tubes[{i}]", raw))
        masses = []
        for i, raw in enumerate(_tables("masses", data)):
            _keys(f"masses[{i}]", raw, required=("s", "mass"))
            masses.append(_build(PointMass, f"masses[{i}]", raw))
        return cls(length, tuple(sections), tuple(tendons), tuple(tubes), tuple(masses))

    def to_toml(self) -> str:
        """The robot as a robot file's text (``from_toml`` reads it back, angles to the round-off of
        their conversion to degrees)."""
        lines = [f"length = {float(self.length)!r}"]
        for kind, table in (
            ("sections", self.sections),
            ("tendons", self.tendons),
            ("tubes", self.tubes),
            ("masses", self.masses),
        ):
            for item in table:
                lines += ["", f"[[{kind}]]"]
                for f in dataclasses.fields(item):
                    v = getattr(item, f.name)
                    if v is None:
                        continue
                    if kind == "tendons" and f.name in ("angle", "twist"):
                        name = "angle_deg" if f.name == "angle" else "twist_deg_per_m"
                        lines.append(f"{name} = {math.degrees(float(v))!r}")
                    else:
                        lines.append(f"{f.name} = {float(v)!r}")
        return "\n".join(lines) + "\n"

    # ---- derived quantities -------------------------------------------------------------------

    @property
    def n_tendons(self) -> int:
        return len(self.tendons)

    @property
    def n_tubes(self) -> int:
        return len(self.tubes)

    def calibration_notes(self, tensions, tip_force) -> list[str]:
        """None: a general robot carries no calibrated ranges (``Robot`` does)."""
        return []

    def warn_outside_calibration(self, tensions, tip_force) -> None:
        """Nothing to warn about (see ``calibration_notes``)."""


SECTION_KEYS = ("end", "outer_diameter", "E", "nu", "density")
TENDON_OPTIONAL = ("end", "twist_deg_per_m", "max_tension", "stiffness")


def is_concrete_tree(obj) -> bool:
    """Every leaf of a description is a concrete value (not a tracer)."""
    import jax

    return all(is_concrete(x) for x in jax.tree.leaves(obj))


def channelled_area(outer, inner, dt, n_channels):
    """Area [m^2] of a disc of diameter ``outer`` less a central channel ``inner`` and
    ``n_channels`` tendon channels of diameter ``dt`` [m]."""
    return jnp.pi / 4 * (outer**2 - inner**2 - n_channels * dt**2)


def channelled_second_moments(outer, inner, dt, r, through):
    """(I_x, I_y) [m^4] of the same disc, the tendon channels at body offsets r (n_t, 3) [m] that
    ``through`` (n_t,) marks (1.0: cut here) removed by the parallel-axis theorem."""
    disc = jnp.pi / 64 * (outer**4 - inner**4)
    own, hole = jnp.pi / 64 * dt**4, jnp.pi / 4 * dt**2
    I_x = disc - jnp.sum(through * (own + hole * r[:, 1] ** 2))
    I_y = disc - jnp.sum(through * (own + hole * r[:, 0] ** 2))
    return I_x, I_y


def section_area(sec: Section, n_channels):
    """Area of a section's body [m^2]: outer disc minus central channel and ``n_channels`` tendon
    channels (the tendons that pass through it)."""
    return channelled_area(sec.outer_diameter, sec.inner_diameter, sec.tendon_channel_diameter, n_channels)


def _keys(where: str, table, required=(), optional=()) -> None:
    if not isinstance(table, dict):
        raise ValueError(f"{where} must be a table of keys, got {table!r}")
    allowed = (*required, *optional)
    unknown = sorted(set(table) - set(allowed))
    if unknown:
        raise ValueError(f"{where}: unknown key(s) {unknown}; allowed: {list(allowed)}")
    missing = [k for k in required if k not in table]
    if missing:
        raise ValueError(f"{where}: missing key(s) {missing}")


def _tables(name: str, data: dict) -> list:
    tables = data.get(name, [])
    if not isinstance(tables, list):
        raise ValueError(f"{name} must be an array of tables ([[{name}]]), got {tables!r}")
    return tables


def _number(name: str, x) -> bool:
    if isinstance(x, bool) or not isinstance(x, (int, float)):
        raise ValueError(f"{name} must be a number, got {x!r}")
    return True


def _radians(name: str, x) -> float:
    _number(name, x)
    return math.radians(x)


def _build(cls, where: str, kw: dict):
    for k, v in kw.items():
        _number(f"{where}.{k}", v)
    try:
        return cls(**kw)
    except ValueError as e:
        raise ValueError(str(e).replace(f"{cls.__name__}.", f"{where}.", 1)) from e


def from_paper(robot) -> GeneralRobot:
    """The paper's ``tdct.Robot`` as a GeneralRobot: one silicone section with the tube channel and
    the tendon channels, its tendons anchored at the tip, its Nitinol tube (depth: the actuation's
    insertion). Solved by ``tdct.solve``, it gives ``Robot``'s results (within 1e-12 relative)."""
    section = Section(
        end=robot.length,
        outer_diameter=robot.outer_diameter,
        E=robot.E_silicone,
        nu=robot.nu_silicone,
        density=robot.density_silicone,
        inner_diameter=robot.channel_diameter,
        tendon_channel_diameter=robot.tendon_channel_diameter,
    )
    angles = jnp.asarray(robot.tendon_angles) if not is_concrete(robot.tendon_angles) else np.asarray(robot.tendon_angles)
    tendons = tuple(Tendon(offset=robot.tendon_offset, angle=angles[i]) for i in range(robot.n_tendons))
    tube = Tube(robot.tube_outer_diameter, robot.tube_inner_diameter, robot.E_tube, robot.nu_tube, robot.density_tube)
    return GeneralRobot(robot.length, (section,), tendons, (tube,))


ROBOTS = Path(__file__).parent / "robots"
"""The example robot files shipped with the package: paper.toml, two_segment.toml."""
