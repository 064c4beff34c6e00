"""A robot on its test rig: what turns recorded servo readings into the model's inputs, and the
model's tip into the measurement frame; the model's tips along a recording, warm-started sample
by sample.

A recorded experiment (``recording.py``) gives servo readings (tendon displacements, pulling
positive) and tip positions measured by a motion-capture system in its own frame. Between them:

- the drive: tendon i is commanded to delta_i = scale servo_i + pretension_i l_i / EA_i, its
  servo reading scaled (spool radius, gearing) and shifted by the stretch that holds it at
  ``pretension_i`` in the straight robot (l_i its rest length, EA_i its axial stiffness
  ``tendons[i].stiffness``); the robot solves with every tendon displacement-driven, slack where
  the shape asks for more than was pulled;
- gravity of magnitude ``g`` along (cos e cos a, cos e sin a, sin e) in the robot's base frame
  (a: ``gravity_azimuth`` about +z from +x, e: ``gravity_elevation`` from the base plane): how
  the robot hung on the rig, which recordings rarely state;
- the registration: p_measured = R(w) p + t, with R(w) the rotation of the rotation vector w
  (``rotation``) and t (``translation``).

Every scalar here has a name, as the robot's own fields do (``fields.py``): ``scale``,
``pretension[i]`` (``[*]`` one value for every tendon, ``[a-b]`` one for tendons a to b, e.g. a
segment's), ``rotation[0]`` ... ``translation[2]``, ``gravity_azimuth``, ``gravity_elevation``,
``g``; any other name is the robot's (``sections[*].E``, ``tendons[0-2].stiffness``).
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Mapping
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from . import fields, rod, roots, status
from .checks import as_array, check_range, is_concrete, read_toml
from .description import Robot
from .inputs import STANDARD_GRAVITY, Actuation, Loads
from .options import DEFAULT_SOLVER, SolverOptions
from .shooting import force_scale, shoot, unscaled
from .tree import pytree, set_fields

STANDARD_G = float(np.linalg.norm(STANDARD_GRAVITY))
"""Standard gravity's magnitude [m/s^2], the default ``Rig.g``."""
RAMP = 8
"""Sub-steps of the actuation ramp from the last converged sample when a warm start fails."""
_VECTORS = {"pretension": None, "rotation": 3, "translation": 3}
_SCALARS = ("scale", "gravity_azimuth", "gravity_elevation", "g")
_LINEAR = ("pretension", "rotation", "translation", "gravity_azimuth", "gravity_elevation")
_NAME = re.compile(r"^(\w+)\[(\d+|\*|\d+-\d+)\]$")


