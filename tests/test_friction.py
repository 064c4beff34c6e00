"""Tendon friction with memory (rod.py, "Tendon friction"): checked against the frictionless model,
the capstan law on the solved shape's own geometry, sticking, the hysteresis loop's limit, global
balance and central differences."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import simpson

import tdct_jax as tdct
from tdct_jax import rig as rigs
from tdct_jax.calibrate_rig import RIG_SOLVER, synthesize_recording
from tdct_jax.description import Robot, Section, Tendon
from tdct_jax.options import SolverOptions

L, OFFSET, PULL = 0.2, 0.0045, 3.0
SOLVER = SolverOptions(steps=20)


def robot(mu, spacing=0.0):
    """A steel-like 1 mm backbone with two opposed tendons (1 pulled, 2 idle) and spring tendons."""
    section = Section(L, 0.001, 50e9, 0.3, 8000.0, friction=mu, guide_spacing=spacing)
    return Robot(L, (section,), (Tendon(OFFSET, np.pi / 2, stiffness=500.0), Tendon(OFFSET, -np.pi / 2, stiffness=500.0)))


def nodes(steps=SOLVER.steps):
    return steps + 1


def solve(mu, tension, memory=None, solver=SOLVER, gravity=None, spacing=0.0):
    memory = np.zeros((nodes(solver.steps), 2)) if memory is None else memory
    return tdct.solve(robot(mu, spacing), tdct.Actuation([tension, 0.0], memory=memory), gravity=gravity, solver=solver)


def turning(sol, i=0):
    """Total turning angle of tendon i's path, from the solved positions alone: the angles between
    consecutive chords of p + R r_i (the path's own geometry, no tension involved)."""
    r = np.array([np.cos(robot(0.0).tendons[i].angle), np.sin(robot(0.0).tendons[i].angle), 0.0]) * OFFSET
    q = np.asarray(sol.position) + np.einsum("nij,j->ni", np.asarray(sol.rotation), r)
    d = np.diff(q, axis=0)
    d = d[np.linalg.norm(d, axis=1) > 0]
    d /= np.linalg.norm(d, axis=1)[:, None]
    return np.sum(np.arctan2(np.linalg.norm(np.cross(d[:-1], d[1:]), axis=1), np.sum(d[:-1] * d[1:], axis=1)))


def test_zero_friction_is_the_frictionless_model():
    """A coefficient of 0 carries the tension profile but changes nothing, to 1e-12 (both solved
    to a tolerance far below that): displacement control, gravity, the second tendon idle."""
    tight = dataclasses.replace(SOLVER, tol=1e-14)
    for act in (tdct.Actuation([PULL, 0.0]), tdct.Actuation([0.0, 0.0], displacements=[2e-3], driven=(0,))):
        plain, zero = (tdct.solve(robot(mu), act, solver=tight) for mu in (None, 0.0))
        for field in ("position", "total_force", "total_moment", "tensions", "displacements"):
            np.testing.assert_allclose(getattr(zero, field), getattr(plain, field), rtol=0, atol=1e-12)
        np.testing.assert_allclose(zero.tendon_tension, plain.tendon_tension, rtol=0, atol=1e-12)


def test_a_sliding_tendon_follows_the_capstan_law():
    """Pulled from slack, the tendon slides all along: its tension at the tip over that at the base
    is exp(-mu theta), theta the turning of its path measured on the solved shape, converging at
    first order in the step (the tension is constant over each RK4 step)."""
    mu, errors = 0.2, []
    for steps in (20, 40):
        sol = solve(mu, PULL, solver=SolverOptions(steps=steps))
        tau = np.asarray(sol.tendon_tension)[:, 0]
        assert tau[0] == PULL and np.all(np.diff(tau) <= 0)
        errors.append(abs(tau[-1] / tau[0] - np.exp(-mu * turning(sol))))
    assert errors[1] < 5e-4 and 1.6 < errors[0] / errors[1] < 2.4


def test_a_small_release_sticks_beyond_the_sliding_zone():
    """Pull to 3 N from slack, release to 2.8 N: near the base the tendon slides back (tension
    rising along it, by exp(+mu theta)); beyond, it sticks, its tension the previous pose's to the bit."""
    mu = 0.2
    pulled = solve(mu, PULL)
    released = solve(mu, 2.8, memory=pulled.tendon_tension)
    before, after = np.asarray(pulled.tendon_tension)[:, 0], np.asarray(released.tendon_tension)[:, 0]
    stuck = after == before
    k = np.argmax(stuck)  # the first stuck node
    assert 2 < k < len(after) - 3 and np.all(stuck[k:])
    assert after[0] == 2.8 and np.all(np.diff(after[:k]) > 0)
    np.testing.assert_allclose(after[k - 1] / after[0], np.exp(mu * turning(_cut(released, k))), rtol=0.05)


def _cut(sol, k):
    return dataclasses.replace(sol, position=sol.position[:k], rotation=sol.rotation[:k])


def _cycle(mu, tensions):
    """Tips along tensions, each solve taking the last one's profile as memory."""
    memory, tips = None, []
    for t in tensions:
        sol = solve(mu, t, memory=memory)
        memory, tips = sol.tendon_tension, tips + [np.asarray(sol.tip_position)]
    return np.array(tips)


def test_the_hysteresis_loop_closes_as_friction_vanishes():
    """Pull 0 -> 3 N and back: at equal tensions the tips differ (the loop's width), by an amount
    proportional to mu for small mu, and not at all without friction."""
    up = np.linspace(0.0, PULL, 7)
    path = np.concatenate([up, up[-2::-1]])
    widths = []
    for mu in (0.0, 0.05, 0.1):
        tips = _cycle(mu, path)
        widths.append(np.max(np.linalg.norm(tips[:7] - tips[6:][::-1], axis=1)))
    assert widths[0] < 1e-12
    assert widths[1] > 1e-4 and 1.8 < widths[2] / widths[1] < 2.2


def test_friction_keeps_the_whole_robot_in_balance():
    """With gravity and friction, the base carries the weight and the tip load, force and moment
    about the base (friction is internal to rod and tendons), and every piece between nodes holds
    its own weight: N(s_k) - N(s_j) = -(weight of [s_j, s_k])."""
    load = tdct.Loads(tip_force=(0.01, 0.0, -0.02))
    sec = robot(0.2).sections[0]
    rho = float(sec.density) * np.pi * float(sec.outer_diameter) ** 2 / 4
    sol = tdct.solve(robot(0.2), tdct.Actuation([PULL, 0.0], memory=np.zeros((21, 2))), load, solver=SOLVER)
    g = np.array(tdct.STANDARD_GRAVITY)
    s, N = np.asarray(sol.s), np.asarray(sol.total_force)
    np.testing.assert_allclose(N - N[0], -rho * g[None] * s[:, None], rtol=0, atol=1e-12)
    np.testing.assert_allclose(N[0], np.asarray(load.tip_force) + rho * g * L, rtol=0, atol=1e-12)
    p = np.asarray(sol.position)
    lever = simpson(np.cross(p, rho * g), x=s, axis=0)
    moment = np.asarray(sol.total_moment[0]) - (np.cross(p[-1], load.tip_force) + lever)
    assert np.abs(moment).max() < 1e-9  # N m: Simpson's rule on the nodes, 2e-10


def test_derivatives_in_mu_memory_and_E_match_central_differences():
    """d(tip)/d(mu), d(tip)/d(E) and d(tip)/d(a memory value) by forward mode through the
    implicit solve, against central differences, where the tendon partly slides and partly sticks."""
    pulled = solve(0.2, PULL)
    memory = np.asarray(pulled.tendon_tension)

    def tip(mu, E, m):
        r = robot(0.2).replace({"sections[0].friction": mu, "sections[0].E": E})
        act = tdct.Actuation._rebuild(np.array([2.8, 0.0]), np.zeros(0), np.zeros(0), (), memory + m * _unit(memory, -3))
        return tdct.solve(r, act, gravity=None, solver=SOLVER, throw=False).tip_position

    x = (0.2, 50e9, 0.0)
    J = jax.jacfwd(tip, argnums=(0, 1, 2))(*x)
    for k, h in enumerate((1e-5, 1e4, 1e-4)):
        up = list(x)
        down = list(x)
        up[k] += h
        down[k] -= h
        fd = (np.asarray(tip(*up)) - np.asarray(tip(*down))) / (2 * h)
        np.testing.assert_allclose(np.asarray(J[k]), fd, rtol=1e-5, atol=1e-9 * np.abs(fd).max())


def _unit(a, row):
    u = np.zeros_like(a)
    u[row, 0] = 1.0
    return u


@pytest.fixture(scope="module")
def rig():
    """A one-segment, three-tendon robot on a rig, with friction, gravity across it."""
    section = Section(0.1, 0.001, 50e9, 0.3, 8000.0, friction=0.15)
    tendons = tuple(Tendon(OFFSET, a, stiffness=300.0) for a in np.radians([90.0, 210.0, 330.0]))
    robot = Robot(0.1, (section,), tendons)
    return rigs.Rig(robot, pretension=np.full(3, 1.0), g=9.81, gravity_azimuth=np.pi / 2, gravity_elevation=0.0)


@pytest.fixture(scope="module")
def cycle_servos():
    """Tendon 1 pulled to 2 mm and released, twice, tendons 2 and 3 let out as it goes [m]."""
    up = np.linspace(0.0, 2e-3, 9)
    one = np.concatenate([up, up[-2::-1], up[1:], up[-2::-1]])
    return np.stack([one, -one / 2, -one / 2], axis=1)


@pytest.mark.slow
def test_a_recording_predicted_in_order_carries_the_memory(rig, cycle_servos):
    """Along a pull-release cycle the tips at equal servo readings differ with friction (the loop)
    and agree without it; the second release retraces the first (the pull to the same peak wipes
    out what came before it: the memory is carried, not built up)."""
    tips = {}
    for mu in (0.0, 0.15):
        r = rigs.replace(rig, {"sections[0].friction": mu})
        tip, _, codes, profiles = rigs.along(r, jnp.asarray(cycle_servos), RIG_SOLVER)
        assert np.all(np.asarray(codes) == 0) and profiles.shape[0] == len(cycle_servos)
        tips[mu] = np.asarray(tip)
    gap = {mu: np.linalg.norm(t[4] - t[12], axis=-1) for mu, t in tips.items()}  # 1 mm, pulling and releasing
    assert gap[0.0] < 1e-9 and gap[0.15] > 1e-4
    np.testing.assert_allclose(tips[0.15][25:], tips[0.15][9:17], rtol=0, atol=1e-9)


@pytest.mark.slow
def test_friction_is_calibrated_with_the_rest(rig, cycle_servos):
    """From a recording made with mu = 0.15 (0.05 mm noise), a fit started at mu = 0.05 finds it
    with the servo scale and the registration; the truth lies within 3 standard errors."""
    noisy = synthesize_recording(rig, np.tile(cycle_servos, (2, 1)), noise=5e-5, seed=1)
    start = rigs.replace(rig, {"sections[0].friction": 0.05, "scale": 1.1})
    params = ("sections[0].friction", "scale", "translation[0]", "translation[1]")
    fit = tdct.calibrate(start, noisy, params, progress=False)
    assert fit.converged
    for p, truth in (("sections[0].friction", 0.15), ("scale", 1.0)):
        assert abs(fit.values[p] - truth) < 3 * fit.std_errors[p], (p, fit.values[p], fit.std_errors[p])
    assert fit.std_errors["sections[0].friction"] < 0.02


def test_friction_inputs_are_checked_before_any_solve(tmp_path):
    """A negative coefficient or spacing, a memory of the wrong shape or on a frictionless robot,
    and friction with multiple shooting are refused by name; the robot file reads and writes the
    two keys."""
    with pytest.raises(ValueError, match=r"Section.friction = -0.1 is outside the allowed range"):
        robot(-0.1)
    with pytest.raises(ValueError, match=r"Section.guide_spacing = -0.01 is outside"):
        robot(0.1, spacing=-0.01)
    with pytest.raises(ValueError, match=r"memory has shape \(5, 2\).*\(21, 2\)"):
        tdct.solve(robot(0.1), tdct.Actuation([1.0, 0.0], memory=np.zeros((5, 2))), solver=SOLVER)
    with pytest.raises(ValueError, match=r"memory: a tension profile only acts with tendon friction"):
        tdct.solve(robot(None), tdct.Actuation([1.0, 0.0], memory=np.zeros((21, 2))), solver=SOLVER)
    with pytest.raises(ValueError, match=r"memory\[0, 0\] = -1 N is outside the allowed range"):
        tdct.Actuation([1.0, 0.0], memory=-np.ones((21, 2)))
    with pytest.raises(ValueError, match=r"intervals = 2 with tendon friction"):
        tdct.solve(robot(0.1), tdct.Actuation([1.0, 0.0]), solver=dataclasses.replace(SOLVER, intervals=2))
    path = tmp_path / "robot.toml"
    path.write_text(robot(0.1, spacing=0.01).to_toml())
    back = Robot.from_toml(path)
    assert float(back.sections[0].friction) == 0.1 and float(back.sections[0].guide_spacing) == 0.01
    path.write_text(path.read_text().replace("friction = 0.1", "friction = -2"))
    with pytest.raises(ValueError, match=rf"robot file {path}: .*friction = -2"):
        Robot.from_toml(path)
