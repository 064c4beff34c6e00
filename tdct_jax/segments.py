"""The Cosserat rod of rod plus tendons: its state, the constitutive relations solved for the
strains, and the paper's printed terms (eqs. 1 and 23-36; docs/model.md); rod.py assembles the
vector field from them, interval by interval.

Both segments carry the same state: position p, rotation R (body to world), and the *total*
internal force N = n + sum_t tau_t t_t and moment M = m + sum_t (R r_t) x tau_t t_t of rod plus
tendons, in the world frame (n, m: the rod's own; t_t: tendon t's unit tangent). Tendon forces
are internal to rod plus tendons, so

    N' = -f,        M' = -p' x N - l,                       f = rho g (gravity), l = 0,

which is the Rucker-Webster model (eq. 1) and the backbone model (eqs. 23-26) before they are
differentiated into a linear system for the strains: given (R, N, M), the strains (v, u) solve the
constitutive relations

    R^T N = K_se (v - e3) + sum_t tau_t pb_t / |pb_t|,
    R^T M = K_bt u        + sum_t tau_t r_t x pb_t / |pb_t|,     pb_t = u x r_t + v,

by a few Newton steps (their Jacobian is the symmetric matrix of eq. 1). In the backbone segment
the tube forbids shear: v = (0, 0, v_z), and the two shear rows of the force relation drop out
(eqs. 16-17). Written this way the balanced transition is plain continuity of the state, the tip
condition is N(L) = F_e, M(L) = M_e, and RK4 conserves the global force balance exactly.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from .linalg import solve_spd, solve_spd_entries
from .so3 import hat, orthonormalize

E3 = np.array([0.0, 0.0, 1.0])


class State(NamedTuple):
    """Rod state along s: p (3,) [m], R (3, 3), total force N (3,) [N], total moment M (3,) [N m].

    RK4 carries it as it is (``SolverOptions.rotation`` "matrix") or as ``Carried`` ("columns");
    the vector field reads R through the methods both have."""

    p: jax.Array
    R: jax.Array
    N: jax.Array
    M: jax.Array

    def world(self, w):
        """R w of a body-frame vector w."""
        return self.R @ w

    def body(self, w):
        """R^T w of a world-frame vector w."""
        return self.R.T @ w

    def rate(self, dp, u, dN, dM) -> State:
        """d/ds of this state: p' = dp, R' = R u^, N' = dN, M' = dM."""
        return State(dp, self.R @ hat(u), dN, dM)

    def orthonormalized(self) -> State:
        return self._replace(R=orthonormalize(self.R))


class Carried(NamedTuple):
    """A State with R by its columns R e_1, R e_2, R e_3 (world frame), each an array of its own.
    With R whole, a Jacobian pass in more than 7 directions (the IK's 11) holds R's tangents in
    one array over XLA:CPU's 512-byte limit for running a loop body in sequence, and every RK4
    step goes through its thread pool (benchmarks/README.md, "R by its columns in the RK4 scan")."""

    p: jax.Array
    R1: jax.Array
    R2: jax.Array
    R3: jax.Array
    N: jax.Array
    M: jax.Array

    def world(self, w):
        return self.R1 * w[0] + self.R2 * w[1] + self.R3 * w[2]

    def body(self, w):
        return jnp.stack([_dot(self.R1, w), _dot(self.R2, w), _dot(self.R3, w)])

    def rate(self, dp, u, dN, dM) -> Carried:
        """As ``State.rate``: column j of R u^ is R (u x e_j)."""
        R1, R2, R3 = self.R1, self.R2, self.R3
        return Carried(dp, R2 * u[2] - R3 * u[1], R3 * u[0] - R1 * u[2], R1 * u[1] - R2 * u[0], dN, dM)

    def orthonormalized(self) -> Carried:
        """``so3.orthonormalize`` on the columns: R_j (3/2) - (1/2) sum_i R_i (R_i . R_j)."""
        R = (self.R1, self.R2, self.R3)
        G = [[_dot(R[i], R[j]) for j in range(3)] for i in range(3)]
        R1, R2, R3 = (1.5 * R[j] - 0.5 * (R[0] * G[0][j] + R[1] * G[1][j] + R[2] * G[2][j]) for j in range(3))
        return self._replace(R1=R1, R2=R2, R3=R3)


def _dot(a, b):
    """a . b of 3-vectors, written out so that XLA fuses it rather than calling a dot kernel."""
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def carried(y: State, rotation: str | None = None):
    """The state RK4 carries for ``SolverOptions.rotation``: y itself ("matrix"), else Carried."""
    return y if rotation == "matrix" else Carried(y.p, y.R[..., 0], y.R[..., 1], y.R[..., 2], y.N, y.M)


def uncarried(c) -> State:
    """The State of what ``carried`` gave (leading axes kept: a path's nodes)."""
    return c if isinstance(c, State) else State(c.p, jnp.stack([c.R1, c.R2, c.R3], -1), c.N, c.M)


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Segment:
    """One segment's section and tendons.

    Attributes:
        K_se: shear/extension stiffness diagonal [N], (3,).
        K_bt: bending/torsion stiffness diagonal [N m^2], (3,).
        rho: linear density [kg/m].
        tau: tendon tensions [N], (n_t,).
        r: body-frame tendon offsets [m], (n_t, 3).
        backbone: 1.0 where the tube is inside (no shear), 0.0 in the silicone-only segment (a
            leaf, so that both segments run through one compiled vector field).
        tilt: tendon tangents follow pb_t = u x r_t + v ("exact"); False uses t_t = e3, the printed
            eqs. 21-22 ("paper" backbone option). Static.
        dr: body-frame r_t' of helical tendons, (n_t, 3), adding to pb_t; None (default): straight
            tendons (r_t' = 0), and nothing is added.
    """

    K_se: jax.Array
    K_bt: jax.Array
    rho: jax.Array
    tau: jax.Array
    r: jax.Array
    backbone: jax.Array
    tilt: bool = dataclasses.field(metadata=dict(static=True), default=True)
    dr: jax.Array | None = None


NEWTON_STEPS = 2
"""Newton steps on the constitutive relations from the tilt-free guess. Over the operating envelope
a third step moves the tip by at most 1e-13 m (benchmarks/accuracy_steps.py) and costs a third
more per evaluation."""


def tendon_tangents(seg: Segment, v, u):
    """Body-frame unit tangents t_t of the tendons, (n_t, 3)."""
    if not seg.tilt:
        return jnp.broadcast_to(E3, seg.r.shape)
    pb = tendon_pb(seg, v, u)
    return pb / jnp.linalg.norm(pb, axis=-1, keepdims=True)


def tendon_pb(seg: Segment, v, u):
    """Unnormalised body-frame tendon tangents pb_t = u x r_t + r_t' + v, (n_t, 3)."""
    pb = jnp.cross(u[None], seg.r) + v[None]
    return pb if seg.dr is None else pb + seg.dr


def strains(seg: Segment, R, N, M):
    """Solves the constitutive relations for (v, u) given the world-frame totals N, M."""
    return body_strains(seg, R.T @ N, R.T @ M)


def strains_at(seg: Segment, y: State | Carried):
    """``strains`` at a state as RK4 carries it."""
    return body_strains(seg, y.body(y.N), y.body(y.M), isinstance(y, Carried))


def body_strains(seg: Segment, bf, bm, split: bool = False):
    """(v, u) given the body-frame totals bf = R^T N, bm = R^T M (``split``: ``_constitutive``)."""
    if not seg.tilt:
        return _tilt_free(seg, bf, bm)
    w = _constitutive(split, seg, bf, bm)
    return w if split else (w[:3], w[3:])


def _tilt_free(seg: Segment, bf, bm):
    """(v, u) with every tendon tangent e3: exact for the "paper" tendon model, else Newton's guess."""
    tau = seg.tau
    v = E3 + (bf - jnp.sum(tau) * E3) / seg.K_se
    v = jnp.where(seg.backbone > 0, v * E3, v)
    u = (bm - jnp.sum(tau[:, None] * jnp.cross(seg.r, E3[None]), axis=0)) / seg.K_bt
    return v, u


def _residual_and_jacobian(seg: Segment, w, bf, bm, split: bool):
    """The constitutive relations F(w) = 0 for w = (v, u) (with ``split``: as (force rows, moment
    rows)) and their Jacobian (eq. 1), symmetric positive definite: diag(K_se, K_bt) +
    sum_t [I; r_t^]^T P_t [I; r_t^] with P_t >= 0.

    In the backbone the shear rows and columns are replaced by the identity (v_x = v_y = 0).
    """
    v, u = w[:3], w[3:]
    tau = seg.tau
    pb = tendon_pb(seg, v, u)
    norm = jnp.linalg.norm(pb, axis=-1)
    t = pb / norm[:, None]
    F_force, F_moment = seg.K_se * (v - E3) + tau @ t - bf, seg.K_bt * u + tau @ jnp.cross(seg.r, t) - bm
    rh = hat(seg.r)
    P = (tau / norm)[:, None, None] * (jnp.eye(3)[None] - t[:, :, None] * t[:, None, :])
    PW = P @ rh
    J = jnp.block(
        [
            [jnp.diag(seg.K_se) + P.sum(0), -PW.sum(0)],
            [(rh @ P).sum(0), jnp.diag(seg.K_bt) - (rh @ PW).sum(0)],
        ]
    )
    shear = 1.0 - seg.backbone
    keep = jnp.stack([shear, shear, *jnp.ones(4)])
    J = J * keep[:, None] * keep[None, :] + jnp.diag(1.0 - keep)
    return ((F_force * keep[:3], F_moment) if split else jnp.concatenate([F_force, F_moment]) * keep), J


@functools.partial(jax.custom_jvp, nondiff_argnums=(0,))
def _constitutive(split: bool, seg: Segment, bf, bm):
    """w = (v, u) solving the constitutive relations, by NEWTON_STEPS Newton steps from the
    tilt-free guess; with ``split`` as (v, u), tangents too: under forward mode in 11 directions
    (the IK's) w's tangents would make an array over XLA:CPU's 512-byte limit (``Carried``), while
    a vmapped CPU batch runs faster with w whole."""

    def newton_step(_, w):
        F, J = _residual_and_jacobian(seg, w, bf, bm, split)
        return w - solve_spd(J, jnp.concatenate(F) if split else F)

    w = lax.fori_loop(0, NEWTON_STEPS, newton_step, jnp.concatenate(_tilt_free(seg, bf, bm)))
    return (w[:3], w[3:]) if split else w


@_constitutive.defjvp
def _constitutive_jvp(split, primals, tangents):
    """Implicit differentiation at the converged strains: dw = -J^-1 (dF/d inputs) d inputs."""
    seg, bf, bm = primals
    out = _constitutive(split, seg, bf, bm)
    w = jnp.concatenate(out) if split else out
    (_, J), (dF, _) = jax.jvp(lambda seg, bf, bm: _residual_and_jacobian(seg, w, bf, bm, split), primals, tangents)
    if not split:
        return out, -solve_spd(J, dF)
    dw = solve_spd_entries(J, [-f[..., i] for f in dF for i in range(3)])
    return out, (jnp.stack(dw[:3], -1), jnp.stack(dw[3:], -1))


def rod_force(seg: Segment, y: State, v, u):
    """The rod's own internal force n and moment m (world frame) from the totals."""
    t = tendon_tangents(seg, v, u)
    f_t = seg.tau[:, None] * t
    n = y.N - y.R @ jnp.sum(f_t, 0)
    m = y.M - y.R @ jnp.sum(jnp.cross(seg.r, f_t), 0)
    return n, m


def printed_moment(seg: Segment, u):
    """What eq. 26 as printed adds to M' (body frame): it is not the derivative of a total moment
    (zero unless the robot twists; docs/model.md, segment "backbone")."""
    return jnp.sum(seg.tau[:, None] * jnp.cross(E3[None], jnp.cross(u[None], seg.r)), 0)


def paper_transition(back: Segment, sil: Segment, y: State) -> State:
    """Eqs. 31-36 as printed: the rod's n, m continuous, so the total force jumps by the tendons'."""
    v, u = strains(back, y.R, y.N, y.M)
    n, m = rod_force(back, y, v, u)
    v1 = E3 + (y.R.T @ n) / sil.K_se
    u1 = (y.R.T @ m) / sil.K_bt
    f_t = sil.tau[:, None] * tendon_tangents(sil, v1, u1)
    return State(y.p, y.R, n + y.R @ jnp.sum(f_t, 0), m + y.R @ jnp.sum(jnp.cross(sil.r, f_t), 0))
