"""tdct.simulate (issue 49): a slender steel cantilever's free vibration against Euler-Bernoulli
theory, the scheme's order in dt, its numerical dissipation, Kelvin-Voigt decay against its
closed form, settling onto the static solution, global momentum balance and exact derivatives
of a trajectory loss. One robot and one step count: one compiled simulation (two with grad)."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import tdct_jax as tdct
from tdct_jax import dynamics, status
from tdct_jax.dynamics import simulate

L, D, E, RHO = 0.3, 2e-3, 200e9, 7800.0
A, I = np.pi / 4 * D**2, np.pi / 64 * D**4
OMEGA = np.array([1.8751, 4.6941, 7.8548]) ** 2 * np.sqrt(E * I / (RHO * A)) / L**2
"""Euler-Bernoulli's first three natural frequencies of the cantilever [rad/s]."""
T1 = 2 * np.pi / OMEGA[0]
STEPS = 300
SOLVER = tdct.SolverOptions(steps=20)
PUSH = np.zeros((STEPS + 1, 3))
PUSH[0, 1] = 1e-3
"""A 1 mN tip force held until t = 0, then released: free vibration about the straight rod."""


def robot(damping=0.0, E=E):
    section = tdct.Section(end=L, outer_diameter=D, E=E, nu=0.3, density=RHO, damping=damping)
    return tdct.Robot(L, (section,), (tdct.Tendon(offset=5e-3, angle=np.pi / 2),))


def free(n, damping=0.0, alpha=-0.2):
    """The released cantilever at n steps per Euler-Bernoulli period, without gravity."""
    return simulate(robot(damping), T1 / n, tip_force=PUSH, tensions=[0.0], gravity=None, solver=SOLVER, alpha=alpha)


def first_mode(y, dt, near=OMEGA[0]):
    """(frequency [rad/s], decay rate [1/s]) of the mode nearest ``near`` in the signal y by the
    matrix pencil method (sums of damped exponentials)."""
    rows = len(y) // 2
    Y = np.array([y[i : i + rows + 1] for i in range(len(y) - rows)])
    V = np.linalg.svd(Y, full_matrices=False)[2][:6].T
    z = np.linalg.eigvals(np.linalg.pinv(V[:-1]) @ V[1:])
    z = z[np.angle(z) > 1e-9]
    k = np.argmin(np.abs(np.angle(z) / dt - near))
    return np.angle(z[k]) / dt, -np.log(np.abs(z[k])) / dt


@pytest.fixture(scope="module")
def runs():
    return {(n, zeta): free(n, 2 * zeta / OMEGA[0]) for n in (50, 100) for zeta in (0.0, 0.02)}


def test_first_natural_frequency_converges_to_euler_bernoulli_at_second_order(runs):
    errors = {}
    for n in (50, 100):
        traj = runs[n, 0.0]
        assert bool(traj.converged)
        w, _ = first_mode(np.asarray(traj.tip_position[:, 1]), T1 / n)
        errors[n] = w / OMEGA[0] - 1
    assert abs(errors[100]) < 5e-3
    assert 3.0 < errors[50] / errors[100] < 5.0  # second order in dt


@pytest.mark.slow
def test_second_and_third_modes_by_multiple_shooting_converge_to_euler_bernoulli():
    """The second and third natural frequencies from the base's shear force (in which the higher
    modes weigh more than at the tip): within 0.5% at 800 steps per first period, where single
    shooting cannot go (k L = 1.06 sqrt(800) = 30), by ten shooting intervals; second order in
    dt against 400 steps per period (the pencil reads the second mode's smaller error less
    cleanly: over twofold less). The same 400 steps (and one compiled simulation) each."""
    solver = tdct.SolverOptions(steps=20, intervals=10)
    push = np.zeros((401, 3))
    push[0, 1] = 1e-3
    errors = {}
    for n in (400, 800):
        traj = simulate(robot(), T1 / n, tip_force=push, tensions=[0.0], gravity=None, solver=solver)
        y = np.asarray(traj.force[:, 0, 1])
        errors[n] = np.array([first_mode(y, T1 / n, OMEGA[k])[0] / OMEGA[k] - 1 for k in (1, 2)])
    assert np.all(np.abs(errors[800]) < 5e-3)
    assert np.all(errors[800] < 0)
    ratio = errors[400] / errors[800]
    assert np.all(ratio > 2.0)
    assert 3.0 < ratio[1] < 5.0  # the third mode's, where the time step's error dominates most


