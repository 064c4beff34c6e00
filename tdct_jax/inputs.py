"""What is done to a robot: tendon tensions and displacements with tube insertions
(``Actuation``), dead loads at the tip and along the body (``Loads``), and gravity; all world
frame, all differentiable leaves, leading batch axes allowed where a field says so.

Gravity stays the solver's ``gravity=`` argument, a vector in any direction.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from .checks import UnitWarning, as_array, check_range, deprecated, is_concrete, plausibility_note, warn_user
from .scene import Scene
from .tree import pytree, set_fields, static, unchecked

STANDARD_GRAVITY = (0.0, -9.81, 0.0)
"""World gravity [m/s^2]: the robot is mounted horizontally, gravity along -y."""


class _Insertion(type):
    """``Actuation(..., insertion=d)``, the former paper robot's one tube: ``insertions``, with a
    FutureWarning once."""

    def __call__(cls, *args, **kwargs):
        if "insertion" in kwargs:
            deprecated("Actuation(insertion=...)", "Actuation(tensions, insertions) (a number for one tube)")
            kwargs["insertions"] = kwargs.pop("insertion")
        return super().__call__(*args, **kwargs)


@pytree
class Actuation(metaclass=_Insertion):
    """Joint-space inputs: each tendon driven by its tension or, for those listed in ``driven``,
    by its displacement (the length pulled at the base, what its encoder reads); mixed control is
    allowed. Leading batch axes are allowed on tensions and insertions (a stack of samples).

    Attributes:
        tensions: tension of each tendon [N], shape (..., n_tendons), tendon 1 first; for a
            displacement-driven tendon, the start of the search (0 is fine). Empty (the default):
            zero on every tendon of the robot it is applied to.
        insertions: depth of each tube from the base [m], shape (..., n_tubes), in [0, L]; a
            number for a robot with one tube. Empty (the default): every tube withdrawn.
        displacements: the commanded displacement of each driven tendon [m], shape (len(driven),):
            its rest length inside the straight robot less its present rest length there (so
            positive when pulled). Its tension is found so that the shape matches; where that
            would take a negative tension the tendon goes slack (tension exactly 0,
            ``Solution.slack``).
        driven: indices of the displacement-driven tendons, 0 for tendon 1 (static).
        memory: with tendon friction (``Section.friction``), each tendon's tension profile at the
            previous pose [N], (n_nodes, n_t): the previous Solution's ``tendon_tension``, so that
            tendons stick where the new pose does not make them slide (quasi-static hysteresis);
            None (default): loading from slack (zero tension everywhere before this pose).
    """

    tensions: object = ()
    insertions: object = ()
    displacements: object = ()
    driven: tuple = static(default=())
    memory: object = None

    def __post_init__(self):
        tensions = self.tensions
        if is_concrete(tensions) and np.ndim(tensions) == 0:
            tensions = (tensions,)
        tensions = as_array("tensions", tensions, trailing=(np.shape(tensions)[-1],) if is_concrete(tensions) else None)
        check_range("tensions", tensions, 0.0, unit=" N")
        insertions = as_array("insertions", self.insertions, unit=" m")
        if np.ndim(insertions) == 0 or np.ndim(insertions) == np.ndim(tensions) - 1 > 0:
            insertions = insertions[..., None]  # one tube
        check_range("insertions", insertions, 0.0, unit=" m")
        if is_concrete(tensions) and is_concrete(insertions) and np.size(tensions) and np.size(insertions):
            ta, ia = np.shape(tensions)[:-1], np.shape(insertions)[:-1]
            if ta != ia:
                raise ValueError(
                    f"tensions has shape {np.shape(tensions)} and insertions {np.shape(insertions)}: their leading (batch) "
                    f"axes {ta} and {ia} must be the same (one configuration: no batch axes)"
                )
        driven = tuple(int(i) for i in self.driven)
        if len(set(driven)) != len(driven) or any(i < 0 for i in driven):
            raise ValueError(f"driven = {self.driven!r}: distinct tendon indices (0 for tendon 1) expected")
        k = len(driven)
        if is_concrete(self.displacements) and np.ndim(self.displacements) <= 1 and np.size(self.displacements) != k:
            raise ValueError(
                f"displacements = {self.displacements!r}: one per driven tendon, and driven = {driven} names {k}; "
                "driven= lists the tendons they drive (0 for tendon 1)"
            )
        displacements = as_array(
            "displacements", self.displacements, (k,) if is_concrete(self.displacements) else None, unit=" m"
        )
        if not k and np.ndim(tensions) > 1:  # none, with the tensions' batch axes: vmap maps every leaf
            displacements = np.zeros(np.shape(tensions)[:-1] + (0,))
        memory = None if self.memory is None else as_array("memory", self.memory, unit=" N")
        if memory is not None:
            if is_concrete(memory) and (np.ndim(memory) < 2 or np.shape(memory)[-1] != np.shape(tensions)[-1]):
                raise ValueError(
                    f"memory has shape {np.shape(memory)}: a tension profile (n_nodes, n_tendons) is expected, "
                    f"n_tendons = {np.shape(tensions)[-1]} (a Solution's tendon_tension)"
                )
            if is_concrete(memory) and np.min(memory) < 0:
                row, col = np.unravel_index(np.argmin(memory), np.shape(memory))
                raise ValueError(
                    f"memory[{row}, {col}] = {np.min(memory):g} N is outside the allowed range [0, inf] N: tensions are not negative"
                )
        set_fields(self, tensions=tensions, insertions=insertions, displacements=displacements, driven=driven, memory=memory)

    @property
    def insertion(self):
        """The first tube's depth [m], shape (...): the insertion of a robot with one tube."""
        return self.insertions[..., 0]

    @classmethod
    def of(cls, act, robot) -> Actuation:
        """``act`` for ``robot``: None, or empty tensions or insertions, are zeros of the robot's
        counts."""
        act = cls() if act is None else act
        if not isinstance(act, cls):
            raise TypeError(f"act must be a tdct.Actuation, got {type(act).__name__}")
        tensions, insertions = act.tensions, act.insertions
        if np.shape(tensions)[-1:] == (0,) and robot.n_tendons:
            tensions = np.zeros(np.shape(tensions)[:-1] + (robot.n_tendons,))
        if np.shape(insertions)[-1:] == (0,) and robot.n_tubes:
            insertions = np.zeros(np.shape(insertions)[:-1] + (robot.n_tubes,))
        if tensions is act.tensions and insertions is act.insertions:
            return act
        return cls._rebuild(tensions, insertions, act.displacements, act.driven, act.memory)

    @classmethod
    def _rebuild(cls, tensions, insertions, displacements, driven, memory=None) -> Actuation:
        """Built without the checks (inside the solver, from traced values; stacks)."""
        return unchecked(cls, tensions=tensions, insertions=insertions, displacements=displacements, driven=driven, memory=memory)

    def scaled(self, lam) -> Actuation:
        """Tensions, displacements and memory times lam (the solver's load continuation)."""
        memory = None if self.memory is None else lam * self.memory
        return self._rebuild(lam * self.tensions, self.insertions, lam * self.displacements, self.driven, memory)


