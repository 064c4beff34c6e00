"""Any tendon-driven continuum robot as data: sections, tendons, tubes and point masses, every
number a differentiable leaf, and the TOML robot file that describes one. The paper's robot is a
preset of this one description (``Robot.paper()``, presets.py; ``tdct_jax/robots/paper.toml``).

Counts (sections, tendons, tubes, masses) are static: they are the lengths of tuples, part of the
tree structure. A tendon anchored at the tip (``end=None``) adds no integration breakpoint; one
with a numeric ``end`` does, at that (traced, differentiable) arc length.
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from pathlib import Path
from typing import ClassVar

import jax.numpy as jnp
import numpy as np

from . import fields
from .checks import (
    UnitWarning,
    array_module,
    as_array,
    check_range,
    deprecated,
    fmt,
    interval,
    is_concrete,
    read_toml,
    relabelled_notes,
    size_note,
    warn_implausible,
    warn_user,
)
from .tree import pytree, set_fields, static

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
        friction: Coulomb coefficient mu between the tendons and their guides in this section
            (capstan friction with memory, rod.py "Tendon friction"); None (default): frictionless,
            and the solver skips the friction terms unless some section has a coefficient.
        guide_spacing: arc length between the guides [m]: spacer disks; 0 (default): a continuous
            channel, a guide at every RK4 node.
        damping: Kelvin-Voigt retardation time [s] of the section's material (with its tubes):
            the viscous stresses are ``damping`` times the elastic ones of the strain rates
            (dynamics.py); 0 (default): elastic. Statics do not see it.
    """

    end: float
    outer_diameter: float
    E: float
    nu: float
    density: float
    inner_diameter: float = 0.0
    tendon_channel_diameter: float = 0.0
    friction: float | None = None
    guide_spacing: float = 0.0
    damping: float = 0.0

    def __post_init__(self):
        units = dict(end=" m", outer_diameter=" m", E=" Pa", nu="", density=" kg/m^3", inner_diameter=" m")
        optional = dict(tendon_channel_diameter=" m", friction="", guide_spacing=" m", damping=" s")
        _scalars(self, units | optional, optional=("friction",))
        if self.friction is not None:
            check_range("Section.friction", self.friction, 0.0)
        check_range("Section.guide_spacing", self.guide_spacing, 0.0, unit=" m")
        check_range("Section.damping", self.damping, 0.0, unit=" s")
        check_range("Section.end", self.end, 0.0, lo_open=True, unit=" m")
        check_range("Section.outer_diameter", self.outer_diameter, 0.0, lo_open=True, unit=" m")
        check_range("Section.E", self.E, 0.0, lo_open=True, unit=" Pa")
        check_range("Section.nu", self.nu, *NU_RANGE, lo_open=True)
        check_range("Section.density", self.density, 0.0, unit=" kg/m^3")
        check_range("Section.tendon_channel_diameter", self.tendon_channel_diameter, 0.0, unit=" m")
        if is_concrete(self.outer_diameter):
            check_range("Section.inner_diameter", self.inner_diameter, 0.0, float(self.outer_diameter), hi_open=True, unit=" m")
        warn_implausible("Section", self, "Section.")


@pytree
class Tendon:
    """One tendon: its routing in the body frame, where it is anchored, its limits.

    The tendon passes through the cross-section at r_t(s) = offset (cos a(s), sin a(s), 0) with
    a(s) = angle + twist s (straight without a twist) and carries its tension from
    the base to the anchor, where it pulls the body back along its own tangent.

    Attributes:
        offset: distance from the axis [m].
        angle: angle about +z from body +x at the base [rad] (the robot file and the command line
            take degrees, ``angle_deg``); beyond 2 pi it gets a UnitWarning (degrees given?).
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
        warn_implausible("Tendon", self, "Tendon.")  # an angle beyond a full turn: degrees given?

    def position(self, s):
        """r_t(s) and its derivative r_t'(s), body frame [m] and [1], each (..., 3)."""
        twist = 0.0 if self.twist is None else self.twist
        xp = array_module(self.offset, self.angle, twist, s)  # numpy for concrete values: no JAX backend started
        a = self.angle + twist * s
        c, sn = xp.cos(a), xp.sin(a)
        r = self.offset * xp.stack([c, sn, xp.zeros_like(c)], axis=-1)
        dr = (self.offset * twist) * xp.stack([-sn, c, xp.zeros_like(c)], axis=-1)
        return r, dr