def test_numerical_dissipation_shrinks_with_dt(runs):
    """Without material damping the first mode decays only by the scheme's own dissipation
    (BDF-alpha, alpha = -0.2): its energy (twice the amplitude's decay rate) loses under 0.1% a
    period at 100 steps a period, and over fourfold less than at half that (second order at
    least; the higher modes, damped more, are left out by the pencil)."""
    lost = {n: 2 * first_mode(np.asarray(runs[n, 0.0].tip_position[:, 1]), T1 / n)[1] * T1 for n in (50, 100)}
    assert 0 < lost[100] < 1e-3
    assert lost[50] / lost[100] > 4.0


def test_kelvin_voigt_decay_matches_its_closed_form(runs):
    """B = tau_d K: the first mode decays as exp(-zeta omega t), zeta = tau_d omega / 2, on top of
    the scheme's own dissipation (the undamped run's)."""
    for n, tol in ((50, 0.02), (100, 0.005)):
        own = first_mode(np.asarray(runs[n, 0.0].tip_position[:, 1]), T1 / n)[1]
        damped = first_mode(np.asarray(runs[n, 0.02].tip_position[:, 1]), T1 / n)[1]
        assert (damped - own) / (0.02 * OMEGA[0]) == pytest.approx(1.0, abs=tol)


def test_a_tip_mass_follows_the_frequency_equation_and_settles_with_its_weight():
    """A point mass M = 0.3 rho A L at the tip: Euler-Bernoulli's frequency equation
    1 + cos b cosh b + (M / rho A L) b (cos b sinh b - sin b cosh b) = 0 (first root by bisection),
    omega = b^2 sqrt(EI / rho A) / L^2; then, damped, a pull under gravity settles onto ``solve``."""
    ratio = 0.3
    heavy = robot().replace(masses=(tdct.PointMass(L, ratio * RHO * A * L),))

    def equation(b):
        return 1 + np.cos(b) * np.cosh(b) + ratio * b * (np.cos(b) * np.sinh(b) - np.sin(b) * np.cosh(b))

    lo, hi = 0.5, 1.8751
    for _ in range(60):
        lo, hi = (lo, (lo + hi) / 2) if equation(lo) * equation((lo + hi) / 2) <= 0 else ((lo + hi) / 2, hi)
    omega = lo**2 * np.sqrt(E * I / (RHO * A)) / L**2
    period = 2 * np.pi / omega
    traj = simulate(heavy, period / 100, tip_force=PUSH, tensions=[0.0], gravity=None, solver=SOLVER)
    w, _ = first_mode(np.asarray(traj.tip_position[:, 1]), period / 100, omega)
    assert w / omega - 1 == pytest.approx(0.0, abs=2e-3)
    damped = heavy.replace({"sections[0].damping": 2 / omega})
    tensions = np.full((STEPS + 1, 1), 1.0)
    tensions[0] = 0.0
    traj = simulate(damped, period / 20, tensions=tensions, gravity=(0.0, -9.81, 0.0), solver=SOLVER)
    static = tdct.solve(damped, tdct.Actuation([1.0]), solver=SOLVER)
    np.testing.assert_allclose(traj.tip_position[-1], static.tip_position, rtol=0, atol=1e-9)


def test_a_damped_pull_settles_onto_the_static_solution():
    damped = robot(2 / OMEGA[0])  # the first mode critically damped
    tensions = np.full((STEPS + 1, 1), 2.0)
    tensions[0] = 0.0
    traj = simulate(damped, T1 / 20, tensions=tensions, gravity=(0.0, -9.81, 0.0), solver=SOLVER)
    static = tdct.solve(damped, tdct.Actuation([2.0]), solver=SOLVER)
    np.testing.assert_allclose(traj.tip_position[-1], static.tip_position, rtol=0, atol=1e-9)
    np.testing.assert_allclose(traj.force[-1, 0], static.total_force[0], rtol=0, atol=1e-9)