@pytree
class Rig:
    """The robot on its rig (module docstring); SI units, angles in rad.

    Attributes:
        robot: a Robot whose tendons all have a ``stiffness`` (EA [N]).
        scale: servo reading to tendon displacement [1], > 0.
        sign: +1 where a positive servo reading pulls its tendon, -1 where a negative one does.
        pretension: each tendon's tension in the straight robot at servo 0 [N], (n_t,).
        rotation: rotation vector of the robot base frame in the measurement frame [rad], (3,).
        translation: the robot base in the measurement frame [m], (3,).
        gravity_azimuth, gravity_elevation: gravity's direction in the robot base frame [rad].
        g: gravity's magnitude [m/s^2] (0: weightless).
    """

    robot: Robot
    scale: float = 1.0
    sign: float = 1.0
    pretension: object = None
    rotation: object = (0.0, 0.0, 0.0)
    translation: object = (0.0, 0.0, 0.0)
    gravity_azimuth: float = 0.0
    gravity_elevation: float = -np.pi / 2
    g: float = STANDARD_G

    def __post_init__(self):
        if not isinstance(self.robot, Robot):
            raise TypeError(f"Rig.robot must be a Robot (a robot file), got {type(self.robot).__name__}")
        n = self.robot.n_tendons
        missing = [i for i, t in enumerate(self.robot.tendons) if t.stiffness is None]
        if missing:
            which = ", ".join(f"{i + 1} (tendons[{i}])" for i in missing)
            raise ValueError(f"tendon(s) {which} have no stiffness: a displacement-driven rig needs each tendon's EA [N]")
        pretension = np.zeros(n) if self.pretension is None else self.pretension
        set_fields(
            self,
            pretension=as_array("Rig.pretension", pretension, (n,) if is_concrete(pretension) else None, unit=" N"),
            rotation=as_array("Rig.rotation", self.rotation, (3,) if is_concrete(self.rotation) else None, unit=" rad"),
            translation=as_array("Rig.translation", self.translation, (3,) if is_concrete(self.translation) else None, unit=" m"),
            # float64 arrays however given (a Python float is weakly typed): one compiled program
            **{
                name: as_array(f"Rig.{name}", getattr(self, name), () if is_concrete(getattr(self, name)) else None, unit=unit)
                for name, unit in (
                    ("scale", ""),
                    ("sign", ""),
                    ("gravity_azimuth", " rad"),
                    ("gravity_elevation", " rad"),
                    ("g", " m/s^2"),
                )
            },
        )
        check_range("Rig.pretension", self.pretension, 0.0, unit=" N")
        check_range("Rig.scale", self.scale, 0.0, lo_open=True)
        if is_concrete(self.sign) and float(self.sign) not in (1.0, -1.0):
            raise ValueError(f"Rig.sign = {float(self.sign):g} must be +1 (a positive servo reading pulls) or -1")
        check_range("Rig.g", self.g, 0.0, unit=" m/s^2")

    @classmethod
    def from_toml(cls, path) -> Rig:
        """A robot file with a ``[rig]`` table (docs/recordings.md): the robot and its rig values,
        angles in degrees there; a file without the table gives the defaults.

        Raises:
            ValueError: naming the file and key, for a bad robot file or ``[rig]`` table.
        """
        path = Path(path)
        data = read_toml(path, "robot file")
        robot = Robot.from_table(data, path)
        table = data.get("rig", {})
        keys = {"scale": 1.0, "sign": 1, "pretension": None, "rotation_deg": (0.0, 0.0, 0.0), "translation": (0.0, 0.0, 0.0)}
        keys |= {"gravity_azimuth_deg": 0.0, "gravity_elevation_deg": -90.0, "g": STANDARD_G}
        unknown = sorted(set(table) - set(keys)) if isinstance(table, dict) else ["(not a table)"]
        if unknown:
            raise ValueError(f"robot file {path}: [rig] has unknown key(s) {unknown}; allowed: {list(keys)}")
        v = keys | table
        try:
            return cls(
                robot,
                scale=v["scale"],
                sign=v["sign"],
                pretension=v["pretension"],
                rotation=np.radians(np.asarray(v["rotation_deg"], float)),
                translation=v["translation"],
                gravity_azimuth=np.radians(v["gravity_azimuth_deg"]),
                gravity_elevation=np.radians(v["gravity_elevation_deg"]),
                g=v["g"],
            )
        except (ValueError, TypeError) as e:
            raise ValueError(f"robot file {path}: [rig]: {e}") from e

    def to_toml(self) -> str:
        """The robot file text with the ``[rig]`` table (``from_toml`` reads it back)."""
        deg = np.degrees
        return self.robot.to_toml() + "\n".join(
            [
                "",
                "[rig]",
                f"scale = {float(self.scale)!r}",
                f"sign = {int(self.sign)}                          # +1: a positive servo reading pulls",
                f"pretension = {[float(x) for x in np.asarray(self.pretension)]!r}          # [N]",
                f"rotation_deg = {[float(x) for x in deg(np.asarray(self.rotation))]!r}     # rotation vector",
                f"translation = {[float(x) for x in np.asarray(self.translation)]!r}      # [m]",
                f"gravity_azimuth_deg = {float(deg(self.gravity_azimuth))!r}",
                f"gravity_elevation_deg = {float(deg(self.gravity_elevation))!r}",
                f"g = {float(self.g)!r}",
                "",
            ]
        )

    @property
    def gravity(self):
        """Gravity in the robot base frame [m/s^2], (3,)."""
        a, e = self.gravity_azimuth, self.gravity_elevation
        return self.g * jnp.stack([jnp.cos(e) * jnp.cos(a), jnp.cos(e) * jnp.sin(a), jnp.sin(e)])

    def displacements(self, servo):
        """Commanded tendon displacements [m] for servo readings [m], (..., n_t)."""
        return self.sign * self.scale * servo + self.pretension * rod.rest_lengths(self.robot) / rod.tendon_stiffness(self.robot)

    def to_measured(self, p):
        """Points p (..., 3) in the robot base frame, in the measurement frame."""
        return p @ rotation_matrix(self.rotation).T + self.translation


