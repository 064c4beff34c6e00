"""The robot's surroundings: obstacles as data, each a signed distance of a world point (issue 26).

Every obstacle is a pytree whose numbers are leaves, so a solve is differentiable in an
obstacle's position and size, and a sweep over obstacle positions is a ``vmap`` like any other.
The distance is positive outside, zero on the surface and negative inside; its gradient is the
outward normal, the direction in which a frictionless contact pushes the robot.

    Plane     a half-space {x : (x - point) . n <= 0}, n the unit outward normal
    Sphere    |x - center| - radius
    Capsule   the distance to the segment [a, b] less the radius (a cylinder with round ends)
    Distance  any function of a world point written in JAX (``function(p, params)``)

A ``Scene`` is a tuple of obstacles with the spacing of the contact candidates along the body.
The file format (``read_scene``, docs/contact.md) is TOML in SI units::

    every = 2                   # a candidate every 2 RK4 steps (optional)

    [[obstacles]]
    kind = "plane"
    name = "table"
    point = [0.0, -0.03, 0.0]   # m
    normal = [0.0, 1.0, 0.0]

    [[obstacles]]
    kind = "sphere"
    center = [0.0, 0.0, 0.2]
    radius = 0.02
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from .checks import UnitWarning, as_array, check_integer, check_range, fmt, is_concrete, reach_note, read_toml, warn_user
from .tree import pytree, set_fields, static


def _name(obstacle, i: int | None = None) -> str:
    """How messages name an obstacle: its kind and name, with its place in the scene where known."""
    kind = type(obstacle).__name__.lower() + (f" {obstacle.name!r}" if obstacle.name else "")
    return kind if i is None else f"obstacles[{i}] ({kind})"


@pytree
class Plane:
    """A half-space: the solid side lies against ``normal``.

    Attributes:
        point: a point on the surface [m], (3,), world frame.
        normal: the outward normal (3,), any non-zero length (stored as a unit vector).
        name: how results and messages name it.
    """

    point: object = (0.0, 0.0, 0.0)
    normal: object = (0.0, 1.0, 0.0)
    name: str = static(default="")

    def __post_init__(self):
        point = as_array(f"{_name(self)} point", self.point, (3,), unit=" m")
        normal = as_array(f"{_name(self)} normal", self.normal, (3,))
        if is_concrete(normal):
            length = np.linalg.norm(normal)
            if length == 0:
                raise ValueError(f"{_name(self)} normal = {fmt(normal)}: a plane needs a non-zero normal")
            normal = normal / length
        set_fields(self, point=point, normal=normal)

    def distance(self, p):
        """Signed distance [m] of the world point p (3,)."""
        n = self.normal / jnp.linalg.norm(self.normal)
        return jnp.dot(p - self.point, n)


@pytree
class Sphere:
    """A solid ball.

    Attributes:
        center: its centre [m], (3,), world frame.
        radius: its radius [m], > 0.
        name: how results and messages name it.
    """

    center: object = (0.0, 0.0, 0.0)
    radius: object = 0.01
    name: str = static(default="")

    def __post_init__(self):
        center = as_array(f"{_name(self)} center", self.center, (3,), unit=" m")
        radius = as_array(f"{_name(self)} radius", self.radius, ())
        check_range(f"{_name(self)} radius", radius, 0.0, lo_open=True, unit=" m")
        set_fields(self, center=center, radius=radius)

    def distance(self, p):
        """Signed distance [m] of the world point p (3,)."""
        return _norm(p - self.center) - self.radius


@pytree
class Capsule:
    """A cylinder of ``radius`` about the segment [a, b], closed by half-spheres (a = b: a sphere).

    Attributes:
        a, b: the axis' end points [m], (3,) each, world frame.
        radius: its radius [m], > 0.
        name: how results and messages name it.
    """

    a: object = (0.0, 0.0, 0.0)
    b: object = (0.0, 0.0, 0.1)
    radius: object = 0.01
    name: str = static(default="")

    def __post_init__(self):
        a = as_array(f"{_name(self)} a", self.a, (3,), unit=" m")
        b = as_array(f"{_name(self)} b", self.b, (3,), unit=" m")
        radius = as_array(f"{_name(self)} radius", self.radius, ())
        check_range(f"{_name(self)} radius", radius, 0.0, lo_open=True, unit=" m")
        set_fields(self, a=a, b=b, radius=radius)

    def distance(self, p):
        """Signed distance [m] of the world point p (3,)."""
        ab = self.b - self.a
        t = jnp.clip(jnp.dot(p - self.a, ab) / jnp.maximum(jnp.dot(ab, ab), 1e-300), 0.0, 1.0)
        return _norm(p - self.a - t * ab) - self.radius


@pytree
class Distance:
    """Any obstacle given by its signed distance function, written in JAX.

    Attributes:
        function: ``function(p, params) -> scalar`` [m] for a world point p (3,) [m]: positive
            outside, negative inside; its gradient (by autodiff) is the outward normal, so it
            should have unit length near the surface (an exact signed distance).
        params: a pytree of the function's numbers (leaves: differentiable, batchable), or ().
        name: how results and messages name it.
    """

    function: Callable = static(default=None)
    params: object = ()
    name: str = static(default="")

    def __post_init__(self):
        if not callable(self.function):
            raise ValueError(f"{_name(self)} function = {self.function!r}: a callable function(p, params) -> distance [m]")

    def distance(self, p):
        """Signed distance [m] of the world point p (3,)."""
        return self.function(p, self.params)


SCENES = Path(__file__).parent / "scenes"
"""The example scene files shipped with the package (``table.toml``: a table and a ball on it)."""
OBSTACLES = {"plane": Plane, "sphere": Sphere, "capsule": Capsule}
"""The obstacle kinds a scene file names (``kind = ...``); ``Distance`` is Python only."""


def _norm(x):
    """|x|, with a finite gradient at x = 0."""
    return jnp.sqrt(jnp.maximum(jnp.dot(x, x), 1e-300))


EVERY = 4
"""Default candidate spacing in RK4 steps: the paper robot's tip resting on a plane is solved in
2.1x the contact-free warm solve (every 1: 4.7x, 2: 4.3x); a body contact in 5.6x (every 1: 54x,
2: 9.7x), its force within 4% of every 2's (benchmarks/contact_speed.py)."""


