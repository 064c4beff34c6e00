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
