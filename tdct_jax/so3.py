"""Rotation helpers: skew matrices and the projection that keeps R on SO(3). No physics."""

import jax.numpy as jnp


def hat(x):
    """Skew matrix x^ with x^ y = x cross y; x has shape (..., 3)."""
    x0, x1, x2 = x[..., 0], x[..., 1], x[..., 2]
    z = jnp.zeros_like(x0)
    return jnp.stack([jnp.stack([z, -x2, x1], -1), jnp.stack([x2, z, -x0], -1), jnp.stack([-x1, x0, z], -1)], -2)


def orthonormalize(R):
    """One Newton-Schulz step toward the nearest rotation: R (3 I - R^T R) / 2.

    An RK4 step leaves R off SO(3) by O(h^5); one step squares that error, so applied after every
    step it holds |R^T R - I| at round-off without changing the integrator's order.
    """
    return R @ (1.5 * jnp.eye(3) - 0.5 * (R.T @ R))


def rotation_columns(dR, R):
    """Columns vee(dR_k R^T) of the world-frame rotation vectors of the derivatives dR (3, 3, k) of R."""
    A = jnp.einsum("ijk,lj->ilk", dR, R)
    return jnp.stack([A[2, 1], A[0, 2], A[1, 0]])


def vee_skew(Q):
    """vee of the skew part of Q (..., 3, 3): the rotation vector of Q to first order."""
    return 0.5 * jnp.stack([Q[..., 2, 1] - Q[..., 1, 2], Q[..., 0, 2] - Q[..., 2, 0], Q[..., 1, 0] - Q[..., 0, 1]], -1)


def cayley(w):
    """The Cayley map (I - w^/2)^-1 (I + w^/2) of rotation vectors w (..., 3): exactly a rotation,
    equal to exp(w^) to first order."""
    W = hat(w)
    c = 4 / (4 + jnp.sum(w**2, -1))[..., None, None]
    return jnp.broadcast_to(jnp.eye(3), W.shape) + c * (W + W @ W / 2)