def rotation_matrix(w):
    """R = exp(w^) by Rodrigues' formula, smooth (and differentiable) at w = 0."""
    t2 = w @ w
    small = t2 < 1e-12
    t = jnp.sqrt(jnp.where(small, 1.0, t2))
    a = jnp.where(small, 1 - t2 / 6, jnp.sin(t) / t)
    b = jnp.where(small, 0.5 - t2 / 24, (1 - jnp.cos(t)) / jnp.where(small, 1.0, t2))
    W = jnp.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
    return jnp.eye(3) + a * W + b * W @ W


def _parse(rig: Rig, name: str):
    """(field, indices) of a rig name (indices None for a scalar); None for a robot field name.
    Raises ValueError, with the allowed names, for an unknown rig name or index."""
    if name in _SCALARS:
        return name, None
    m = _NAME.match(name)
    if not m or m[1] not in _VECTORS:
        return None
    n = _VECTORS[m[1]] or rig.robot.n_tendons
    if m[2] == "*":
        return m[1], tuple(range(n))
    lo, _, hi = m[2].partition("-")
    lo, hi = int(lo), int(hi or lo)
    if not lo <= hi < n:
        raise ValueError(f"{name!r}: {m[1]} has {n} entries (indices 0 to {n - 1}, a range a-b with a <= b)")
    return m[1], tuple(range(lo, hi + 1))


def check_name(rig: Rig, name: str) -> None:
    """Raises ValueError unless ``name`` is a rig or robot field name (``fields.py``)."""
    if _parse(rig, name) is None:
        try:
            fields.check(rig.robot, name)
        except ValueError as e:
            allowed = ", ".join([*_SCALARS, "pretension[i, *, a-b]", "rotation[0-2]", "translation[0-2]"])
            raise ValueError(f"{e}; or a rig name: {allowed}") from None


def is_linear(name: str) -> bool:
    """Whether the named value may be zero or negative (fitted as it is, not in log space)."""
    return name.split("[", 1)[0] in _LINEAR or fields.is_linear(name)


def value(rig: Rig, name: str) -> float:
    """The named value (for a shared name, the one value its entries share; ValueError if they differ)."""
    where = _parse(rig, name)
    if where is None:
        return fields.value(rig.robot, name)
    field, index = where
    if index is None:
        return float(getattr(rig, field))
    values = np.asarray(getattr(rig, field))[list(index)]
    if np.ptp(values) > 0:
        raise ValueError(f"{name}: the entries differ ({values.tolist()}); name one, e.g. {field}[{index[0]}]")
    return float(values[0])


def replace(rig: Rig, values: Mapping[str, object]) -> Rig:
    """The rig with the named values set (concrete or traced)."""
    robot_values, changes = {}, {}
    for name, v in values.items():
        where = _parse(rig, name)
        if where is None:
            robot_values[name] = v
            continue
        field, index = where
        if index is None:
            changes[field] = v
        else:
            base = changes.get(field, jnp.asarray(getattr(rig, field), float))
            changes[field] = base.at[np.asarray(index)].set(v)
    changes["robot"] = fields.replace(rig.robot, robot_values)
    if all(is_concrete(v) for v in values.values()):
        return dataclasses.replace(rig, **changes)
    new = object.__new__(Rig)
    set_fields(new, **{f.name: changes.get(f.name, getattr(rig, f.name)) for f in dataclasses.fields(Rig)})
    return new


def _unknowns(robot: Robot):
    """Size of a sample's unknowns: the base wrench and every tendon's tension."""
    return 6 + robot.n_tendons


def solve_sample(rig: Rig, servo, guess, solver: SolverOptions = DEFAULT_SOLVER, memory=None):
    """The model's tip in the measurement frame for servo readings [m] (n_t,), from ``guess`` (base
    wrench and tensions, (6 + n_t,), NaN: the straight robot): (tip (3,), the unknowns found
    (6 + n_t,), status code, and with tendon friction the tension profile, else None).
    ``memory``: with friction, the previous sample's tension profile (``Actuation.memory``).
    Derivatives in the rig come from the implicit function theorem."""
    robot = rig.robot
    n = robot.n_tendons
    guess = lax.stop_gradient(guess)
    warm = jnp.all(jnp.isfinite(guess))
    act = Actuation._rebuild(
        jnp.where(warm, guess[6:], 0.0), jnp.zeros(robot.n_tubes), rig.displacements(servo), tuple(range(n)), memory
    )
    problem = (robot, act, Loads(), rig.gravity)
    x, info = roots.root(*problem, jnp.where(warm, guess, jnp.nan), solver)
    F_c = force_scale(*problem)
    profile = None
    if robot.has_friction:
        _, (nodes, pl, *_) = shoot(*problem, solver, x, F_c, path=True)
        tip, profile = nodes.y.p[-1, -1], rod.tension_profile(pl, nodes)
    else:
        tip = shoot(*problem, solver, x, F_c)[1].p
    return rig.to_measured(tip), unscaled(robot, x, F_c), info.result.astype(jnp.int32), profile


