"""Frictionless contact with obstacles (issue 26): small-deflection closed forms, complementarity and
global equilibrium over random scenes, derivatives through contact against central differences,
bad input, and a far scene giving the contact-free solve.

Compiled configurations: the beam with a sphere, the beam with a tilted plane, the bent rod with a
plane and a sphere (single and vmapped), and the bent rod contact free.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import tdct_jax as tdct
from tdct_jax import status
from tdct_jax.solve import Solution, solution_and_compliance, solve_arguments

L, D, E, NU = 0.3, 2e-3, 1e9, 0.3
r = D / 2
EI = E * np.pi / 64 * D**4
GA = E / (2 * (1 + NU)) * np.pi / 4 * D**2
ZERO_G = (0.0, 0.0, 0.0)
EQUILIBRIUM_ATOL = 1e-9  # N and N m


def beam(tendon=False):
    """A weightless uniform rod along +z; with ``tendon``, one tendon at body +y to the tip."""
    section = tdct.Section(end=L, outer_diameter=D, E=E, nu=NU, density=0.0)
    tendons = (tdct.Tendon(offset=5e-3, angle=np.pi / 2),) if tendon else ()
    return tdct.Robot(L, (section,), tendons)


# ---- acceptance 1: small-deflection closed forms ----------------------------------------------------

A_PUSH, DELTA, R_SPHERE = L / 2, 1e-4, 1e-3


@pytest.fixture(scope="module")
def pushed():
    """The beam pushed toward -y at s = a by a small sphere placed so that the beam must deflect by
    delta there (its gap at zero load is -delta)."""
    sphere = tdct.Sphere(center=(0.0, R_SPHERE + r - DELTA, A_PUSH), radius=R_SPHERE)
    return tdct.solve(beam(), None, None, gravity=ZERO_G, scene=tdct.Scene((sphere,), every=1))


def test_sphere_pushing_a_cantilever_carries_3_EI_delta_over_a_cubed(pushed):
    c = pushed.contact
    assert pushed.converged
    j = int(np.argmin(np.abs(np.asarray(c.s) - A_PUSH)))
    assert c.s[j] == pytest.approx(A_PUSH, abs=1e-15)
    assert np.count_nonzero(c.active) == 1 and c.active[j, 0]
    F = float(c.force[j, 0])
    # Timoshenko (the model shears with K_se = G A, no shear coefficient): delta = F (a^3 / 3EI + a / GA);
    # what is left is geometric nonlinearity, (delta / a)^2 ~ 4e-7, and RK4's error
    assert F == pytest.approx(DELTA / (A_PUSH**3 / (3 * EI) + A_PUSH / GA), rel=1e-6)
    # Euler-Bernoulli: the shear adds 3 EI / (GA a^2) = 8.7e-5 of the compliance: 1e-3 covers it
    assert F == pytest.approx(3 * EI * DELTA / A_PUSH**3, rel=1e-3)
    # the gap closes (to the solver's tolerance) and the deflection at a is delta
    assert abs(float(c.gap[j, 0])) < 1e-12
    assert float(-c.position[j, 1]) == pytest.approx(DELTA, rel=1e-6)


TILT, W_LOAD = 0.2, 1e-5  # rad, N/m


@pytest.fixture(scope="module")
def propped():
    """The beam under a uniform load w along -y, its tip resting on a frictionless plane through
    the unloaded tip, tilted by TILT about x so that the rest of the body stays clear of it."""
    n = (0.0, np.cos(TILT), -np.sin(TILT))
    plane = tdct.Plane(point=(0.0, -r / np.cos(TILT), L), normal=n)
    load = tdct.Loads(distributed_force=(0.0, -W_LOAD, 0.0))
    return tdct.solve(beam(), None, load, gravity=ZERO_G, scene=tdct.Scene((plane,), every=2))


def test_uniformly_loaded_cantilever_propped_at_the_tip_carries_three_eighths(propped):
    c = propped.contact
    assert propped.converged
    assert np.all(~c.active[:-1]) and c.active[-1, 0]  # only the tip touches
    lift = float(c.force[-1, 0] * c.normal[-1, 0, 1])  # the plane's reaction along +y
    wL = W_LOAD * L
    # the unknown tip reaction R of a propped cantilever: the cantilever's tip deflection under w
    # equals that under R, each with Timoshenko's shear term; phi = 3 EI / (GA L^2)
    phi = 3 * EI / (GA * L**2)
    assert lift == pytest.approx(3 / 8 * wL * (1 + 4 * phi / 3) / (1 + phi), rel=1e-6)
    assert lift == pytest.approx(3 / 8 * wL, rel=1e-3)  # Euler-Bernoulli: phi = 1.1e-5
    assert abs(float(c.gap[-1, 0])) < 1e-12


@pytest.mark.slow
def test_line_contact_on_a_plane_matches_beam_theory():
    """The beam under a uniform load q over a plane parallel to it, delta = 1 mm below its surface:
    clamped at the base, it touches down at s = a and lies flat beyond (zero curvature), so on
    [0, a] w(a) = -delta, w'(a) = 0, M(a) = 0: delta = q a^4 / (72 EI), and the base carries
    2 q a / 3 (Euler-Bernoulli), the plane the rest. Candidates every RK4 step; Newton from the
    contact-free start (the rod 5 mm into the plane) needs ~140 steps to find the contact set."""
    q, delta = 0.02, 1e-3
    plane = tdct.Plane((0.0, -r - delta, 0.0), (0.0, 1.0, 0.0))
    load = tdct.Loads(distributed_force=(0.0, -q, 0.0))
    sol = tdct.solve(
        beam(), None, load, gravity=ZERO_G, scene=tdct.Scene((plane,), every=1), solver=tdct.SolverOptions(max_iter=300)
    )
    a = (72 * EI * delta / q) ** 0.25
    # the touch-down point falls between candidates 15 mm apart: the base force is 7e-4 off at 20
    # steps (3e-5 at 40)
    assert float(-sol.total_force[0, 1]) == pytest.approx(2 * q * a / 3, rel=2e-3)
    c = sol.contact
    lift = float(np.sum(c.force[:, 0] * c.normal[:, 0, 1]))
    assert lift == pytest.approx(q * L - 2 * q * a / 3, rel=2e-3)
    touching = np.asarray(c.s)[np.asarray(c.active[:, 0])]
    assert touching.min() == pytest.approx(a, abs=L / 20) and touching.max() == L


# ---- acceptance 3: complementarity and equilibrium over random scenes -------------------------------

TENSION = 0.3
TIP_FORCE = (2e-3, 0.0, 0.0)  # N: bends the rod out of the tendon's plane by about 2 cm
N_RANDOM = 64


def random_obstacles(n, seed):
    """n random (plane point, plane normal, sphere centre, sphere radius) near the bent rod: the
    tendon bends it toward +y (tip near (0.023, 0.083, 0.283) m, y(s) ~ 0.9 s^2); planes ahead of
    the bend facing back at it (toward -y and the base), spheres anywhere near the body. Some
    touch, some do not; none holds the base."""
    rng = np.random.default_rng(seed)
    s = rng.uniform(0.3, 1.0, n) * L
    angle = rng.uniform(-0.6, 0.0, n)
    point = np.stack([np.zeros(n), 0.9 * s**2 * rng.uniform(0.5, 4.0, n), s], 1)
    normal = np.stack([rng.uniform(-0.2, 0.2, n), -np.cos(angle), np.sin(angle)], 1)
    centre = np.stack([rng.uniform(0.0, 0.02, n), rng.uniform(0.0, 0.15, n), rng.uniform(0.1, 0.35, n)], 1)
    radius = rng.uniform(0.005, 0.03, n)
    return point, normal, centre, radius


def scene_of(point, normal, centre, radius):
    return tdct.Scene((tdct.Plane(point, normal, name="wall"), tdct.Sphere(centre, radius, name="ball")), every=2)


def _solve_one(obstacle):
    act = tdct.Actuation([TENSION])
    return tdct.solve(beam(True), act, tdct.Loads(jnp.asarray(TIP_FORCE)), gravity=ZERO_G, scene=scene_of(*obstacle), throw=False)


# lax.map, not vmap: one configuration after another, each running only the solver branches it
# needs (under vmap every lane runs the smoothed fallback once one lane does)
_solve_chunk = jax.jit(lambda obs: jax.lax.map(_solve_one, obs))


def solve_random(n, seed):
    """n random scenes solved N_RANDOM at a time (the last chunk padded with its last scene), so
    every n runs the one compiled program."""
    obstacles = random_obstacles(n, seed)
    padded = -(-n // N_RANDOM) * N_RANDOM
    arrays = [np.concatenate([a, np.repeat(a[-1:], padded - n, axis=0)]) for a in obstacles]
    chunks = [_solve_chunk(tuple(jnp.asarray(a[i : i + N_RANDOM]) for a in arrays)) for i in range(0, padded, N_RANDOM)]
    return obstacles, jnp.asarray(TIP_FORCE), jax.tree.map(lambda *c: np.concatenate(c)[:n], *chunks)


@pytest.fixture(scope="module", params=[pytest.param(N_RANDOM, id="64"), pytest.param(1000, id="1000", marks=pytest.mark.slow)])
def random_scenes(request):
    return solve_random(request.param, 0)


def test_random_scenes_converge_or_are_flagged(random_scenes):
    _, _, sol = random_scenes
    codes = np.asarray(sol.result)
    ok = codes == status.SUCCESS
    assert np.all(ok | np.isin(codes, [status.CONTACT_UNCONVERGED, status.PENETRATION, status.NONFINITE]))
    assert ok.mean() > 0.9, np.unique(codes, return_counts=True)
    touching = np.asarray(sol.contact.active).any(axis=(1, 2))
    assert touching[ok].sum() > codes.size // 4 and (~touching[ok]).sum() > 0  # both kinds are exercised


def test_complementarity_at_every_candidate(random_scenes):
    _, _, sol = random_scenes
    ok = np.asarray(sol.converged)
    force, gap = np.asarray(sol.contact.force)[ok], np.asarray(sol.contact.gap)[ok]
    # the solver's tolerance, 1e-10 on each Fischer-Burmeister row phi(force / F_c, gap / L), with
    # F_c = 0.302 N here (tension and tip load)
    tol_f, tol_g = 1e-10 * 0.302, 1e-10 * L  # N, m
    assert force.min() >= -tol_f
    assert gap.min() >= -tol_g
    assert np.max(force * gap) <= max(force.max(), 0.302) * tol_g


def test_global_equilibrium_with_the_contact_forces(random_scenes):
    """N(0) is the sum of every external force on the robot (tip load, contact forces; no weight),
    M(0) the sum of their moments about the base at the origin: the tendons' loads are internal."""
    _, tip_force, sol = random_scenes
    ok = np.asarray(sol.converged)
    c = jax.tree.map(lambda a: np.asarray(a)[ok], sol.contact)
    on_robot = c.force[..., None] * c.normal  # (k, n_c, n_o, 3)
    tip = np.asarray(sol.tip_position)[ok]
    N0 = np.asarray(tip_force) + on_robot.sum(axis=(1, 2))
    M0 = np.cross(tip, np.asarray(tip_force)) + np.cross(c.position[:, :, None], on_robot).sum(axis=(1, 2))
    np.testing.assert_allclose(np.asarray(sol.total_force)[ok, 0], N0, rtol=0, atol=EQUILIBRIUM_ATOL)
    np.testing.assert_allclose(np.asarray(sol.total_moment)[ok, 0], M0, rtol=0, atol=EQUILIBRIUM_ATOL)
    # the wrench on each obstacle is the opposite of what it exerts on the robot
    np.testing.assert_allclose(c.wrench[..., :3].sum(1), -on_robot.sum(axis=(1, 2)), rtol=0, atol=1e-15)


