"""Fixed-step RK4 as a lax.scan, so that the step lengths (the segment ends) can be traced inputs."""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jax import lax


def _axpy(a, x, y):
    return jax.tree.map(lambda xi, yi: yi + a * xi, x, y)


def rk4(f, y0, h, params, project=None, path: bool = False):
    """Integrates y' = f(p, y) in classical RK4 steps, step k of length h[k] with parameters p[k].

    Args:
        f: vector field (p, y) -> y' on a pytree state.
        y0: the state at the start.
        h: step lengths, (steps,) (traced; a zero step gives the state back).
        params: pytree of the vector field's parameters, each leaf with a leading axis of length
            steps, e.g. the segment each step lies in (one compiled vector field for them all).
        project: optional map applied to the state after each step (e.g. back onto SO(3)).
        path: also return the states at all steps + 1 nodes (leading axis).

    Returns:
        The final state, and the stacked path when ``path`` is True.
    """
    nodes = jnp.array([0.0, 0.5, 0.5, 1.0])
    weights = jnp.array([1.0, 2.0, 2.0, 1.0]) / 6

    def step(y, hp):
        h, p = hp

        def stage(j, c):
            incr, k = c
            k = f(p, _axpy(nodes[j] * h, k, y))
            return _axpy(weights[j], k, incr), k

        zero = jax.tree.map(jnp.zeros_like, y)
        incr, _ = lax.fori_loop(0, 4, stage, (zero, zero))
        y = _axpy(h, incr, y)
        if project is not None:
            y = project(y)
        return y, (y if path else None)

    y1, ys = lax.scan(step, y0, (h, params))
    if not path:
        return y1
    return y1, jax.tree.map(lambda a, b: jnp.concatenate([a[None], b]), y0, ys)