@pytree
class Scene:
    """Obstacles the robot can touch, and where along the body it can touch them.

    Attributes:
        obstacles: a tuple of ``Plane``, ``Sphere``, ``Capsule`` and ``Distance`` (at least one).
        every: a contact candidate every ``every`` RK4 steps along the body, and at the tip
            (static; 1 is the finest; default ``EVERY``).
    """

    obstacles: tuple = ()
    every: int = static(default=EVERY)

    def __post_init__(self):
        obstacles = tuple(self.obstacles) if isinstance(self.obstacles, (list, tuple)) else (self.obstacles,)
        if not obstacles:
            raise ValueError("obstacles = (): a scene needs at least one obstacle")
        for i, o in enumerate(obstacles):
            if not isinstance(o, (Plane, Sphere, Capsule, Distance)):
                raise TypeError(f"Scene obstacles[{i}] must be a tdct.Plane, Sphere, Capsule or Distance, got {type(o).__name__}")
            if isinstance(o, Distance):
                _check_function(o, i)
        set_fields(self, obstacles=obstacles, every=check_integer("every", self.every))

    @property
    def n_obstacles(self) -> int:
        return len(self.obstacles)

    @property
    def names(self) -> tuple[str, ...]:
        """Each obstacle's name, or ``obstacles[i]`` where it has none."""
        return tuple(o.name or f"obstacles[{i}]" for i, o in enumerate(self.obstacles))

    def distances(self, p):
        """Signed distances [m] of the world point p (3,) to every obstacle, (n_obstacles,)."""
        return jnp.stack([jnp.asarray(o.distance(p), float) for o in self.obstacles])

    def normals(self, p):
        """Outward unit normals of every obstacle at the world point p (3,), (n_obstacles, 3): the
        normalised gradient of each distance."""
        g = jnp.stack([jax.grad(lambda p, o=o: jnp.asarray(o.distance(p), float))(p) for o in self.obstacles])
        return g / jnp.linalg.norm(g, axis=-1, keepdims=True)

    def check_base(self, base_radius: float) -> None:
        """ValueError naming the obstacle whose distance from the base (the origin) is below the
        body's radius there: the robot would start inside it."""
        if not all(is_concrete(x) for x in jax.tree.leaves(self)):
            return
        with jax.ensure_compile_time_eval():
            d = np.asarray(self.distances(jnp.zeros(3)))
        for i, o in enumerate(self.obstacles):
            if d[i] < base_radius:
                raise ValueError(
                    f"{_name(o, i)}: the robot's base (the origin, body radius {base_radius:g} m) is inside it or "
                    f"touching it (distance {d[i]:g} m); move the obstacle at least {base_radius:g} m from the origin"
                )

    def check_reach(self, length: float) -> None:
        """A UnitWarning (``checks.reach_note``) for each obstacle whose centre (a sphere's), axis (a
        capsule's) or surface (a plane's, a ``Distance``'s) lies more than ``TARGET_REACH`` robot
        lengths (``length`` [m]) from the base, as if typed in millimetres; traced obstacles get none."""
        if not all(is_concrete(x) for x in jax.tree.leaves(self)):
            return
        with jax.ensure_compile_time_eval():
            d = np.abs(np.asarray(self.distances(jnp.zeros(3))))
        for i, o in enumerate(self.obstacles):
            where = {Sphere: "center", Capsule: "axis"}.get(type(o), "surface")
            note = reach_note(f"{_name(o, i)} {where}", d[i] + float(getattr(o, "radius", 0.0)), length)
            if note:
                warn_user(note, UnitWarning)

    def to_dict(self) -> dict:
        """The scene file's table (``read_scene``); ``Distance`` obstacles have no file form."""
        out = {"every": self.every, "obstacles": []}
        for i, o in enumerate(self.obstacles):
            kind = next((k for k, c in OBSTACLES.items() if isinstance(o, c)), None)
            if kind is None:
                raise ValueError(f"{_name(o, i)}: a Distance obstacle (a Python function) cannot be written to a scene file")
            fields = {f: np.asarray(getattr(o, f)).tolist() for f in _FILE_FIELDS[kind]}
            out["obstacles"].append({"kind": kind, **({"name": o.name} if o.name else {}), **fields})
        return out


