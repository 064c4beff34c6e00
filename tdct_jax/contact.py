"""Frictionless contact with a ``Scene`` inside shooting: candidates, forces, complementarity
(issue 26; docs/model.md, "Contact").

Contact candidates sit at every ``scene.every``-th RK4 node along the body (not the base) and at
the tip: n_c = ceil(P steps / every) of them for P breakpoint intervals of ``steps`` RK4 steps
(static). The integration pieces are cut so that each interior candidate is a piece start
(``rod.pieces``). At candidate j and obstacle o the unknown normal force lambda_jo >= 0 pushes
the centreline point p_j along the obstacle's outward normal n_o(p_j), a point force

    N(s_j+) = N(s_j-) - F_j,   F_j = sum_o lambda_jo n_o(p_j),   M continuous,

and at the tip it enters the tip condition, N(L) = F_e + F_tip. The gap is the obstacle's signed
distance less the body's outer radius there, g_jo = d_o(p_j) - r(s_j). Each pair adds one
unknown, lambda_jo / F_c, and one residual row, Fischer and Burmeister's

    phi(a, b) = a + b - sqrt(a^2 + b^2),   a = lambda_jo / F_c,   b = g_jo / L,

zero iff a >= 0, b >= 0 and a b = 0: the force pushes, the body does not penetrate, and only a
touching point carries force (the same function ``rod.closing`` uses for slack tendons).
Newton starts contact free (lambda = 0). A candidate inside a zero-length breakpoint interval
(e.g. a tube at depth 0) shares its point with the next one: its row is a itself (no force).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax


class Contact(NamedTuple):
    """The contacts of a solution with a scene (``Solution.contact``), n_c candidates along the
    body (the last one the tip) and n_o obstacles.

    Attributes:
        s: the candidates' arc lengths [m], (n_c,).
        position: their centreline points [m], world frame, (n_c, 3).
        gap: distance from the body's surface to each obstacle [m], (n_c, n_o): the obstacle's
            signed distance of the centreline point less the body's outer radius there.
        force: normal force magnitudes [N], (n_c, n_o): >= 0, exactly 0 where not touching.
        normal: each obstacle's outward unit normal at the point, (n_c, n_o, 3): the direction in
            which the obstacle pushes the robot.
        wrench: the force [N] and moment about the world origin [N m] that the robot exerts on
            each obstacle, (n_o, 6).
        active: where force pushes (the complementarity's force side wins), (n_c, n_o), bool.
    """

    s: jax.Array
    position: jax.Array
    gap: jax.Array
    force: jax.Array
    normal: jax.Array
    wrench: jax.Array
    active: jax.Array


class Starts(NamedTuple):
    """What ``rod.integrate`` records at each piece's start: the position [m] (3,) and the
    gaps to every obstacle [m] (n_o,)."""

    p: jax.Array
    gap: jax.Array


class Candidates(NamedTuple):
    """The contact candidates inside shooting, the tip last: forces lambda [N] (n_c, n_o), gaps
    [m] (n_c, n_o) and ``off`` (n_c,), True for a candidate inside a zero-length interval."""

    force: jax.Array
    gap: jax.Array
    off: jax.Array


def n_candidates(P: int, steps: int, every: int) -> int:
    """Candidates along a robot of P breakpoint intervals of ``steps`` RK4 steps: the nodes every
    ``every`` steps from the base, the base excluded, and the tip."""
    return (P * steps - 1) // every + 1


def interior_pieces(P: int, steps: int, g: int, every: int) -> np.ndarray:
    """The pieces (of g steps, ``rod.pieces``) whose starts are the interior candidates."""
    nodes = every * np.arange(1, n_candidates(P, steps, every))
    return nodes // g


SMOOTHING = (1e-3, 1e-5)
"""mu of the smoothed solves that follow where plain Newton from the contact-free start fails
(``shooting._root``), each from the last root, the exact one last: phi_mu = 0 iff a, b > 0 and
a b = mu^2, a root near the exact one. Newton from the contact-free start can wander among
contact sets: the paper robot bent onto a plane with a candidate every RK4 step failed after 306
steps with the load continuation alone; with (1e-3,) the exact solve from the smoothed root still
failed; with these it converges (benchmarks/contact_speed.py)."""


def fischer_burmeister(a, b, mu=0.0):
    """phi(a, b) = a + b - sqrt(a^2 + b^2 + 2 mu^2): for mu = 0 zero iff a >= 0, b >= 0 and a b = 0
    (with a finite gradient, 1 in a and 0 in b, at a = b = 0)."""
    return a + b - jnp.sqrt(a**2 + b**2 + 2 * mu**2 + 1e-300)


def residual(touch: Candidates, F_c, L, mu=0.0):
    """The contact rows of the shooting residual, candidate by candidate, (n_c * n_o,), smoothed by mu."""
    a, b = touch.force / F_c, touch.gap / L
    return jnp.where(touch.off[:, None], a, fischer_burmeister(a, b, mu)).reshape(-1)


def at_start(scene, force, p, radius):
    """The point force sum_o lambda_o n_o(p) [N] (3,) that the obstacles exert at the centreline
    point p with the normal forces ``force`` (n_o,), and the Starts there (gaps for a body of
    outer ``radius`` [m])."""
    return force @ scene.normals(p), Starts(p, scene.distances(p) - radius)


def outputs(scene, s, p, touch: Candidates, F_c, L) -> Contact:
    """The Contact at the candidates' arc lengths s (n_c,) and points p (n_c, 3)."""
    normal = lax.map(scene.normals, p)
    gap = touch.gap
    a, b = touch.force / F_c, gap / L
    # at the root a or b is zero to round-off; a slack candidate's force is reported as exactly 0
    active = (a > b) & ~touch.off[:, None]
    force = jnp.where(active, touch.force, 0.0)
    F = force[..., None] * normal  # on the robot
    wrench = jnp.concatenate([-jnp.sum(F, 0), -jnp.sum(jnp.cross(p[:, None], F), 0)], -1)
    return Contact(s, p, gap, force, normal, wrench, active)
