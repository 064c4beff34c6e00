"""Solver behaviour: convergence over the operating envelope, vmap, gradients, no retracing."""

import importlib
import logging
import math
import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import rel_err

import tdct_jax as tdct
from tdct_jax import shooting, status
from tdct_jax.inputs import gravity_vector
from tdct_jax.newton import lazily


def envelope(n, seed=0):
    """Random configurations: 0-10 N on a random subset of tendons, 0-160 mm, 0-0.5 N any direction."""
    rng = np.random.default_rng(seed)
    tensions = rng.uniform(0, 10, (n, 4)) * (rng.random((n, 4)) < 0.5)
    insertion = rng.uniform(0, 0.16, n)
    direction = rng.normal(size=(n, 3))
    force = direction / np.linalg.norm(direction, axis=1, keepdims=True) * rng.uniform(0, 0.5, (n, 1))
    return tensions, insertion, force


def batched_solve(robot):
    def one(tau, d, f):
        return tdct.solve(robot, tdct.Actuation(tau, d), tdct.Loads(tip_force=f))

    return jax.jit(jax.vmap(one))


@pytest.mark.slow
def test_converges_over_the_operating_envelope(robot):
    tensions, insertion, force = envelope(200)
    sol = batched_solve(robot)(tensions, insertion, force)
    failed = int(np.sum(~np.asarray(sol.converged)))
    iters = np.asarray(sol.iterations)
    print(
        f"200 random configurations: {failed} failed; Newton iterations min {iters.min()}, mean {iters.mean():.2f}, max {iters.max()}"
    )
    assert failed == 0
    assert np.asarray(sol.residual_norm).max() <= 1e-10
    # vmap equals one-by-one solves.
    for i in (0, 7, 123):
        single = tdct.solve(robot, tdct.Actuation(tensions[i], insertion[i]), tdct.Loads(tip_force=force[i]))
        np.testing.assert_allclose(sol.position[i], single.position, rtol=0, atol=1e-12)


def test_no_retracing_when_only_values_change(paper_case, caplog):
    robot, act, load, _ = paper_case
    with jax.log_compiles(), caplog.at_level(logging.WARNING, logger="jax"):
        for tau in (1.0, 2.0, 3.0):
            solver = tdct.SolverOptions(tol=1e-10 * tau, max_iter=40 + int(tau))  # leaves: no recompile either
            r = robot.replace({"sections[*].E": tau * 1e6})
            tdct.solve(r, tdct.Actuation((tau, 0, 0, 0), 0.01 * tau), load, solver=solver)
    compiles = [r.getMessage() for r in caplog.records if "Compiling" in r.getMessage()]
    assert not any("solution_and_compliance" in m for m in compiles), compiles


SEQUENTIAL_BYTES = 512
"""XLA:CPU runs a loop body's operations one after another when none touches an array over this
size, and through its thread pool otherwise (ThunkExecutor's execute_sequential_buffer_threshold)."""


def _large_arrays_in_loops(hlo: str, limit: int) -> list:
    """Instructions of compiled HLO text, inside while-loop bodies and conditions, whose result or
    an operand holds an array of more than ``limit`` bytes, as "computation: instruction"."""
    loops = set(re.findall(r"(?:body|condition)=%?([\w.\-]+)", hlo))
    size = {"f64": 8, "s64": 8, "f32": 4, "s32": 4, "u32": 4, "pred": 1, "u8": 1, "s8": 1}

    def largest(shape):
        arrays = re.findall(r"(\w+)\[([\d,]*)\]", shape)
        return max((size.get(t, 8) * math.prod(int(d) for d in dims.split(",") if d) for t, dims in arrays), default=0)

    found, computation, shapes = [], None, {}
    for line in hlo.splitlines():
        if head := re.match(r"^(?:ENTRY )?%?([\w.\-]+) .*\{$", line):
            computation, shapes = head.group(1), {}
        elif m := re.match(r"\s*(?:ROOT )?%?([\w.\-]+) = (\(.*?\)|\S+) ([\w\-]+)\(([^)]*)\)", line):
            name, shape, op, args = m.groups()
            shapes[name] = shape
            trivial = op in ("parameter", "get-tuple-element", "tuple", "constant", "bitcast", "while", "call")
            operands = [shapes.get(a.strip().lstrip("%"), "") for a in args.split(",")]
            if computation in loops and not trivial and max(map(largest, [shape, *operands])) > limit:
                found.append(f"{computation}: {name} {shape}")
    return found