@pytree
class Tube:
    """A stiffening tube in the central channel, inserted from the base to a depth the actuation
    sets (``Actuation.insertions``). It slides freely: it adds bending stiffness and weight,
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
        warn_implausible("Tube", self, "Tube.")

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
        warn_implausible("PointMass", self, "PointMass.")


class _PaperByDefault(type):
    """``Robot()`` or ``Robot(E_silicone=...)`` (no sections: the former paper robot class) gives
    ``Robot.paper(...)``, with a FutureWarning once."""

    def __call__(cls, *args, **kwargs):
        if not args and "sections" not in kwargs:
            deprecated("tdct.Robot() for the paper's robot", "tdct.Robot.paper()")
            return cls.paper(**kwargs)
        return super().__call__(*args, **kwargs)


class CalibrationWarning(UserWarning):
    """Inputs outside the range a robot was calibrated over: a note, not an error."""


@pytree
class Robot(metaclass=_PaperByDefault):
    """A tendon-driven continuum robot: sections along the arc length, tendons, tubes, point masses.

    Every number is a differentiable leaf; the counts are static. The sections run from the base
    in order, each to its own ``end``; the last must end at ``length`` (the solver uses ``length``).
    ``Robot.paper()`` is the paper's robot (Table II); ``Robot.from_toml`` reads a robot file;
    ``robot.replace({"sections[0].E": 1e6})`` changes fields by name (fields.py), traced values
    included, so ``jax.grad`` reaches them.

    Attributes:
        length: L [m].
        sections: tuple of Section, at least one.
        tendons: tuple of Tendon, in actuation order (none is valid).
        tubes: tuple of Tube, outermost first, each inside the one before (none is valid).
        masses: tuple of PointMass.
        calibrated_tension: (lowest, highest) tension [N] the robot was calibrated over (static),
            or None; inputs beyond it get a CalibrationWarning, not an error.
        calibrated_tip_force: (lowest, highest) tip force magnitude [N] likewise (static), or None.
        merged: set when built, not given (static): where some of the robot's own breakpoints
            (``own_breakpoints``: a section end, a tendon anchor, a point mass) lie at the same arc
            length, each one's group by the index of its first member (the length's, for those at
            the tip); the solver integrates each group as one breakpoint. None where none coincide,
            or where a breakpoint was traced when the robot was built (``replace`` under ``jit``
            or ``grad``): each then keeps its own, zero-length, interval.

    Raises:
        ValueError: bad values, naming the field (``sections[1].end``), the value and the range.
    """

    length: float
    sections: tuple
    tendons: tuple = ()
    tubes: tuple = ()
    masses: tuple = ()
    calibrated_tension: tuple | None = static(default=None)
    calibrated_tip_force: tuple | None = static(default=None)
    merged: tuple | None = static(default=None, repr=False)

    ITEMS: ClassVar[dict] = {}  # the item kinds and their classes, for fields.py (set below)

    def __post_init__(self):
        set_fields(self, length=as_array("length", self.length, (), unit=" m"))
        check_range("length", self.length, 0.0, lo_open=True, unit=" m")
        warn_implausible("Robot", self)
        for name, cls in (("sections", Section), ("tendons", Tendon), ("tubes", Tube), ("masses", PointMass)):
            items = tuple(getattr(self, name))
            for i, item in enumerate(items):
                if not isinstance(item, cls):
                    raise TypeError(f"{name}[{i}] must be a tdct.{cls.__name__}, got {type(item).__name__}")
            set_fields(self, **{name: items})
        if not self.sections:
            raise ValueError("sections: a robot needs at least one section, got none")
        for name in ("calibrated_tension", "calibrated_tip_force"):
            bounds = getattr(self, name)
            if bounds is not None:
                bounds = as_array(name, bounds, (2,), unit=" N")
                check_range(name, bounds, 0.0, unit=" N")
                if bounds[0] > bounds[1]:
                    raise ValueError(f"{name} = {fmt(bounds)} N must be (lowest, highest) with lowest <= highest")
                set_fields(self, **{name: tuple(float(b) for b in bounds)})
        if is_concrete_tree(self):
            self._check()
        set_fields(self, merged=coincident(own_breakpoints(self)))

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
        sizes = {f"sections[{j}].outer_diameter": sec.outer_diameter for j, sec in enumerate(self.sections)}
        note = size_note(L, sizes | {f"tendons[{i}].offset": t.offset for i, t in enumerate(self.tendons)})
        if note:
            warn_user(note, UnitWarning)

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
            if through and lo > hi:
                raise ValueError(_no_room(f"sections[{j}].", dt, D, dc, "inner_diameter"))
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
    def from_toml(cls, path: str | Path) -> Robot:
        """Reads a robot file (docs/robot-file.md), SI units.

        Raises:
            ValueError: the file cannot be read, has unknown or missing keys, or bad values; the
                message names the file, the field, the value and the allowed range.
        """
        path = Path(path)
        return cls.from_table(read_toml(path, "robot file"), path)

    @classmethod
    def from_table(cls, data: dict, path) -> Robot:
        """``from_dict`` of a robot file's table, its errors and unit notes prefixed with the file's path."""
        if not data:
            raise ValueError(f"robot file {path} is empty: {EMPTY}")
        try:
            with relabelled_notes(lambda note: f"robot file {path}: {note}"):
                return cls.from_dict(data)
        except (ValueError, TypeError) as e:
            raise ValueError(f"robot file {path}: {e}") from e

    @classmethod
    def from_dict(cls, data: dict) -> Robot:
        """A robot from the parsed robot file (the TOML's tables as dicts); see ``from_toml``."""
        if "sections" not in data:  # the paper robot's values by their Table II names (``Robot.paper``)
            table = data.get("robot", data)
            if not table:
                raise ValueError(f"the robot's table is empty: {EMPTY}")
            unknown = sorted(set(table) - set(PAPER))
            if items := [f"[[{k}]]" for k in unknown if k in cls.ITEMS]:
                raise ValueError(
                    f"no [[sections]]: a robot file with {', '.join(items)} describes "
                    "its body by length and [[sections]] (docs/robot-file.md); only a file of nothing but the paper "
                    "robot's Table II names (E_silicone, tendon_offset, ...) may leave them out"
                )
            if unknown:
                raise ValueError(
                    f"unknown field(s) {unknown}; allowed: the robot file's keys (length, sections, ...) or {sorted(PAPER)}"
                )
            return cls.paper(**table)
        # a [rig] table (how the robot sits on its test rig) is read by ``rig.Rig.from_toml``
        ranges = ("calibrated_tension", "calibrated_tip_force")
        _keys("the file", data, required=("length", "sections"), optional=("tendons", "tubes", "masses", "rig", *ranges))
        length = data["length"]
        sections, previous = [], 0.0
        for i, raw in enumerate(_tables("sections", data)):
            _keys(f"sections[{i}]", raw, required=SECTION_KEYS, optional=SECTION_OPTIONAL)
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
        calibrated = {k: data[k] for k in ranges if k in data}
        return cls(length, tuple(sections), tuple(tendons), tuple(tubes), tuple(masses), **calibrated)

    def to_toml(self) -> str:
        """The robot as a robot file's text (``from_toml`` reads it back, angles to the round-off of
        their conversion to degrees)."""
        lines = [f"length = {float(self.length)!r}"]
        lines += [f"{k} = {list(getattr(self, k))!r}" for k in ("calibrated_tension", "calibrated_tip_force") if getattr(self, k)]
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
    def has_friction(self) -> bool:
        """Some section has a friction coefficient (static): the solver carries tendon tension profiles."""
        return any(sec.friction is not None for sec in self.sections)

    @property
    def n_tubes(self) -> int:
        return len(self.tubes)

    def calibration_notes(self, tensions, tip_force) -> list[str]:
        """Notes for concrete inputs outside the calibrated ranges (tensions [N], tip forces [N],
        any leading axes); tracers, and a robot without calibrated ranges, give none."""
        notes = []
        magnitudes = None if not is_concrete(tip_force) else np.linalg.norm(np.asarray(tip_force, dtype=float), axis=-1)
        for what, values, bounds in (
            ("tensions", tensions, self.calibrated_tension),
            ("tip force magnitudes", magnitudes, self.calibrated_tip_force),
        ):
            if bounds is None or values is None or not is_concrete(values) or np.size(values) == 0:
                continue
            lo, hi = bounds
            v = np.asarray(values, dtype=float)
            extreme = f"up to {v.max():.4g} N" if v.max() > hi else f"down to {v.min():.4g} N" if v.min() < lo else None
            if extreme:
                notes.append(
                    f"{what} {extreme} are outside the range {interval(lo, hi)} N this robot was calibrated over: "
                    "the model is not validated there (far above it, shapes may loop)"
                )
        return notes

    def warn_outside_calibration(self, tensions, tip_force) -> None:
        """``calibration_notes`` as CalibrationWarnings, attributed to the caller's code."""
        for note in self.calibration_notes(tensions, tip_force):
            warn_user(note, CalibrationWarning)

    def replace(self, values=None, /, **named) -> Robot:
        """This robot with fields changed by name (fields.py): ``{"sections[0].E": 1e6}``,
        ``{"tendons[*].offset": 7e-3}``, or keywords: ``length=0.2``, or whole item tuples
        (``masses=(tdct.PointMass(0.1, 0.01),)``). Values may be traced (``jax.grad`` through
        them); concrete ones are checked as when built."""
        items = {k: named.pop(k) for k in list(named) if k in self.ITEMS}
        return fields.replace(dataclasses.replace(self, **items) if items else self, {**(values or {}), **named})

    @classmethod
    def paper(cls, **table_ii) -> Robot:
        """The paper's TDCT robot: one silicone section with the tube channel and four tendon
        channels, four straight tendons anchored at the tip (tendon 1 at body +y, then
        counter-clockwise), one Nitinol tube (its depth: the actuation's insertion), calibrated
        over 0-10 N of tension and 0-0.5 N of tip force.

        Its values are Table II's (``PAPER``), any of them overridden by name: ``length``,
        ``outer_diameter``, ``channel_diameter``, ``tendon_offset``, ``tendon_angles`` [rad],
        ``tendon_channel_diameter``, ``E_silicone``, ``nu_silicone``, ``density_silicone``,
        ``tube_outer_diameter``, ``tube_inner_diameter``, ``E_tube``, ``nu_tube``,
        ``density_tube``, ``calibrated_tension``, ``calibrated_tip_force``. The paper gives neither
        the tendon offset nor the silicone density: both are fitted (``paper.fit_load_capacities``,
        Gauss-Newton on exact derivatives) to the ten load capacities of Sec. V.A. One offset
        alone cannot match them (16% rms misfit); the pair leaves 5.7% rms. The fitted density is
        above the 1130 kg/m^3 of Elastosil M4601: an effective one that also carries what the
        model leaves out (tendons, sensor fibre, tip fixture). The tendon channel diameter is a
        guess and the tube density a handbook value for Nitinol.
        """
        unknown = sorted(set(table_ii) - set(PAPER))
        if unknown:
            raise TypeError(f"Robot.paper: unknown value(s) {unknown}; allowed: {sorted(PAPER)}")
        v = PAPER | table_ii
        _check_paper(v)
        angles = v["tendon_angles"]
        n = int(np.size(angles)) if is_concrete(angles) else int(np.shape(angles)[0])
        if n == 0:
            raise ValueError("tendon_angles must list at least one tendon, got an empty list")
        angles = as_array("tendon_angles", angles, (n,)) if is_concrete(angles) else angles
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UnitWarning)  # _check_paper noted them by their Table II names
            section = Section(
                end=v["length"],
                outer_diameter=v["outer_diameter"],
                E=v["E_silicone"],
                nu=v["nu_silicone"],
                density=v["density_silicone"],
                inner_diameter=v["channel_diameter"],
                tendon_channel_diameter=v["tendon_channel_diameter"],
            )
            tendons = tuple(Tendon(offset=v["tendon_offset"], angle=angles[i]) for i in range(n))
            tube = Tube(v["tube_outer_diameter"], v["tube_inner_diameter"], v["E_tube"], v["nu_tube"], v["density_tube"])
        return cls(v["length"], (section,), tendons, (tube,), (), v["calibrated_tension"], v["calibrated_tip_force"])

    def __getattr__(self, name):
        """The paper robot's former field names (``robot.E_silicone``): deprecated, warning once."""
        if name in fields.PAPER_NAMES:
            deprecated(f"robot.{name}", f"robot.replace / tdct.fields names: {fields.PAPER_NAMES[name]!r}")
            return fields.get(self, fields.PAPER_NAMES[name])
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")

    def to_general(self) -> Robot:
        """This robot (deprecated: every robot is already the one description)."""
        deprecated("Robot.to_general()", "the robot itself (Robot.paper() is already the one description)")
        return self


