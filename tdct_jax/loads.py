"""What is done to the robot: tendon tensions and tube insertion (Actuation), tip load (TipLoad),
and gravity."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from .checks import UnitWarning, as_array, check_range, is_concrete, plausibility_note, warn_user
from .tree import pytree, set_fields

STANDARD_GRAVITY = (0.0, -9.81, 0.0)
"""World gravity [m/s^2]: the robot is mounted horizontally, gravity along -y."""


def _check_batch(name_a: str, a, name_b: str, b, trailing_a: int, trailing_b: int) -> None:
    """The leading (batch) axes of two leaves are the same, as ``jax.vmap`` needs them."""
    if not (is_concrete(a) and is_concrete(b)):
        return
    sa, sb = np.shape(a)[: np.ndim(a) - trailing_a], np.shape(b)[: np.ndim(b) - trailing_b]
    if sa != sb:
        raise ValueError(
            f"{name_a} has shape {np.shape(a)} and {name_b} {np.shape(b)}: their leading (batch) axes {sa} and {sb} "
            "must be the same (one configuration: no batch axes)"
        )


@pytree
class Actuation:
    """Joint-space inputs; leading batch axes are allowed (e.g. a stack of experiments).

    Attributes:
        tensions: tendon tensions tau_t >= 0 [N], shape (..., n_tendons), tendon 1 first.
        insertion: Nitinol tube insertion depth d from the base [m], shape (...), in [0, L]
            (checked against the robot by every entry point).
    """

    tensions: object = (0.0, 0.0, 0.0, 0.0)
    insertion: object = 0.0

    def __post_init__(self):
        tensions = self.tensions
        if is_concrete(tensions) and np.ndim(tensions) == 0:
            tensions = (tensions,)
        tensions = as_array("tensions", tensions, trailing=(np.shape(tensions)[-1],) if is_concrete(tensions) else None)
        check_range("tensions", tensions, 0.0, unit=" N")
        insertion = as_array("insertion", self.insertion)
        check_range("insertion", insertion, 0.0, unit=" m")
        _check_batch("tensions", tensions, "insertion", insertion, 1, 0)
        set_fields(self, tensions=tensions, insertion=insertion)


@pytree
class TipLoad:
    """External load at the tip, world frame; leading batch axes are allowed.

    Attributes:
        force: tip force F_e [N], shape (..., 3).
        moment: tip moment M_e [N m], shape (..., 3).
    """

    force: object = (0.0, 0.0, 0.0)
    moment: object = (0.0, 0.0, 0.0)

    def __post_init__(self):
        force = as_array("force", self.force, trailing=(3,))
        moment = as_array("moment", self.moment, trailing=(3,))
        _check_batch("force", force, "moment", moment, 1, 1)
        set_fields(self, force=force, moment=moment)

    @classmethod
    def from_mass(cls, mass, gravity=STANDARD_GRAVITY) -> TipLoad:
        """The weight of a tip mass [kg] (shape (...) for a batch) under ``gravity`` [m/s^2]."""
        mass = as_array("mass", mass)
        check_range("mass", mass, 0.0, unit=" kg")
        g = gravity_vector(gravity)
        concrete = is_concrete(mass) and is_concrete(g)
        force = np.multiply.outer(mass, g) if concrete else jnp.einsum("...,i->...i", mass, g)
        return cls(force=force, moment=np.zeros(np.shape(force)))


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
