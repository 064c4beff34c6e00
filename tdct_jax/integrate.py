"""Fixed-step RK4 as a lax.scan, so that the step lengths (the segment ends) can be traced inputs."""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jax import lax


def _axpy(a, x, y):
    return jax.tree.map(lambda xi, yi: yi + a * xi, x, y)


def coupled(y, *others):
    """y, each leaf plus 0 times the sum of every leaf of y and ``others`` (where finite): the same
    numbers, but under ``vmap`` and ``jax.jvp`` every leaf of y is batched and has a tangent where
    any of them has, as one step of the integration makes them (the base position and rotation are
    constants; the vector field's parameters reach the state in the first step). A loop whose
    carry starts so is traced once by the batching and differentiation rules, which trace its
    body again for each carry they find batched or differentiated only after it."""
    s = sum(jnp.sum(a) for a in jax.tree.leaves((y, others)))
    zero = 0.0 * jnp.where(jnp.isfinite(s), s, 0.0)
    return jax.tree.map(lambda a: a + zero, y)


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
    y0 = coupled(y0, h, params)
    after = jnp.array([0.5, 0.5, 1.0, 0.0])  # where stage j + 1 evaluates, in steps from y
    weights = jnp.array([1.0, 2.0, 2.0, 1.0]) / 6

    def piece(y, hp):
        h, p = hp

        def step(y, _):
            # the loop carries the sum so far and the next stage's point, both starting at y: no
            # zeros to start from, which ``vmap`` and ``jax.jvp`` would trace the stages again to
            # find batched and differentiated (``coupled``)
            def stage(j, c):
                total, point = c
                k = f(p, point)
                return _axpy(h * weights[j], k, total), _axpy(h * after[j], k, y)

            y, _ = lax.fori_loop(0, 4, stage, (y, y))
            if project is not None:
                y = project(y)
            return y, (y if path else None)

        return lax.scan(step, y, None, length=steps)

    y1, ys = lax.scan(piece, y0, (h, params))
    if not path:
        return y1
    return y1, jax.tree.map(lambda a, b: jnp.concatenate([a[None], b.reshape(b.shape[0] * b.shape[1], *b.shape[2:])]), y0, ys)