def test_a_displacement_driven_pull_retraces_the_tension_driven_one_and_settles_onto_solve():
    """The encoder readings (``Trajectory.displacements``) of a damped smooth 2 N pull under
    gravity, commanded back as the tendon's displacement, give back its tensions and tips; a
    displacement ramped in the same way settles onto ``solve``'s displacement-driven equilibrium,
    and one below the sagging rod's own reading slackens the tendon (tension exactly 0)."""
    damped = robot(2 / OMEGA[0])
    g = (0.0, -9.81, 0.0)
    t = np.arange(STEPS + 1) * T1 / 20
    ramp = (np.sin(np.pi * np.minimum(t / T1, 0.5)) ** 2)[:, None]
    pulled = simulate(damped, T1 / 20, tensions=2.0 * ramp, gravity=g, solver=SOLVER)
    encoder = np.asarray(pulled.displacements)
    assert encoder[-1, 0] - encoder[0, 0] > 5e-5  # 2 N bends the rod: the tendon's path shortens ~0.1 mm

    def driven(displacements):
        return simulate(damped, T1 / 20, displacements=displacements, driven=(0,), tensions=[0.0], gravity=g, solver=SOLVER)

    back = driven(encoder)
    np.testing.assert_allclose(back.tensions, 2.0 * ramp, rtol=0, atol=1e-6)
    np.testing.assert_allclose(back.tip_position, pulled.tip_position, rtol=0, atol=1e-10)
    for end in (encoder[0, 0] + 1.5 * (encoder[-1, 0] - encoder[0, 0]), encoder[0, 0] - 1e-4):
        settled = driven(encoder[0, 0] + (end - encoder[0, 0]) * ramp)
        static = tdct.solve(damped, tdct.Actuation([0.0], displacements=[end], driven=(0,)), gravity=g, solver=SOLVER)
        np.testing.assert_allclose(settled.tip_position[-1], static.tip_position, rtol=0, atol=1e-9)
        np.testing.assert_allclose(settled.tensions[-1], static.tensions, rtol=0, atol=1e-7)
    assert static.tensions[0] == 0.0 and settled.tensions[-1, 0] == 0.0  # the last: slack


def test_a_point_load_held_then_removed_under_tilted_gravity():
    """A critically damped rod, gravity tilted off every axis, a point force at mid-span held for
    the first rows: held, the rod stays at rest in ``solve``'s equilibrium with the force (no
    spurious motion from the start); released, it settles onto ``solve``'s without it."""
    damped = robot(2 / OMEGA[0])
    g = 9.81 * np.array([0.3, -0.8, 0.45]) / np.linalg.norm([0.3, -0.8, 0.45])
    force, held = np.array([0.0, 0.4, -0.2]), 6
    load = tdct.Loads(point_s=(L / 2,), point_force=[force])
    point = np.zeros((STEPS + 1, 1, 3))
    point[:held, 0] = force
    traj = simulate(damped, T1 / 20, tensions=[0.0], point_force=point, load=load, gravity=g, solver=SOLVER)
    act = tdct.Actuation([0.0])
    loaded = tdct.solve(damped, act, load, gravity=g, solver=SOLVER).tip_position
    free = tdct.solve(damped, act, gravity=g, solver=SOLVER).tip_position
    assert np.linalg.norm(loaded - free) > 5e-3  # 7 mm
    np.testing.assert_allclose(traj.tip_position[:held], np.broadcast_to(loaded, (held, 3)), rtol=0, atol=1e-12)
    np.testing.assert_allclose(traj.tip_position[-1], free, rtol=0, atol=1e-9)


