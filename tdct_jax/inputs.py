"""What is done to a ``GeneralRobot``: tendon tensions and tube insertions (``GeneralActuation``),
and dead loads along the body (``Loads``), all world-frame, all differentiable leaves.

``TipLoad`` (loads.py) stays the shorthand for a tip force and moment; ``Loads.of`` turns one
into a ``Loads``. Gravity stays the solver's ``gravity=`` argument, a vector in any direction.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from .checks import as_array, check_range, is_concrete
from .loads import Actuation, TipLoad
from .scene import Scene
from .tree import pytree, set_fields, static, unchecked


@pytree
class GeneralActuation:
    """Joint-space inputs of a GeneralRobot (one configuration): each tendon driven by its tension
    or, for those listed in ``driven``, by its displacement (the length pulled at the base, what
    its encoder reads); mixed control is allowed.

    Attributes:
        tensions: tension of each tendon [N], shape (n_tendons,), in the robot's tendon order;
            for a displacement-driven tendon, the start of the search (0 is fine).
        insertions: depth of each tube from the base [m], shape (n_tubes,), in [0, L].
        displacements: the commanded displacement of each driven tendon [m], shape (len(driven),):
            its rest length inside the straight robot less its present rest length there (so
            positive when pulled). Its tension is found so that the shape matches; where that
            would take a negative tension the tendon goes slack (tension exactly 0,
            ``GeneralSolution.slack``).
        driven: indices of the displacement-driven tendons (static).
    """

    tensions: object = ()
    insertions: object = ()
    displacements: object = ()
    driven: tuple = static(default=())

    def __post_init__(self):
        tensions = as_array("tensions", self.tensions, (np.size(self.tensions),) if is_concrete(self.tensions) else None)
        check_range("tensions", tensions, 0.0, unit=" N")
        driven = tuple(int(i) for i in self.driven)
        if len(set(driven)) != len(driven) or any(i < 0 for i in driven):
            raise ValueError(f"driven = {self.driven!r}: distinct tendon indices (0 for the first tendon) expected")
        k = len(driven)
        displacements = as_array(
            "displacements", self.displacements, (k,) if is_concrete(self.displacements) else None, unit=" m"
        )
        set_fields(self, driven=driven, displacements=displacements)
        insertions = as_array(
            "insertions", self.insertions, (np.size(self.insertions),) if is_concrete(self.insertions) else None
        )
        check_range("insertions", insertions, 0.0, unit=" m")
        set_fields(self, tensions=tensions, insertions=insertions)

    @classmethod
    def of(cls, act, n_tubes: int) -> GeneralActuation:
        """A GeneralActuation from itself, None (nothing actuated) or a ``tdct.Actuation`` (its
        scalar ``insertion`` is the one tube's depth, or ignored when it is 0 and there are none)."""
        if act is None:
            return cls()
        if isinstance(act, cls):
            return act
        if isinstance(act, Actuation):
            if n_tubes == 1:
                return cls(act.tensions, jnp.reshape(act.insertion, (1,)) if not is_concrete(act.insertion) else [act.insertion])
            if n_tubes == 0 and is_concrete(act.insertion) and float(act.insertion) == 0.0:
                return cls(act.tensions, ())
            raise ValueError(
                f"a tdct.Actuation carries one insertion, the robot has {n_tubes} tubes: use tdct.GeneralActuation(tensions, insertions)"
            )
        raise TypeError(f"act must be a tdct.GeneralActuation or tdct.Actuation, got {type(act).__name__}")

    @classmethod
    def _rebuild(cls, tensions, insertions, displacements, driven) -> GeneralActuation:
        """Built without the checks (inside the solver, from traced values; stacks)."""
        return unchecked(cls, tensions=tensions, insertions=insertions, displacements=displacements, driven=driven)

    def scaled(self, lam) -> GeneralActuation:
        """Tensions and displacements times lam (the solver's load continuation)."""
        return self._rebuild(lam * self.tensions, self.insertions, lam * self.displacements, self.driven)


@pytree
class Loads:
    """Dead loads on the robot, world frame.

    Attributes:
        tip_force: F_e at s = L [N], (3,).
        tip_moment: M_e at s = L [N m], (3,).
        point_s: arc lengths of the point loads [m], (k,), in [0, L].
        point_force: their forces [N], (k, 3).
        point_moment: their moments [N m], (k, 3).
        distributed_force: a force per unit length along the whole body [N/m], (3,) (added to
            the weight).
        scene: the obstacles the robot may touch (a ``tdct.Scene``), or None: a pytree child, so
            the solve's implicit derivatives, ``vmap`` and sweeps reach the obstacles' numbers.
            Not scaled by the load continuation (issue 26; contact.py).
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
        for name in ("tip_force", "tip_moment", "distributed_force"):
            values[name] = as_array(name, getattr(self, name), (3,))
        set_fields(self, point_s=point_s, **values)

    @property
    def n_points(self) -> int:
        return int(np.shape(self.point_s)[0])

    @classmethod
    def of(cls, load) -> Loads:
        """A Loads from itself, None (no load) or a ``TipLoad`` (its tip force and moment)."""
        if load is None:
            return cls()
        if isinstance(load, cls):
            return load
        if isinstance(load, TipLoad):
            return cls(tip_force=load.force, tip_moment=load.moment)
        raise TypeError(f"load must be a tdct.Loads or tdct.TipLoad, got {type(load).__name__}")

    def with_scene(self, scene) -> Loads:
        """The same loads with the obstacles ``scene`` (a checked Scene, or None)."""
        fields = {name: getattr(self, name) for name in self.__dataclass_fields__}
        return unchecked(Loads, **(fields | dict(scene=scene)))

    def with_point(self, s, force, moment=None) -> Loads:
        """These loads with one more point load: force [N] (3,) and moment [N m] (3,), default
        none, at arc length s [m] (values may be traced)."""
        moment = jnp.zeros(3) if moment is None else moment
        fields = {name: getattr(self, name) for name in self.__dataclass_fields__}
        point = dict(
            point_s=jnp.append(jnp.asarray(self.point_s, float), s),
            point_force=jnp.concatenate([jnp.reshape(self.point_force, (-1, 3)), jnp.reshape(force, (1, 3))]),
            point_moment=jnp.concatenate([jnp.reshape(self.point_moment, (-1, 3)), jnp.reshape(moment, (1, 3))]),
        )
        return unchecked(Loads, **(fields | point))

    def scaled(self, lam) -> Loads:
        """Every load times lam (the solver's load continuation); the scene as it is."""
        scaled = {name: lam * getattr(self, name) for name in ("tip_force", "tip_moment", "point_force", "point_moment")}
        return unchecked(Loads, point_s=self.point_s, distributed_force=lam * self.distributed_force, scene=self.scene, **scaled)
