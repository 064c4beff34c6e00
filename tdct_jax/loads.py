"""What is done to the robot: tendon tensions and tube insertion (Actuation), tip load (TipLoad)."""

from __future__ import annotations

import dataclasses

import jax
import numpy as np

from ._checks import as_array, check_range, is_concrete

STANDARD_GRAVITY = (0.0, -9.81, 0.0)
"""World gravity [m/s^2]: the robot is mounted horizontally, gravity along -y."""


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Actuation:
    """Joint-space inputs.

    Attributes:
        tensions: tendon tensions tau_t >= 0 [N], shape (n_tendons,), tendon 1 first.
        insertion: Nitinol tube insertion depth d from the base [m], in [0, L] (checked by solve).
    """

    tensions: tuple = (0.0, 0.0, 0.0, 0.0)
    insertion: float = 0.0

    def __post_init__(self):
        t = self.tensions
        if is_concrete(t):
            t = as_array("tensions", t, (np.asarray(t).size,))
            check_range("tensions", t, 0.0, unit=" N")
        object.__setattr__(self, "tensions", t)
        d = as_array("insertion", self.insertion, ())
        check_range("insertion", d, 0.0, unit=" m")
        object.__setattr__(self, "insertion", d)


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class TipLoad:
    """External load at the tip, world frame.

    Attributes:
        force: tip force F_e [N], shape (3,).
        moment: tip moment M_e [N m], shape (3,).
    """

    force: tuple = (0.0, 0.0, 0.0)
    moment: tuple = (0.0, 0.0, 0.0)

    def __post_init__(self):
        object.__setattr__(self, "force", as_array("force", self.force, (3,)))
        object.__setattr__(self, "moment", as_array("moment", self.moment, (3,)))

    @classmethod
    def from_mass(cls, mass: float, gravity=STANDARD_GRAVITY) -> TipLoad:
        """The weight of a tip mass [kg] under ``gravity`` [m/s^2]."""
        mass = as_array("mass", mass, ())
        check_range("mass", mass, 0.0, unit=" kg")
        return cls(force=mass * as_array("gravity", gravity, (3,)))