def test_global_momentum_balance():
    """The base's impulse is the rod's loss of momentum (no gravity, no tip load): int_0^t N(0) dt
    = -(int rho A p_t ds)(t), under a smooth pull of the tendon (2 N, sin^2 over half a period),
    to O(dt^2): below 0.5% of the momentum's largest at 50 steps a period, and over threefold less
    at half the step once the pull is done."""
    late = {}
    for n in (50, 100):
        dt = T1 / n
        t = np.arange(STEPS + 1) * dt
        pull = 2.0 * np.sin(np.pi * np.minimum(t / T1, 0.5)) ** 2
        traj = simulate(robot(), dt, tensions=pull[:, None], gravity=None, solver=SOLVER)
        momentum = RHO * A * np.trapezoid(np.asarray(traj.velocity[..., 1]), np.asarray(traj.s[0]), axis=1)
        base = np.asarray(traj.force[:, 0, 1])
        impulse = np.concatenate([[0.0], np.cumsum((base[1:] + base[:-1]) / 2 * dt)])
        error = np.abs(impulse + momentum - momentum[0]) / np.abs(momentum).max()
        assert error.max() < 5e-3
        late[n] = error[t > T1].max()
    assert late[50] / late[100] > 3.0


def test_tendon_friction_keeps_statics_hysteresis_and_settles_onto_solve_with_its_memory():
    """Tendon friction (mu = 0.3) on the critically damped rod under gravity, single shooting:
    pulled to 2 N and released to 1 N, slowly (3 periods a ramp), it settles 1.3 um from where a
    pull straight to 1 N settles (the hysteresis no memoryless model has). Each settled pose is
    ``solve``'s with the last step's tension profile as its memory (1e-12 m), and each agrees with
    statics' chain of poses (solve at 2 N from slack, then at 1 N with that memory; solve at 1 N)
    within 0.1 um, a tenth of the gap."""
    rough = robot(2 / OMEGA[0]).replace({"sections[0].friction": 0.3})
    solver = tdct.SolverOptions(steps=20, intervals=1)
    g = (0.0, -9.81, 0.0)
    t = np.arange(STEPS + 1) * T1 / 20

    def ramp(a, b):
        return np.clip((t - a) / (b - a), 0.0, 1.0)[:, None]

    def settled(tensions):
        traj = simulate(rough, T1 / 20, tensions=tensions, gravity=g, solver=solver)
        assert bool(traj.converged)
        memory = tdct.Actuation(traj.tensions[-1], memory=traj.tendon_tension[-2])
        static = tdct.solve(rough, memory, gravity=g, solver=solver)
        np.testing.assert_allclose(traj.tip_position[-1], static.tip_position, rtol=0, atol=1e-12)
        return np.asarray(traj.tip_position[-1]), traj

    released, traj = settled(2.0 * ramp(0, 3 * T1) - ramp(6 * T1, 9 * T1))
    pulled, _ = settled(ramp(0, 3 * T1))
    assert np.linalg.norm(released - pulled) > 1e-6
    profile = np.asarray(traj.tendon_tension[-1, :, 0])
    assert profile[0] == 1.0 and profile[-1] > 1.001  # released: the tension rises toward the tip
    first = tdct.solve(rough, tdct.Actuation([2.0]), gravity=g, solver=solver)
    chain = tdct.solve(rough, tdct.Actuation([1.0], memory=first.tendon_tension), gravity=g, solver=solver)
    direct = tdct.solve(rough, tdct.Actuation([1.0]), gravity=g, solver=solver)
    np.testing.assert_allclose(released, chain.tip_position, rtol=0, atol=1e-7)
    np.testing.assert_allclose(pulled, direct.tip_position, rtol=0, atol=1e-7)