# ---- acceptance 4: derivatives through contact ------------------------------------------------------

SPHERE_C, SPHERE_R = (0.015, 0.085, 0.26), 0.02  # 3 mm into the contact-free shape near s = 0.27 m
# Central differences of step h: truncation (h / scale)^2 relative, the scale being the contact
# force (4.5e-4 N) for the loads, the sphere's radius for its centre; and the solver's error over
# 2 h, about 1e-12 F_c C / h with tol 1e-12. Both stay below 1e-5 with these steps.
TIGHT = tdct.SolverOptions(tol=1e-12)
H = (1e-5, 1e-6, 1e-6)  # tension [N], sphere centre [m], tip force [N]
FD_RTOL = 1e-5


def tip_in_contact(tension, centre, tip_force):
    scene = tdct.Scene((tdct.Sphere(centre, SPHERE_R),), every=2)
    act = tdct.Actuation(jnp.reshape(tension, (1,)))
    return tdct.solve(beam(True), act, tdct.Loads(tip_force), gravity=ZERO_G, scene=scene, solver=TIGHT).tip_position


@pytest.fixture(scope="module")
def contact_point():
    # float64 arrays, not weak-typed scalars: a weak-typed tension traced into the solve gives its
    # Newton loop and its path evaluation different round-off (1e-10 in the contact rows)
    args = tuple(jnp.asarray(x, jnp.float64) for x in (TENSION, SPHERE_C, TIP_FORCE))
    sol = tdct.solve(
        beam(True), tdct.Actuation([TENSION]), tdct.Loads(args[2]), gravity=ZERO_G,
        scene=tdct.Scene((tdct.Sphere(SPHERE_C, SPHERE_R),), every=2), solver=TIGHT,
    )  # fmt: skip
    return args, sol


