"""Fixed-step RK4 for one segment, as a lax.scan so the segment ends can be traced inputs."""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jax import lax


def _axpy(a, x, y):
    return jax.tree.map(lambda xi, yi: yi + a * xi, x, y)


def rk4(f, y0, s0, s1, steps: int, project=None, path: bool = False):
    """Integrates y' = f(s, y) from s0 to s1 in ``steps`` classical RK4 steps.

    Args:
        f: vector field (s, y) -> y' on a pytree state.
        y0: state at s0.
        s0, s1: segment ends (traced; s1 == s0 gives y0 back).
        steps: number of steps (static).
        project: optional map applied to the state after each step (e.g. back onto SO(3)).
        path: also return the states at all steps + 1 nodes (leading axis).

    Returns:
        The state at s1, and the stacked path when ``path`` is True.
    """
    h = (s1 - s0) / steps

    nodes = jnp.array([0.0, 0.5, 0.5, 1.0])
    weights = jnp.array([1.0, 2.0, 2.0, 1.0]) / 6

    def step(y, i):
        s = s0 + i * h

        def stage(j, c):
            incr, k = c
            k = f(s + nodes[j] * h, _axpy(nodes[j] * h, k, y))
            return _axpy(weights[j], k, incr), k

        zero = jax.tree.map(jnp.zeros_like, y)
        incr, _ = lax.fori_loop(0, 4, stage, (zero, zero))
        y = _axpy(h, incr, y)
        if project is not None:
            y = project(y)
        return y, (y if path else None)

    y1, ys = lax.scan(step, y0, jnp.arange(steps))
    if not path:
        return y1
    return y1, jax.tree.map(lambda a, b: jnp.concatenate([a[None], b]), y0, ys)