@pytree
class Loads:
    """Dead loads on the robot, world frame.

    Attributes:
        tip_force: F_e at s = L [N], (..., 3): leading batch axes allowed.
        tip_moment: M_e at s = L [N m], (..., 3).
        point_s: arc lengths of the point loads [m], (k,), in [0, L].
        point_force: their forces [N], (k, 3).
        point_moment: their moments [N m], (k, 3).
        distributed_force: a force per unit length along the whole body [N/m], (3,) (added to
            the weight).
        scene: the obstacles the robot may touch (a ``tdct.Scene``), or None: a pytree child, so
            the solve's implicit derivatives, ``vmap`` and sweeps reach the obstacles' numbers.
            Not scaled by the load continuation (contact.py). ``solve(..., scene=)`` puts it here.
    """

    tip_force: object = (0.0, 0.0, 0.0)
    tip_moment: object = (0.0, 0.0, 0.0)
    point_s: object = ()
    point_force: object = None
    point_moment: object = None
    distributed_force: object = (0.0, 0.0, 0.0)
    scene: object = None

    def __post_init__(self):
        if self.scene is not None and not isinstance(self.scene, Scene):
            raise TypeError(f"scene must be a tdct.Scene or None, got {type(self.scene).__name__}")
        k = np.size(self.point_s) if is_concrete(self.point_s) else None
        point_s = as_array("point_s", self.point_s, (k,) if k is not None else None, unit=" m")
        check_range("point_s", point_s, 0.0, unit=" m")
        values = {}
        for name in ("point_force", "point_moment"):
            x = getattr(self, name)
            if x is None and k is not None:
                x = np.zeros((k, 3))
            values[name] = as_array(name, x, (k, 3) if k is not None and is_concrete(x) else None)
        for name in ("tip_force", "tip_moment"):
            values[name] = as_array(name, getattr(self, name), trailing=(3,))
        force, moment = values["tip_force"], values["tip_moment"]
        if is_concrete(force) and is_concrete(moment) and np.shape(force) != np.shape(moment):
            raise ValueError(
                f"tip_force has shape {np.shape(force)} and tip_moment {np.shape(moment)}: their leading (batch) axes must "
                "be the same (one configuration: no batch axes)"
            )
        values["distributed_force"] = as_array("distributed_force", self.distributed_force, (3,))
        set_fields(self, point_s=point_s, **values)

    @classmethod
    def from_mass(cls, mass, gravity=STANDARD_GRAVITY) -> Loads:
        """The weight of a tip mass [kg] (shape (...) for a batch) under ``gravity`` [m/s^2]."""
        mass = as_array("mass", mass)
        check_range("mass", mass, 0.0, unit=" kg")
        g = gravity_vector(gravity)
        concrete = is_concrete(mass) and is_concrete(g)
        force = np.multiply.outer(mass, g) if concrete else jnp.einsum("...,i->...i", mass, g)
        return cls(tip_force=force, tip_moment=np.zeros(np.shape(force)))

    @property
    def n_points(self) -> int:
        return int(np.shape(self.point_s)[0])

    @property
    def force(self):
        """The tip force (deprecated name: ``tip_force``)."""
        deprecated("load.force", "load.tip_force")
        return self.tip_force

    @property
    def moment(self):
        """The tip moment (deprecated name: ``tip_moment``)."""
        deprecated("load.moment", "load.tip_moment")
        return self.tip_moment

    @classmethod
    def of(cls, load) -> Loads:
        """A Loads from itself or None (no load)."""
        if load is None:
            return cls()
        if isinstance(load, cls):
            return load
        raise TypeError(f"load must be a tdct.Loads, got {type(load).__name__}")

    def _with(self, **changes) -> Loads:
        fields = {name: getattr(self, name) for name in self.__dataclass_fields__}
        return unchecked(Loads, **(fields | changes))

    def with_tip(self, force, moment=None) -> Loads:
        """The same loads with another tip force [N] (and moment [N m], default as they are),
        unchecked: values may be traced or carry batch axes."""
        return self._with(tip_force=force, tip_moment=self.tip_moment if moment is None else moment)

    def with_scene(self, scene) -> Loads:
        """The same loads with the obstacles ``scene`` (a checked Scene, or None)."""
        return self._with(scene=scene)

    def with_point(self, s, force, moment=None) -> Loads:
        """These loads with one more point load: force [N] (3,) and moment [N m] (3,), default
        none, at arc length s [m] (values may be traced)."""
        moment = jnp.zeros(3) if moment is None else moment
        return self._with(
            point_s=jnp.append(jnp.asarray(self.point_s, float), s),
            point_force=jnp.concatenate([jnp.reshape(self.point_force, (-1, 3)), jnp.reshape(force, (1, 3))]),
            point_moment=jnp.concatenate([jnp.reshape(self.point_moment, (-1, 3)), jnp.reshape(moment, (1, 3))]),
        )

    def scaled(self, lam) -> Loads:
        """Every load times lam (the solver's load continuation); the scene as it is."""
        names = ("tip_force", "tip_moment", "point_force", "point_moment", "distributed_force")
        return self._with(**{name: lam * getattr(self, name) for name in names})


class TipLoad:
    """Deprecated: ``TipLoad(force, moment)`` is ``Loads(tip_force=force, tip_moment=moment)``."""

    def __new__(cls, force=(0.0, 0.0, 0.0), moment=(0.0, 0.0, 0.0)) -> Loads:
        deprecated("tdct.TipLoad(force, moment)", "tdct.Loads(tip_force=force, tip_moment=moment)")
        return Loads(tip_force=force, tip_moment=moment)

    @staticmethod
    def from_mass(mass, gravity=STANDARD_GRAVITY) -> Loads:
        deprecated("tdct.TipLoad.from_mass", "tdct.Loads.from_mass")
        return Loads.from_mass(mass, gravity)


def gravity_vector(gravity):
    """World gravity [m/s^2] as a (3,) array; None means none (the robot's weight switched off)."""
    if gravity is None:
        return np.zeros(3)
    g = as_array("gravity", gravity, (3,))
    if not is_concrete(g):
        return jnp.asarray(g, dtype=float)
    note = plausibility_note("gravity", np.linalg.norm(g), "|gravity|")
    if note:
        warn_user(note, UnitWarning)
    return g