SECTION_KEYS = ("end", "outer_diameter", "E", "nu", "density")
SECTION_OPTIONAL = ("start", "inner_diameter", "tendon_channel_diameter", "friction", "guide_spacing", "damping")
TENDON_OPTIONAL = ("end", "twist_deg_per_m", "max_tension", "stiffness")


def own_breakpoints(robot: Robot) -> list:
    """The robot's own breakpoints in their static order: the base (0), the interior section ends,
    the anchors not at the tip, the point masses, the length; traced or concrete."""
    return [
        0.0,
        *(sec.end for sec in robot.sections[:-1]),
        *(t.end for t in robot.tendons if t.end is not None),
        *(m.s for m in robot.masses),
        robot.length,
    ]


def coincident(values: list) -> tuple | None:
    """For breakpoints ``values``, each one's group: the index of the first at the same arc length,
    the last's (the length) for those equal to it; None if none coincide or any is traced."""
    if not all(is_concrete(v) for v in values):
        return None
    v = [np.asarray(x, dtype=float) for x in values]
    last = len(v) - 1

    def same(a, b):
        return a.shape == b.shape and bool(np.all(a == b))

    group = tuple(last if same(x, v[last]) else next(j for j in range(i + 1) if same(v[j], x)) for i, x in enumerate(v))
    return None if group == tuple(range(len(v))) else group


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
        with relabelled_notes(lambda note: note.replace(f"{cls.__name__}.", f"{where}.", 1)):
            return cls(**kw)
    except ValueError as e:
        raise ValueError(str(e).replace(f"{cls.__name__}.", f"{where}.", 1)) from e