def test_a_rod_falling_onto_a_plane_never_enters_it_balances_momentum_and_settles_onto_solve():
    """The critically damped rod released straight under gravity lands on a plane 2.2 mm below
    its axis (a contact candidate every 5 RK4 steps and the tip): no candidate ever enters it,
    every force pushes; the rod's momentum changes by the base force, the weight and the contact
    forces at every step (the scheme's own derivative of the momentum, BDF-alpha, against their
    sum: within 0.5% of the largest, the rest the nodes' trapezoid in s; an impact's impulse lands
    in one step); and it settles onto ``solve``'s contact equilibrium, its tip at rest on the
    plane with the force the plane takes."""
    damped = robot(2 / OMEGA[0])
    scene = tdct.Scene((tdct.Plane((0.0, -2.2e-3, 0.0), (0.0, 1.0, 0.0)),), every=5)
    g = (0.0, -9.81, 0.0)
    dt = T1 / 20
    traj = simulate(damped, dt, 100, tensions=[0.0], scene=scene, gravity=g, start="straight", solver=SOLVER)
    assert bool(traj.converged)
    force, gap = np.asarray(traj.contact_force[..., 0]), np.asarray(traj.contact_gap[..., 0])
    assert gap.min() > -1e-12 and force.min() >= 0 and force[:, -1].max() > 0.01
    assert np.all((force == 0) | (np.abs(gap) < 1e-12))  # only a touching candidate pushes

    momentum = RHO * A * np.trapezoid(np.asarray(traj.velocity[..., 1]), np.asarray(traj.s[0]), axis=1)
    rate = -np.asarray(traj.force[:, 0, 1]) + force.sum(1) + RHO * A * L * g[1]
    c = dynamics.scheme(dt)
    derivative = np.zeros_like(momentum)
    for i in range(1, len(momentum)):
        derivative[i] = c.c0 * momentum[i] + c.c1 * momentum[i - 1] + c.c2 * momentum[max(i - 2, 0)] + c.d1 * derivative[i - 1]
    assert np.abs(derivative - rate)[1:].max() < 5e-3 * np.abs(rate[1:]).max()  # row 0: the straight start, not at rest

    static = tdct.solve(damped, tdct.Actuation([0.0]), gravity=g, scene=scene, solver=tdct.SolverOptions(steps=20))
    np.testing.assert_allclose(traj.tip_position[-1], static.tip_position, rtol=0, atol=1e-9)
    np.testing.assert_allclose(traj.contact_force[-1], static.contact.force, rtol=0, atol=1e-9)
    assert traj.tip_position[-1, 1] == pytest.approx(-1.2e-3, abs=1e-12)  # on the plane: its surface 1 mm below the axis


def tubed(tube_E, tube_density, damping=0.0):
    """The rod as a tube (1 mm bore) with a tube of its own inside, pushed along it in time."""
    section = tdct.Section(end=L, outer_diameter=D, inner_diameter=1e-3, E=E, nu=0.3, density=RHO, damping=damping)
    tube = tdct.Tube(outer_diameter=0.8e-3, inner_diameter=0.6e-3, E=tube_E, nu=0.3, density=tube_density)
    return tdct.Robot(L, (section,), (tdct.Tendon(offset=0.8e-3, angle=np.pi / 2),), tubes=(tube,))


PUSHED = np.linspace(0.05, 0.25, 61)[:, None]
"""A tube pushed from 50 to 250 mm deep over 60 steps (one compiled simulation for both tests)."""


def test_a_tube_that_changes_nothing_changes_nothing_when_it_moves():
    """A tube of no mass and a millionth of the rod's stiffness, pushed 0.2 m along the rod at
    2.6 m/s while it falls from straight under gravity, leaves the motion as it is with the tube
    held: the history follows the material points across the moving breakpoint (``remap``). The
    difference left, 8e-8 m, is the tube's unshearable region (1.2e-7 m between the tube held at
    its two depths); carrying the history by stage index instead gives 7e-5 m."""
    phantom = tubed(1e7, 0.0)
    dt = T1 / 50

    def run(depths):
        return simulate(phantom, dt, tensions=[0.0], insertions=depths, start="straight", solver=SOLVER)

    moved, held = run(PUSHED), run(np.full_like(PUSHED, PUSHED[0]))
    assert bool(moved.converged)
    assert np.abs(np.asarray(held.tip_position[:, 1])).max() > 2e-3  # it falls 2.5 mm and swings
    np.testing.assert_allclose(moved.tip_position, held.tip_position, rtol=0, atol=3e-7)
    np.testing.assert_allclose(moved.s[-1, 20], PUSHED[-1, 0])  # the nodes moved with the tube's end
    np.testing.assert_allclose(moved.insertions, PUSHED)


