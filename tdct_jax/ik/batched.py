"""Many targets: a batch of them through the batch engine (or one vmap when traced), and a
sequence of them tracked as one compiled scan."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from .. import status
from ..batch import Kernel, batch_solver, default_chunk_size, lanes_per_call, run_batched
from ..checks import is_concrete
from .driver import _solve_ik, rank
from .problem import IKResult, Plan, Problem, scaled_inputs
from .reach import _where, no_model
from .starts import STARTS

CHUNK_SIZE = 64
"""Targets per compiled call of a batched IK on the CPU (other platforms: ``batch.CHUNK_SIZES``).
Targets that miss from their first start try their other starts, a start a lane (``_retry``), in
calls of this many lanes so as to reuse the compiled program: a round trip over 1,000 targets took
81 s at 256 lanes against 55 s at 64 (tests/test_ik.py, compile included); with the grid start
since, 51 s at 64 (quiet, 2026-11-26)."""
RETRY_LANES = 1024
"""Lanes per compiled call of the retry pass at most: it reuses the first pass's program where
that has no more lanes (the CPU's 64), and otherwise compiles one of this size. A vmapped retry
costs what its lanes cost, not its misses: on one H100, 30 misses padded to the first pass's
8,192 lanes took 37 s, 4 misses over 1,024 lanes 2.3 s; on the CPU with 256-lane chunks, one miss
over 256 lanes 71 s, over 32 lanes 10 s (benchmarks/README.md)."""


def _batched(prob: Problem, plan: Plan, v0, wrench0) -> IKResult:
    """Many targets (a leading axis on ``prob.target``, and on the load's tip force and moment when
    it has one). With concrete values they run through the batch engine in chunks, each target from
    its first start only; those that did not reach run again, each of their other starts in a lane
    of its own of the same compiled program (``_retry``), so that a few hard targets do not hold up
    the rest. Traced (inside the caller's jit or vmap): one vmap, every start."""
    loads = jnp.ndim(prob.load.tip_force) == 2
    per = (prob.target, (prob.load.tip_force, prob.load.tip_moment) if loads else None)
    if not all(is_concrete(x) for x in jax.tree.leaves((prob, v0))):
        return jax.vmap(lambda per, v: _solve_ik(_one(prob, per), v, wrench0, plan)[0])(per, v0)
    leaves, tree = jax.tree.flatten(per)
    own = tuple(i for i, leaf in enumerate(leaves) if np.ndim(leaf) >= 1)  # the rest (weights) are shared
    points = {f"in{i}": np.asarray(leaves[i]) for i in own} | {"v0": np.asarray(v0)}
    kernel = Kernel(_ik_point, (("plan", plan), ("tree", tree), ("own", own)))
    prob = prob._replace(solver=batch_solver(prob.solver))
    # the load's other fields are shared: the base holds them (the tip's, the first target's, replaced)
    load = prob.load.with_tip(prob.load.tip_force[0], prob.load.tip_moment[0]) if loads else prob.load
    base = (prob._replace(target=None, load=load), wrench0, leaves)
    chunk = CHUNK_SIZE if jax.default_backend() == "cpu" else default_chunk_size()
    n = len(v0)
    out = run_batched(kernel, base, points | _tries(np.zeros(n, np.int32)), chunk_size=chunk, progress=False)
    # a target that phase 1 reached from its first start gets the same answer from every start (the
    # next is tried only after one falls short), e.g. one whose phase 2 ran out of steps: not run again
    again = np.flatnonzero((out[".result"] != status.SUCCESS) & ~out["reached"])
    if again.size:  # in whole calls of ``lanes``, the first pass's where it has no more than RETRY_LANES
        lanes = min(lanes_per_call(n, chunk), RETRY_LANES)

        def run(rows, first):
            pad = -rows.size % lanes
            rows, first = (np.concatenate([a, np.full(pad, a[-1])]) for a in (rows, first))
            got = run_batched(
                kernel, base, {k: v[rows] for k, v in points.items()} | _tries(first), chunk_size=lanes, progress=False
            )
            return {k: v[: rows.size - pad] for k, v in got.items()}

        _retry(out, again, run)
    names, tree = RESULT_TREES[kernel, jax.tree.structure(base)]
    return jax.tree.unflatten(tree, [jnp.asarray(out[name]) for name in names])


def _tries(first):
    """The kernel's start inputs: each lane tries the one start ``first``."""
    return {"first": first, "stop": first + 1}


RETRY_ROUNDS = ((1,), tuple(range(2, STARTS)))
"""The retry's rounds of starts: the grid start, then the others for the targets it did not bring
to the target. A vmapped call lasts as long as its slowest lane, and a start that ``find`` would
not have tried (one after a start that reached) can run to its step limit: on the paper robot's
1,000-target round trip (``tests/test_ik.py``) the grid start reached 8 of its 9 misses within 15
steps, while starts after it took up to 60."""


def _retry(out: dict, again, run) -> None:
    """Targets ``again`` (rows of the first pass's outputs ``out``, from start 0) from their other
    starts, one start a lane, in ``RETRY_ROUNDS``: ``run(rows, first)`` runs the kernel on those
    rows from those starts. Each target then takes what ``find`` trying its starts in turn would
    have ended with: the first start that reached, or else the best end by ``rank`` and |e| (the
    earlier on a tie), with the steps of every start it tried (so the answers are those of one IK
    from every start)."""
    ends = {row: [{k: v[row] for k, v in out.items()}] for row in again}
    for starts in RETRY_ROUNDS:
        todo = [row for row in again if not any(end["reached"] for end in ends[row])]
        if not todo:
            break
        rows = np.repeat(todo, len(starts))
        tried = run(rows, np.tile(np.asarray(starts, np.int32), len(todo)))
        for j, row in enumerate(rows):
            ends[row].append({k: v[j] for k, v in tried.items()})
    for row, its in ends.items():  # its: the row's ends, start by start
        reached = [j for j, end in enumerate(its) if end["reached"]]
        if reached:
            best, used = reached[0], its[: reached[0] + 1]
        else:
            best, used = min(range(len(its)), key=lambda j: (int(rank(its[j]["code"])), float(its[j]["e2"]), j)), its
        for k in out:
            out[k][row] = its[best][k]
        out[".iterations"][row] = sum(int(end[".iterations"]) for end in used)


RESULT_TREES: dict = {}
"""(kernel, its base's tree structure) -> (the names of ``_ik_point``'s outputs, IKResult's tree
structure), recorded when ``_ik_point`` is traced: the batch's IKResult is built from them
without tracing a whole IK again for its shapes (``jax.eval_shape``: 2.1 s of a batch's 11.5 s
first call)."""


def _one(prob: Problem, per) -> Problem:
    """The problem of one target of a batch: its target, and its tip force and moment where each
    has its own (the Loads' only fields with batch axes)."""
    target, tip = per
    load = prob.load if tip is None else prob.load.with_tip(tip[0], tip[1])
    return prob._replace(target=target, load=load)


def _ik_point(base, point, kernel: Kernel) -> dict:
    prob, wrench0, leaves = base
    own = kernel.option("own")
    leaves = [point[f"in{i}"] if i in own else leaf for i, leaf in enumerate(leaves)]
    prob = _one(prob, jax.tree.unflatten(kernel.option("tree"), leaves))
    result, _, _, ended = _solve_ik(prob, point["v0"], wrench0, kernel.option("plan"), tries=(point["first"], point["stop"]))
    paths, tree = jax.tree_util.tree_flatten_with_path(result)
    names = [jax.tree_util.keystr(path) for path, _ in paths]
    RESULT_TREES[kernel, jax.tree.structure(base)] = names, tree
    return {name: leaf for name, (_, leaf) in zip(names, paths, strict=True)} | ended._asdict()


@functools.partial(jax.jit, static_argnames=("plan", "tree", "own"))
def _track(prob, leaves, v0, wrench0, plan, tree, own):
    def step(carry, xs):
        v, wrench, model = carry
        target = jax.tree.unflatten(tree, [xs[own.index(i)] if i in own else leaf for i, leaf in enumerate(leaves)])
        result, *new, _ = _solve_ik(prob._replace(target=target), v, wrench, plan, model=model)
        ok = result.result == status.SUCCESS
        return _where(ok, (scaled_inputs(result.actuation, prob, plan), *new), (v, wrench, model)), result

    return lax.scan(step, (v0, wrench0, no_model(prob, plan)), [leaves[i] for i in own])[1]