_FILE_FIELDS = {"plane": ("point", "normal"), "sphere": ("center", "radius"), "capsule": ("a", "b", "radius")}


def _check_function(o: Distance, i: int) -> None:
    """A user distance function must return one finite number at the origin (ValueError naming
    the obstacle)."""
    if not all(is_concrete(x) for x in jax.tree.leaves(o.params)):
        return
    try:
        with jax.ensure_compile_time_eval():
            d = o.function(jnp.zeros(3), o.params)
    except Exception as e:
        raise ValueError(f"{_name(o, i)} function fails at the origin: {type(e).__name__}: {e}") from e
    if jnp.shape(d) != ():
        raise ValueError(
            f"{_name(o, i)} function returns shape {jnp.shape(d)} at the origin: one number (a distance [m]) expected"
        )
    if not np.isfinite(float(d)):
        raise ValueError(f"{_name(o, i)} function returns {float(d)} at the origin: a finite distance [m] expected")


def scene_from_dict(table: dict, where: str = "the scene") -> Scene:
    """A Scene from a scene file's top-level table (module docstring); ValueError naming the
    obstacle and field for anything missing, unknown or out of range."""
    unknown = set(table) - {"every", "obstacles"}
    if unknown:
        raise ValueError(f"{where}: unknown key(s) {sorted(unknown)}; a scene has 'every' and [[obstacles]]")
    items = table.get("obstacles")
    if not isinstance(items, list) or not items:
        raise ValueError(f"{where}: no [[obstacles]] tables; a scene needs at least one obstacle")
    obstacles = []
    for i, item in enumerate(items):
        kind = item.get("kind") if isinstance(item, dict) else None
        if kind not in OBSTACLES:
            raise ValueError(f"{where}: obstacles[{i}] kind = {kind!r} must be one of {tuple(OBSTACLES)}")
        fields = _FILE_FIELDS[kind]
        extra = set(item) - {"kind", "name", *fields}
        if extra:
            raise ValueError(f"{where}: obstacles[{i}] ({kind}) has unknown field(s) {sorted(extra)}; it takes {fields}")
        missing = [f for f in fields if f not in item]
        if missing:
            raise ValueError(f"{where}: obstacles[{i}] ({kind}) lacks {missing}; it takes {fields} (SI units: m)")
        try:
            obstacles.append(OBSTACLES[kind](**{f: item[f] for f in fields}, name=str(item.get("name", ""))))
        except ValueError as e:
            raise ValueError(f"{where}: obstacles[{i}]: {e}") from None
    try:
        return Scene(tuple(obstacles), every=table.get("every", EVERY))
    except ValueError as e:
        raise ValueError(f"{where}: {e}") from None


def read_scene(path) -> Scene:
    """A Scene from a TOML scene file (module docstring; docs/contact.md)."""
    path = Path(path)
    return scene_from_dict(read_toml(path, "scene file"), f"scene file {path}")