def test_a_tube_pushed_in_during_a_damped_pull_settles_onto_solve_at_its_last_depth():
    """A stiff tube (Nitinol) pushed in over the first 20 of 60 long steps, then held, the tendon
    pulled: the critically damped rod settles onto ``solve``'s equilibrium at the last depth."""
    stiff = tubed(75e9, 6450.0, damping=2 / OMEGA[0])
    depths = np.minimum(PUSHED, PUSHED[20])
    traj = simulate(stiff, 0.01, tensions=[1.0], insertions=depths, start="straight", solver=SOLVER)
    static = tdct.solve(stiff, tdct.Actuation([1.0], depths[-1]), solver=SOLVER)
    np.testing.assert_allclose(traj.tip_position[-1], static.tip_position, rtol=0, atol=1e-9)


@pytest.mark.parametrize(
    ("depths", "words"),
    [
        (np.linspace(0.1, 0.4, 5)[:, None], "insertions[3] (t = 0.003 s) = [0.325] is outside the allowed range [0, 0.3] m"),
        (np.zeros((5, 2)), "insertions has shape (5, 2): (1,) or (times, 1) expected"),
        (np.zeros((6, 1)), "insertions has 6 rows: one per time, 5"),
    ],
)
def test_bad_insertions_along_time_are_refused_by_name(depths, words):
    with pytest.raises(ValueError) as e:
        simulate(tubed(75e9, 6450.0), 1e-3, 4, tensions=[0.0], insertions=depths)
    assert words in str(e.value)


@pytest.mark.slow
def test_derivatives_of_a_trajectory_loss_match_central_differences():
    """jax.grad of a loss over the whole trajectory, through every step's implicit solve, in E,
    the damping and one entry of the tension history, against central differences."""
    tensions = np.zeros((STEPS + 1, 1))
    tensions[1:40] = 1.0
    tight = tdct.SolverOptions(steps=20, tol=1e-11)

    def loss(E, damping, tensions):
        traj = simulate(robot(damping, E), T1 / 50, tensions=tensions, gravity=None, solver=tight, throw=False)
        return jnp.sum(traj.tip_position[:, 1] ** 2)

    args = (E, 2e-4, jnp.asarray(tensions))
    grads = jax.grad(loss, argnums=(0, 1, 2))(*args)
    for k, h in ((0, 1e-4 * E), (1, 1e-4 * 2e-4)):
        plus, minus = list(args), list(args)
        plus[k], minus[k] = args[k] + h, args[k] - h
        fd = (loss(*plus) - loss(*minus)) / (2 * h)
        assert float(grads[k]) == pytest.approx(float(fd), rel=1e-6)
    e = np.zeros_like(tensions)
    e[10] = 1e-4
    fd = (loss(E, 2e-4, tensions + e) - loss(E, 2e-4, tensions - e)) / 2e-4
    assert float(grads[2][10, 0]) == pytest.approx(float(fd), rel=1e-6)


@pytest.mark.slow
def test_derivatives_through_multiple_shooting_match_central_differences():
    """The same through four shooting intervals (the root differentiated in the interior
    rotations' Cayley coordinates), under gravity: the damping and one tension of the history."""
    tensions = np.zeros((61, 1))
    tensions[1:40] = 1.0
    solver = tdct.SolverOptions(steps=20, tol=1e-11, intervals=4)

    def loss(damping, tensions):
        traj = simulate(robot(damping), T1 / 50, tensions=tensions, gravity=(0.0, -9.81, 0.0), solver=solver, throw=False)
        return jnp.sum(traj.tip_position[:, 1] ** 2)

    grads = jax.grad(loss, argnums=(0, 1))(2e-4, jnp.asarray(tensions))
    h = 1e-4 * 2e-4
    assert float(grads[0]) == pytest.approx(float((loss(2e-4 + h, tensions) - loss(2e-4 - h, tensions)) / (2 * h)), rel=1e-6)
    e = np.zeros_like(tensions)
    e[10] = 1e-4
    fd = (loss(2e-4, tensions + e) - loss(2e-4, tensions - e)) / 2e-4
    assert float(grads[1][10, 0]) == pytest.approx(float(fd), rel=1e-6)