def _no_room(prefix: str, dt: float, D: float, dc: float, channel: str) -> str:
    """The message for a tendon channel diameter that leaves no room between the central channel and the surface."""
    return (
        f"{prefix}tendon_channel_diameter = {dt:g} m leaves no room for a tendon channel between the central channel "
        f"({channel} {dc:g} m) and the surface (outer_diameter {D:g} m): it must be at most "
        f"({prefix}outer_diameter - {prefix}{channel}) / 2 = {(D - dc) / 2:g} m"
    )


EMPTY = "describe the robot by length and [[sections]] (docs/robot-file.md), or give the paper robot's Table II names"
"""What an empty robot file or table is told."""


def _check_paper(v: dict) -> None:
    """``Robot.paper``'s values checked by their Table II names (then its items check themselves)."""
    units = dict(E_silicone=" Pa", E_tube=" Pa", density_silicone=" kg/m^3", density_tube=" kg/m^3", nu_silicone="", nu_tube="")
    for name in PAPER:
        if name not in ("tendon_angles", "calibrated_tension", "calibrated_tip_force"):
            v[name] = as_array(name, v[name], (), unit=units.get(name, " m"))
    for name in ("length", "outer_diameter", "E_silicone", "E_tube", "tube_outer_diameter"):
        check_range(name, v[name], 0.0, lo_open=True, unit=units.get(name, " m"))
    for name in ("density_silicone", "density_tube", "tendon_channel_diameter", "tube_inner_diameter"):
        check_range(name, v[name], 0.0, unit=units.get(name, " m"))
    for name in ("nu_silicone", "nu_tube"):
        check_range(name, v[name], *NU_RANGE, lo_open=True)
    warn_implausible("paper", v)
    if not all(is_concrete(v[n]) for n in ("outer_diameter", "channel_diameter", "tube_outer_diameter", "tendon_offset")):
        return
    check_range("channel_diameter", v["channel_diameter"], 0.0, float(v["outer_diameter"]), hi_open=True, unit=" m")
    where = " m (must fit the channel)"
    check_range("tube_outer_diameter", v["tube_outer_diameter"], 0.0, float(v["channel_diameter"]), lo_open=True, unit=where)
    dt = float(v["tendon_channel_diameter"])
    rim = (float(v["outer_diameter"]) - dt) / 2
    if dt > 0:
        core = (float(v["channel_diameter"]) + dt) / 2
        if core > rim:
            raise ValueError(_no_room("", dt, float(v["outer_diameter"]), float(v["channel_diameter"]), "channel_diameter"))
        where = " m (tendon channels between the central channel and the surface)"
        check_range("tendon_offset", v["tendon_offset"], core, rim, unit=where)
    else:
        check_range("tendon_offset", v["tendon_offset"], 0.0, rim, unit=" m (tendons inside the body)")
    a = np.asarray(v["tendon_angles"], dtype=float) if is_concrete(v["tendon_angles"]) else None
    if dt > 0 and a is not None and a.size > 1:  # the channels at r_t do not overlap
        gap = np.abs((a[:, None] - a[None, :] + np.pi) % (2 * np.pi) - np.pi)
        np.fill_diagonal(gap, np.inf)
        i, j = np.unravel_index(np.argmin(gap), gap.shape)
        distance = 2 * float(v["tendon_offset"]) * np.sin(gap[i, j] / 2)
        if distance <= dt:
            raise ValueError(
                f"tendon_angles: tendons {min(i, j) + 1} and {max(i, j) + 1} are {np.degrees(gap[i, j]):.3g} deg apart, so their "
                f"channels (diameter {dt:g} m) at tendon_offset {float(v['tendon_offset']):g} m overlap: centres {distance:.3g} m "
                f"apart, at least {dt:g} m needed"
            )


PAPER = dict(
    length=0.160,
    outer_diameter=0.020,
    channel_diameter=1.5e-3,
    tendon_offset=6.931e-3,
    tendon_angles=(np.pi / 2, np.pi, 3 * np.pi / 2, 0.0),
    tendon_channel_diameter=1.0e-3,
    E_silicone=0.85e6,
    nu_silicone=0.5,
    density_silicone=1792.0,
    tube_outer_diameter=1.397e-3,
    tube_inner_diameter=1.118e-3,
    E_tube=83e9,
    nu_tube=0.33,
    density_tube=6450.0,
    calibrated_tension=(0.0, 10.0),
    calibrated_tip_force=(0.0, 0.5),
)
"""The paper's robot (Table II) by name, SI units: ``Robot.paper()``'s values. ``tendon_offset``
and ``density_silicone`` are fitted to the Sec. V.A load capacities (``Robot.paper``)."""

Robot.ITEMS.update(sections=Section, tendons=Tendon, tubes=Tube, masses=PointMass)

ROBOTS = Path(__file__).parent / "robots"
"""The example robot files shipped with the package: paper.toml, two_segment.toml."""