def _along(rig: Rig, servos, solver: SolverOptions):
    """``solve_sample`` along a recorded sequence, each sample warm-started from the last
    converged one, and when that fails, reached by a ramp of ``RAMP`` sub-steps from it; with
    tendon friction, each takes the last converged one's tension profile as its memory (the ramp's
    sub-steps too: the path the servos took), from none at the start (loading from slack). One
    chain, not vmapped pieces: under vmap every ``lax.cond`` of the solver runs both branches,
    which costs more than the lanes gain on a CPU."""
    n = _unknowns(rig.robot)

    def step(carry, servo):
        last, last_servo, memory = carry
        tip, x, code, profile = solve_sample(rig, servo, last, solver, memory)

        def ramp():
            def sub(j, c):
                s = last_servo + (servo - last_servo) * (j + 1) / RAMP
                _, x, code, profile = solve_sample(rig, s, c[0], solver, c[1])
                ok = code == status.SUCCESS
                return jnp.where(ok, x, c[0]), c[1] if profile is None else jnp.where(ok, profile, c[1]), code

            x, memory_r, code = lax.fori_loop(0, RAMP, sub, (last, memory, jnp.int32(status.SUCCESS)))
            return solve_sample(rig, servo, x, solver, memory_r)

        tip, x, code, profile = lax.cond(code == status.SUCCESS, lambda: (tip, x, code, profile), ramp)
        ok = code == status.SUCCESS
        memory = memory if profile is None else jnp.where(ok, profile, memory)
        return (jnp.where(ok, x, last), jnp.where(ok, servo, last_servo), memory), (tip, x, code, profile)

    memory = None
    if rig.robot.has_friction:
        memory = jnp.zeros((rod.n_intervals(rig.robot, Loads()) * (solver.steps + 1), rig.robot.n_tendons))
    start = (jnp.full(n, jnp.nan), jnp.zeros(rig.robot.n_tendons), memory)
    return lax.scan(step, start, servos)[1]


along = jax.jit(_along, static_argnames=("solver",))
"""Tips (n, 3), unknowns (n, 6 + n_t), status codes (n,) and, with tendon friction, tension
profiles (n, n_nodes, n_t) (else None) along a sequence of servo readings (n, n_t) [m],
warm-started sample by sample (``_along``)."""


def memories(profiles):
    """Each sample's memory from the profiles along a sequence (n, n_nodes, n_t): its predecessor's,
    none (zeros) for the first; None without friction (``profiles`` None)."""
    if profiles is None:
        return None
    profiles = jnp.asarray(profiles)
    return jnp.concatenate([jnp.zeros_like(profiles[:1]), profiles[:-1]])


@jax.jit
def _batch(rig: Rig, servos, guesses, solver: SolverOptions = DEFAULT_SOLVER, memory=None):
    """``solve_sample`` side by side (vmap); with friction each sample's ``memory`` given (``memories``)."""
    return jax.vmap(lambda s, g, m: solve_sample(rig, s, g, solver, m))(servos, guesses, memory)


def errors(predicted, measured, offset=None) -> dict:
    """Tip errors after removing an offset between predicted and measured tips (n, 3) [m] (by
    default their mean offset): RMSE (the Euclidean error's root mean square), mean, median and
    95th percentile [m], the offset removed (3,) and the sample count."""
    predicted, measured = np.asarray(predicted), np.asarray(measured)
    offset = np.mean(measured - predicted, axis=0) if offset is None else np.asarray(offset)
    e = np.linalg.norm(predicted + offset - measured, axis=1)
    return dict(
        rmse=float(np.sqrt(np.mean(e**2))),
        mean=float(np.mean(e)),
        median=float(np.median(e)),
        p95=float(np.percentile(e, 95)),
        offset=offset,
        n=int(e.size),
    )