@pytest.mark.parametrize(
    ("kw", "words"),
    [
        ({"dt": 0.0}, "dt = 0 is outside the allowed range (0, inf] s"),
        ({"alpha": 0.3}, "alpha = 0.3 is outside"),
        ({"tensions": np.zeros((5, 2))}, "tensions has shape (5, 2)"),
        ({"tensions": np.zeros((5, 1)), "tip_force": np.zeros((6, 3))}, "tensions has 5 rows: one per time, 6"),
        ({"start": "moving"}, "start = 'moving'"),
        ({"tensions": [-1.0]}, "tensions"),
        ({"displacements": [1e-3], "driven": (1,)}, "driven = (1,): the robot has 1 tendons"),
        ({"displacements": [0.5], "driven": (0,)}, "displacements[0] (tendons[0]) = 0.5 is outside"),
        ({"displacements": [1e-3]}, "displacements has shape (1,): (0,)"),
    ],
)
def test_bad_input_is_refused_by_name(kw, words):
    args = {"dt": 1e-3, "steps": 4} | kw
    dt, steps = args.pop("dt"), args.pop("steps")
    with pytest.raises(ValueError, match=None) as e:
        simulate(robot(), dt, None if "tensions" in args and np.ndim(args["tensions"]) == 2 else steps, **args)
    assert words in str(e.value)


def test_a_step_that_does_not_converge_raises_naming_its_time_and_numbers(runs, monkeypatch):
    traj = runs[(50, 0.0)]
    broken = dataclasses.replace(
        traj, result=traj.result.at[7:].set(status.NEWTON_LIMIT), residual_norm=traj.residual_norm.at[7].set(1e-3)
    )
    monkeypatch.setattr(dynamics, "_simulate", lambda *args, **kwargs: broken)
    with pytest.raises(status.ConvergenceError) as e:
        free(50)
    words = str(e.value)
    assert words.startswith(f"simulate: time step 7 (t = {7 * T1 / 50:g} s) did not converge: Newton limit reached")
    assert "max_iter = 50 steps" in words and "(0.001) below tol = 1e-10" in words and "?" not in words
    assert words.endswith("Try more solver.intervals (multiple shooting), a ramped input or more solver.max_iter.")


def test_what_is_not_simulated_is_refused():
    rough = robot().replace({"sections[0].friction": 0.1})
    with pytest.raises(ValueError, match="intervals = 4 with tendon friction"):
        simulate(rough, 1e-3, 4, tensions=[0.0], solver=tdct.SolverOptions(intervals=4))
    with pytest.raises(ValueError, match="intervals = 4 with a scene: contact is solved by single shooting only"):
        simulate(robot(), 1e-3, 4, scene=tdct.Scene((tdct.Plane((0.0, -0.01, 0.0)),)), solver=tdct.SolverOptions(intervals=4))
    with pytest.raises(ValueError, match="insertions along time with tendon friction"):
        simulate(tubed(75e9, 6450.0).replace({"sections[0].friction": 0.1}), 1e-3, 4, insertions=np.zeros((5, 1)))


@pytest.mark.slow
def test_a_motion_fit_recovers_modulus_and_damping_within_their_standard_errors():
    """A synthetic recording (a smooth 1 N pull, 100 steps, 1 um noise per coordinate) of the
    cantilever with E and tau_d known, fitted from E 30% high and tau_d 2.5x: both recovered
    within three standard errors, the residual at the noise."""
    n, dt = 100, T1 / 50
    t = np.arange(n + 1) * dt
    pull = (np.sin(np.pi * np.minimum(t / T1, 0.5)) ** 2)[:, None]
    truth = {"sections[*].E": E, "sections[*].damping": 2e-4}
    traj = simulate(robot(2e-4), dt, tensions=pull, gravity=None, solver=SOLVER)
    noise = 1e-6
    tip = np.asarray(traj.tip_position) + noise * np.random.default_rng(0).standard_normal((n + 1, 3))
    fit = tdct.fit_motion(robot(5e-4, 1.3 * E), tdct.Motion(dt, pull, tip), gravity=None, solver=SOLVER)
    assert fit.converged
    for name, value in truth.items():
        assert abs(fit.values[name] - value) < 3 * fit.std_errors[name]
        assert fit.std_errors[name] < 0.01 * value
    assert fit.rmse_after == pytest.approx(np.sqrt(3) * noise, rel=0.2)