def test_the_derivative_case_is_in_contact(contact_point):
    _, sol = contact_point
    c = sol.contact
    assert np.count_nonzero(c.active) >= 1
    # away from contact-set changes: every candidate clearly touching or clearly free
    a, b = np.asarray(c.force / np.max(c.force)), np.asarray(c.gap / L)
    assert np.all((a > 1e-3) | (b > 1e-4))


@pytest.mark.slow
def test_derivatives_through_contact_match_central_differences(contact_point):
    args, _ = contact_point
    J = jax.jit(jax.jacfwd(tip_in_contact, argnums=(0, 1, 2)))(*args)
    tip = jax.jit(tip_in_contact)
    for k, h in enumerate(H):
        x = np.asarray(args[k], float)
        cols = []
        for i in range(x.size):
            e = np.zeros(x.size)
            e[i] = h
            plus, minus = list(args), list(args)
            plus[k], minus[k] = jnp.asarray(x + e.reshape(x.shape)), jnp.asarray(x - e.reshape(x.shape))
            cols.append((tip(*plus) - tip(*minus)) / (2 * h))
        fd = np.stack(cols, -1).reshape(np.shape(J[k]))
        scale = np.max(np.abs(fd))
        assert np.max(np.abs(np.asarray(J[k]) - fd)) <= FD_RTOL * scale, k