def test_newton_pass_loops_run_in_sequence(paper_case):
    """The loops of a Newton pass (the residual and its forward-mode Jacobian through the RK4 scan
    over both segments) touch no array over SEQUENTIAL_BYTES: scanning over per-step copies of the
    segments (3 kB) sent every RK4 step to the thread pool, a third more instructions per solve
    (docs/performance.md)."""
    robot, act, load, sol = paper_case
    g = gravity_vector(tdct.STANDARD_GRAVITY)
    x = shooting.scaled(robot, sol.base_wrench, shooting.force_scale(robot, act, load, g))

    def jacobian(robot, act, load, g, x):
        return jax.jacfwd(lambda x: shooting.residual(robot, act, load, g, tdct.SolverOptions(), x))(x)

    hlo = jax.jit(jacobian).lower(robot, act, load, g, x).compile().as_text()
    assert "while" in hlo
    assert _large_arrays_in_loops(hlo, SEQUENTIAL_BYTES) == []


@pytest.mark.parametrize("rotation", ["columns", "matrix"])
def test_rk4_steps_of_an_ik_pass_run_in_sequence_with_r_by_columns(paper_case, rotation):
    """The IK's augmented pass differentiates the tip residual in 11 directions (6 shooting
    unknowns, 4 tensions, the insertion). With R carried whole its tangents make an (11, 3, 3)
    array, over SEQUENTIAL_BYTES, and every RK4 step runs through the thread pool; carried by its
    columns (SolverOptions.rotation "columns", the default outside CPU batches) no array of an
    RK4 step is over it: only the loop over the two segments' pieces, which runs twice a pass,
    may hold one (a piece's parameters and their tangents)."""
    robot, act, load, sol = paper_case
    g = gravity_vector(tdct.STANDARD_GRAVITY)
    F_c = shooting.force_scale(robot, act, load, g)
    z = jnp.concatenate([shooting.scaled(robot, sol.base_wrench, F_c), act.tensions, jnp.reshape(act.insertion, 1)])
    solver = tdct.SolverOptions(rotation=rotation)

    def residual(z):
        moved = tdct.Actuation(z[6:10], z[10])
        return shooting.shoot(robot, moved, load, g, solver, z[:6], F_c)[0]

    hlo = jax.jit(jax.jacfwd(residual)).lower(z).compile().as_text()
    loops = {instruction.split(":")[0] for instruction in _large_arrays_in_loops(hlo, SEQUENTIAL_BYTES)}
    assert (len(loops) <= 1) == (rotation == "columns"), loops


def test_root_in_inputs_is_the_root_with_its_derivatives_in_the_inputs(paper_case):
    """``shooting.root_in_inputs`` (Newton's passes taken in the inputs too, for the IK's phase 2)
    finds the root that ``tdct.solve`` found, and its Jacobians of the residual and the tip in the
    inputs (tensions, insertion) equal central differences at that root."""
    robot, act, load, sol = paper_case
    g = gravity_vector(tdct.STANDARD_GRAVITY)
    solver = tdct.SolverOptions()
    v = np.concatenate([act.tensions, [act.insertion]])

    def actuation(v):
        return tdct.Actuation(v[:4], v[4])

    @jax.jit
    def found(v):  # one program: the root, its Jacobians in v, central differences at the root
        x, info, ((J_r, J_p, J_R), p, R) = shooting.root_in_inputs(robot, actuation, v, load, g, jnp.full(6, jnp.nan), solver)
        F_c = shooting.force_scale(robot, actuation(v), load, g)

        def tip(v):
            res, y = shooting.shoot(robot, actuation(v), load, g, solver, x, F_c)
            return jnp.concatenate([res, y.p, y.R.ravel()])

        h = 1e-6
        central = jax.vmap(lambda dv: (tip(v + dv) - tip(v - dv)) / (2 * h))(h * jnp.eye(5)).T
        taken = jnp.concatenate([J_r[:, 6:], J_p[:, 6:], J_R[..., 6:].reshape(9, 5)])
        return shooting.unscaled(robot, x, F_c), p, info, taken, central

    wrench, p, info, taken, central = found(v)
    assert int(info.result) == status.SUCCESS
    np.testing.assert_allclose(wrench, sol.base_wrench, rtol=0, atol=1e-9)
    np.testing.assert_allclose(p, sol.tip_position, rtol=0, atol=1e-10)
    assert rel_err(taken, central) < 1e-6
    assert info.jacobians[0].shape == (6, 6)


