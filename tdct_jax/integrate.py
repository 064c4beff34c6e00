"""Fixed-step RK4 as a lax.scan, so that the step length (from the breakpoints) can be a traced input."""

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


def rk4(f, y0, h, steps: int, project=None, path: bool = False, xs=None):
    """Integrates y' = f(y) in ``steps`` classical RK4 steps of length h: a ``lax.scan`` of the
    steps, each a loop of its four stages (rod.py scans the pieces between breakpoints, each
    with its own parameters, and calls this for each).

    The step loop touches no per-step copies of the vector field's parameters: XLA:CPU runs a
    loop body whose operations all touch at most 512 bytes as a plain sequence, and hands a body
    with a larger operand to its thread pool, step by step (docs/performance.md, "Where the time
    goes").

    Args:
        f: vector field y -> y' on a pytree state.
        y0: the state at the start, ``coupled`` to h and to f's parameters where they may be
            batched or differentiated (rod.py couples the state once, before its scan of the pieces).
        h: the step length (traced; a zero step gives the state back).
        steps: RK4 steps (static).
        project: optional map applied to the state after each step (e.g. back onto SO(3)); with
            ``xs``, called as project(y, x) with the step's slice x of xs.
        path: also return the states at all steps + 1 nodes (leading axis).
        xs: optional per-step data for ``project`` (a pytree with leading axis ``steps``).

    Returns:
        The final state, and the stacked path when ``path`` is True.
    """
    after = jnp.array([0.5, 0.5, 1.0, 0.0])  # where stage j + 1 evaluates, in steps from y
    weights = jnp.array([1.0, 2.0, 2.0, 1.0]) / 6

    def step(y, x):
        # the loop carries the sum so far and the next stage's point, both starting at y: no
        # zeros to start from, which ``vmap`` and ``jax.jvp`` would trace the stages again to
        # find batched and differentiated (``coupled``)
        def stage(j, c):
            total, point = c
            k = f(point)
            return _axpy(h * weights[j], k, total), _axpy(h * after[j], k, y)

        y, _ = lax.fori_loop(0, 4, stage, (y, y))
        if project is not None:
            y = project(y) if xs is None else project(y, x)
        return y, (y if path else None)

    y1, ys = lax.scan(step, y0, xs, length=steps)
    if not path:
        return y1
    return y1, jax.tree.map(lambda a, b: jnp.concatenate([a[None], b]), y0, ys)