@pytest.mark.slow
def test_compliance_in_contact_matches_central_differences(contact_point):
    args, _ = contact_point
    scene = tdct.Scene((tdct.Sphere(SPHERE_C, SPHERE_R),), every=2)
    C = tdct.compliance(beam(True), tdct.Actuation([TENSION]), tdct.Loads(args[2]), gravity=ZERO_G, scene=scene, solver=TIGHT)
    tip = jax.jit(tip_in_contact)
    h = H[2]
    fd = np.stack(
        [(tip(args[0], args[1], args[2] + e) - tip(args[0], args[1], args[2] - e)) / (2 * h) for e in h * np.eye(3)], -1
    )
    np.testing.assert_allclose(C, fd, rtol=0, atol=FD_RTOL * np.max(np.abs(fd)))
    free = tdct.compliance(beam(True), tdct.Actuation([TENSION]), tdct.Loads(args[2]), gravity=ZERO_G, solver=TIGHT)
    assert np.linalg.norm(C) < np.linalg.norm(free)  # the obstacle stiffens the tip


# ---- bad input, and a far scene ---------------------------------------------------------------------


def test_base_inside_an_obstacle_is_refused():
    scene = tdct.Scene((tdct.Sphere((0.0, 0.0, 0.0), 0.01, name="lump"),))
    with pytest.raises(ValueError, match="lump"):
        tdct.solve(beam(), None, None, gravity=ZERO_G, scene=scene)


def test_multiple_shooting_with_a_scene_is_refused():
    scene = tdct.Scene((tdct.Plane((0.0, 1.0, 0.0), (0.0, -1.0, 0.0)),))
    with pytest.raises(ValueError, match="intervals = 2"):
        tdct.solve(beam(), None, None, gravity=ZERO_G, scene=scene, solver=tdct.SolverOptions(intervals=2))


def test_a_far_scene_gives_the_contact_free_solve():
    act = tdct.Actuation([TENSION])
    free = tdct.solve(beam(True), act, None, gravity=ZERO_G)
    far = tdct.Scene((tdct.Plane((0.0, -1.0, 0.0), (0.0, 1.0, 0.0)), tdct.Sphere((0.0, 0.0, 2.0), 0.1)), every=4)
    sol = tdct.solve(beam(True), act, None, gravity=ZERO_G, scene=far)
    assert isinstance(sol, Solution) and free.contact is None
    np.testing.assert_allclose(sol.tip_position, free.tip_position, rtol=0, atol=1e-12)
    assert not np.any(sol.contact.active) and np.all(sol.contact.force == 0)
    assert sol.contact.force.shape == (20 // 4, 2)


def test_the_contact_passes_share_one_copy_of_the_integration():
    """Plain Newton, the smoothed solves and the exact one are passes of one loop (``shooting._contact_root``):
    the contact solve's program is the contact-free one's and a little more, not one shooting
    integration per pass (before: 39 while loops against 16, 2.6 times the lines)."""
    act = tdct.Actuation([TENSION])
    far = tdct.Scene((tdct.Plane((0.0, -1.0, 0.0), (0.0, 1.0, 0.0)), tdct.Sphere((0.0, 0.0, 2.0), 0.1)), every=4)
    free, touching = (
        solution_and_compliance.lower(
            *solve_arguments(beam(True), act, None, ZERO_G, None, tdct.SolverOptions(), scene)
        ).as_text()
        for scene in (None, far)
    )
    assert touching.count("stablehlo.while") <= free.count("stablehlo.while") + 4
    assert len(touching.splitlines()) < 1.3 * len(free.splitlines())