def test_lazily_keeps_its_branch_inside_its_loop_under_vmap():
    """XLA hoists loop-invariant work out of a while loop. ``lazily``'s branch read only values
    invariant in its one-pass loop, so under vmap it ran before the loop whether or not a lane
    needed it (a batched IK ran the grid start's coarse solves for every lane, 3-4x its time):
    the compiled program must hold the branch's work inside the loop, not in its entry."""

    def g(needed, x, y):
        def branch(y):
            with jax.named_scope("lazily_branch"):
                return jnp.cos(y) ** 2 + 1.0

        return lazily(needed, branch, x, y)

    args = (jnp.array([True, False]), jnp.ones(2), jnp.full(2, 0.5))
    hlo = jax.jit(jax.vmap(g)).lower(*args).compile().as_text()
    assert "lazily_branch" in hlo
    assert "lazily_branch" not in hlo[hlo.index("\nENTRY") :]
    np.testing.assert_allclose(jax.jit(jax.vmap(g))(*args), [math.cos(0.5) ** 2 + 1.0, 1.0], rtol=1e-15)


@pytest.mark.slow
def test_reverse_and_forward_gradients_agree_with_central_differences(paper_case):
    robot, act, load, _ = paper_case

    def tip_y(E, tau1):
        r = robot.replace({"sections[*].E": E})
        return tdct.solve(r, tdct.Actuation(jnp.stack([tau1, 0.0, 0.0, 0.0]), act.insertion), load).tip_position[1]

    g = jax.grad(tip_y, argnums=(0, 1))(0.85e6, 6.0)
    hE, ht = 1e2, 1e-4
    fd_E = (tip_y(0.85e6 + hE, 6.0) - tip_y(0.85e6 - hE, 6.0)) / (2 * hE)
    fd_t = (tip_y(0.85e6, 6.0 + ht) - tip_y(0.85e6, 6.0 - ht)) / (2 * ht)
    assert rel_err(g[0], fd_E) < 1e-6
    assert rel_err(g[1], fd_t) < 1e-6


def test_unrolled_spd_solve_matches_lapack_on_a_batch():
    from tdct_jax.linalg import solve_spd

    rng = np.random.default_rng(3)
    G = rng.normal(size=(50, 6, 6))
    A = G @ np.swapaxes(G, 1, 2) + np.diag([1e3, 1e3, 1e5, 1e-2, 1e-2, 1e-3])  # stiffness-like scales
    b = rng.normal(size=(50, 6))
    x = np.asarray(jax.jit(solve_spd)(A, b))
    assert rel_err(x, np.linalg.solve(A, b[..., None])[..., 0]) < 1e-9


def test_single_solves_go_to_the_cpu_where_a_gpu_is_the_default(robot, monkeypatch):
    solve = importlib.import_module("tdct_jax.solve")

    def arguments(gravity=tdct.STANDARD_GRAVITY):
        return solve.solve_arguments(robot, tdct.Actuation(), None, gravity, None, tdct.SolverOptions())

    cpu, put = jax.local_devices(backend="cpu")[0], []
    real_put = jax.device_put
    monkeypatch.setattr(solve.jax, "device_put", lambda x, device: put.append(device) or real_put(x, device))
    arguments()
    assert put == []  # the CPU is the default: nothing to move
    monkeypatch.setattr(solve.jax, "default_backend", lambda: "gpu")
    args = arguments()
    assert put == [cpu] and args[3].devices() == {cpu}  # gravity: jit runs where committed arguments are
    jax.jit(lambda g: arguments(g)[3])(np.zeros(3))
    assert put == [cpu]  # traced arguments (jit, vmap, sweeps) stay where they are


def test_rotation_layouts_give_the_same_solve(paper_case):
    """R carried whole or by its columns (SolverOptions.rotation) is the same arithmetic in
    another order: the same Newton steps, shapes and base wrenches to round-off."""
    robot, act, load, _ = paper_case
    sols = [tdct.solve(robot, act, load, solver=tdct.SolverOptions(rotation=r)) for r in ("columns", "matrix")]
    assert int(sols[0].iterations) == int(sols[1].iterations)
    np.testing.assert_allclose(sols[0].position, sols[1].position, rtol=0, atol=1e-15)
    assert rel_err(sols[0].base_wrench, sols[1].base_wrench) < 1e-13
