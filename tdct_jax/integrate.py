"""Fixed-step RK4 as a lax.scan, so that the step lengths (the segment ends) can be traced inputs."""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jax import lax


def _axpy(a, x, y):
    return jax.tree.map(lambda xi, yi: yi + a * xi, x, y)


def rk4(f, y0, h, params, steps: int, project=None, path: bool = False):
    """Integrates y' = f(p, y) over consecutive pieces, piece j in ``steps`` classical RK4 steps of
    length h[j] with parameters p[j] (one compiled vector field for them all).

    A scan over the pieces runs a scan over each piece's steps, so that inside a piece its
    parameters are constants (what the vector field derives from them is computed once a piece)
    and the step loop touches no per-step copies of them: XLA:CPU runs a loop body whose
    operations all touch at most 512 bytes as a plain sequence, and hands a body with a larger
    operand to its thread pool, step by step (docs/performance.md, "Where the time goes").

    Args:
        f: vector field (p, y) -> y' on a pytree state.
        y0: the state at the start.
        h: step length of each piece, (pieces,) (traced; a zero step gives the state back).
        params: pytree of the vector field's parameters, each leaf with a leading axis of length
            pieces, e.g. the segments (None where f needs none).
        steps: RK4 steps per piece (static).
        project: optional map applied to the state after each step (e.g. back onto SO(3)).
        path: also return the states at all pieces * steps + 1 nodes (leading axis).

    Returns:
        The final state, and the stacked path when ``path`` is True.
    """
    nodes = jnp.array([0.0, 0.5, 0.5, 1.0])
    weights = jnp.array([1.0, 2.0, 2.0, 1.0]) / 6

    def piece(y, hp):
        h, p = hp

        def step(y, _):
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

        return lax.scan(step, y, None, length=steps)

    y1, ys = lax.scan(piece, y0, (h, params))
    if not path:
        return y1
    return y1, jax.tree.map(lambda a, b: jnp.concatenate([a[None], b.reshape(b.shape[0] * b.shape[1], *b.shape[2:])]), y0, ys)
