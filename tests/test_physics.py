"""The solver against truths it did not produce: closed-form beams, equilibrium, RK4 order, limits."""

import jax
import numpy as np
import pytest
from conftest import NO_GRAVITY, rel_err, section
from scipy.integrate import simpson
from scipy.optimize import brentq
from scipy.special import ellipe, ellipeinc, ellipk, ellipkinc

import tdct_jax as tdct
from tdct_jax import shooting
from tdct_jax.inputs import gravity_vector
from tdct_jax.segments import Segment, State, strains
from tdct_jax.so3 import hat, orthonormalize

G = np.array([0.0, -9.81, 0.0])


def test_small_deflection_matches_timoshenko_without_tube(robot):
    P = 1e-4
    sol = tdct.solve(robot, tdct.Actuation(), tdct.Loads(tip_force=(0.0, -P, 0.0)), gravity=NO_GRAVITY, throw=True)
    L, sec = float(robot.length), section(robot)
    exact = P * L**3 / (3 * sec.E * sec.I_x) + P * L / (sec.G * sec.A)
    assert rel_err(-sol.tip_position[1], exact) < 1e-3


def test_small_deflection_with_tube_to_tip_has_no_shear_term(robot):
    P = 1e-3
    act = tdct.Actuation(insertions=robot.length)
    sol = tdct.solve(robot, act, tdct.Loads(tip_force=(P, 0.0, 0.0)), gravity=NO_GRAVITY, throw=True)
    sec = section(robot)
    EI = sec.E * sec.I_y + sec.EI_tube
    assert rel_err(sol.tip_position[0], P * robot.length**3 / (3 * EI)) < 1e-3


def bisshopp_drucker(alpha):
    """Exact tip drop and horizontal reach / L of an inextensible cantilever under a dead tip load."""

    def excess(theta0):
        m = (1 + np.sin(theta0)) / 2
        phi1 = np.arcsin(1 / np.sqrt(2 * m))
        return ellipk(m) - ellipkinc(phi1, m) - np.sqrt(alpha)

    theta0 = brentq(excess, 1e-9, np.pi / 2 - 1e-12)
    m = (1 + np.sin(theta0)) / 2
    phi1 = np.arcsin(1 / np.sqrt(2 * m))
    drop = 1 - 2 / np.sqrt(alpha) * (ellipe(m) - ellipeinc(phi1, m))
    return drop, np.sqrt(2 * np.sin(theta0) / alpha), theta0


@pytest.mark.parametrize("alpha", [1.0, 5.0])
def test_large_deflection_matches_elliptic_integral_solution(alpha):
    # A slender rod (d/L = 0.002) with nu near -1 makes extension and shear negligible.
    rod = tdct.Robot.paper(
        length=1.0,
        outer_diameter=2e-3,
        channel_diameter=1e-5,
        tube_outer_diameter=1e-5,
        tube_inner_diameter=0.0,
        tendon_channel_diameter=0.0,
        tendon_offset=0.0,
        nu_silicone=-0.999,
    )
    EI = section(rod).E * section(rod).I_x
    sol = tdct.solve(rod, tdct.Actuation(), tdct.Loads(tip_force=(0.0, -alpha * EI, 0.0)), gravity=NO_GRAVITY, throw=True)
    drop, reach, theta0 = bisshopp_drucker(alpha)
    assert rel_err(-sol.tip_position[1], drop) < 1e-3
    assert rel_err(sol.tip_position[2], reach) < 1e-3
    assert rel_err(-sol.tip_angle, theta0) < 1e-3


@pytest.mark.parametrize("tendon", [0, 1])
def test_single_tendon_bends_into_a_circular_arc(robot, tendon):
    tau = np.zeros(4)
    tau[tendon] = 3.0
    sol = tdct.solve(robot, tdct.Actuation(tensions=tau), gravity=NO_GRAVITY, throw=True)
    # no tube (d = 0): the robot is the interval [d, L], the second; the first, [0, 0], is empty
    kappa = np.linalg.norm(np.asarray(sol.curvature), axis=1)[len(sol.s) // 2 :]
    assert np.ptp(kappa) / kappa.mean() < 1e-8
    sec = section(robot)
    I = sec.I_x if tendon == 0 else sec.I_y
    assert rel_err(kappa.mean(), 3.0 * float(robot.tendons[0].offset) / (sec.E * I)) < 1e-2
    # The points lie on a circle through the base, tangent to +z there, of radius |v| / |u|
    # (u is per undeformed length; the tendon also shortens the robot).
    p = np.asarray(sol.position)
    normal = np.cross(np.asarray(sol.rotation)[0] @ np.asarray(sol.curvature)[0], [0.0, 0.0, 1.0])
    centre = normal / np.linalg.norm(normal) * np.linalg.norm(sol.strain[0]) / kappa.mean()
    assert np.ptp(np.linalg.norm(p - centre, axis=1)) < 1e-9
    # Tendon 1 (body +y) lifts the tip toward +y; tendon 2 (body -x) pulls it toward -x.
    assert p[-1, 1] > 0.01 if tendon == 0 else p[-1, 0] < -0.01


CASES = {
    "planar": (tdct.Actuation(tensions=(8.0, 0, 0, 0), insertions=0.05), tdct.Loads.from_mass(0.03)),
    "3d": (
        tdct.Actuation(tensions=(6.0, 0, 3.0, 2.0), insertions=0.07),
        tdct.Loads(tip_force=(0.1, -0.2, 0.05), tip_moment=(1e-3, 0.0, 2e-3)),
    ),
}


def _equilibrium_defect(robot, act, load, sol):
    """Base load minus the tip load and the weight (force), and minus their moments about the base."""
    s, p = np.asarray(sol.s), np.asarray(sol.position)
    d = float(act.insertion)
    nb = len(s) // 2  # [0, d] and [d, L], steps + 1 nodes each
    sec = section(robot)
    rho_b, rho_s = sec.rho + sec.rho_tube, sec.rho
    weight = G * (rho_s * float(robot.length) + (rho_b - rho_s) * d)
    lever = simpson(np.cross(p[:nb], rho_b * G), x=s[:nb], axis=0) + simpson(np.cross(p[nb:], rho_s * G), x=s[nb:], axis=0)
    F, M = np.asarray(load.tip_force), np.asarray(load.tip_moment)
    force = np.asarray(sol.total_force[0]) - (F + weight)
    moment = np.asarray(sol.total_moment[0]) - (np.cross(p[-1], F) + M + lever)
    scale_f = np.linalg.norm(F) + np.linalg.norm(weight) + float(np.sum(act.tensions))
    return np.abs(force).max() / scale_f, np.abs(moment).max() / (scale_f * float(robot.length))


@pytest.mark.parametrize("case", CASES)
def test_global_equilibrium_and_continuity_at_transition(robot, case):
    act, load = CASES[case]
    sol = tdct.solve(robot, act, load, throw=True)
    f_err, m_err = _equilibrium_defect(robot, act, load, sol)
    # Force: round-off. Moment: Simpson's rule for the weight's lever on the solver's nodes is the
    # limit (4.9e-9 at 16 steps, against 0.65% for the paper's printed transition).
    assert f_err < 1e-12 and m_err < 1e-8
    # Both sides of s = d are nodes: total (rod + tendon) force and moment and the position equal
    # there; the rod's own force jumps by the tendons' pull.
    k = len(sol.s) // 2
    assert float(sol.s[k - 1]) == float(sol.s[k]) == pytest.approx(float(act.insertion))
    for field in ("position", "total_force", "total_moment"):
        a = np.asarray(getattr(sol, field))
        assert np.max(np.abs(a[k] - a[k - 1])) <= 1e-15 * np.abs(a).max()


def test_paper_options_show_the_known_equilibrium_defect(robot):
    act, load = CASES["planar"]
    sol = tdct.solve(robot, act, load, solver=tdct.SolverOptions(transition="paper", tendon_model="paper"), throw=True)
    f_err, m_err = _equilibrium_defect(robot, act, load, sol)
    print(f"paper transition: relative force defect {f_err:.3g}, moment defect {m_err:.3g}")
    assert f_err > 1e-4


@pytest.mark.slow
def test_rk4_is_fourth_order(robot):
    act, load = tdct.Actuation(tensions=(10.0, 0, 0, 0), insertions=0.04), tdct.Loads.from_mass(0.05)
    # the reference: 400 steps, the configuration test_calibrate's interpolation check compiles
    tips = {n: np.asarray(tdct.solve(robot, act, load, solver=tdct.SolverOptions(steps=n)).tip_position) for n in (10, 20, 400)}
    e_coarse = np.linalg.norm(tips[10] - tips[400])
    e_fine = np.linalg.norm(tips[20] - tips[400])
    print(f"tip error {e_coarse:.3g} m at 10 steps, {e_fine:.3g} m at 20 (against 400): ratio {e_coarse / e_fine:.1f}")
    assert 10 < e_coarse / e_fine < 20


def test_rk4_equals_classical_steps_written_out(paper_case):
    """Both segments in one scan (integrate.rk4 over two pieces) equal classical RK4 written out
    step by step, each segment with its own vector field, at every node."""
    robot, act, load, sol = paper_case
    solver, g = tdct.SolverOptions(steps=4), gravity_vector(tdct.STANDARD_GRAVITY)
    F_c = shooting.force_scale(robot, act, load, g)
    x = shooting.scaled(robot, sol.base_wrench, F_c)
    _, (carry, pl, *_) = shooting.shoot(robot, act, load, g, solver, x, F_c, path=True)
    nodes = carry.y

    def axpy(a, x, y):
        return State(*(yi + a * xi for xi, yi in zip(x, y, strict=True)))

    def vector_field(seg):  # the Cosserat rod of rod plus tendons: N' = -rho g, M' = -p' x N
        def f(y):
            v, u = strains(seg, y.R, y.N, y.M)
            dp = y.R @ v
            return State(dp, y.R @ hat(u), -seg.rho * g, -np.cross(dp, y.N))

        return f

    r = np.stack([np.asarray(t.position(0.0)[0]) for t in robot.tendons])
    y = State(np.zeros(3), np.eye(3), *np.split(np.asarray(sol.base_wrench), 2))
    ys = []
    for k, length in enumerate((act.insertion, robot.length - act.insertion)):
        P = jax.tree.map(lambda a, k=k: a[k], pl.intervals)
        f, h = vector_field(Segment(P.K_se, P.K_bt, P.rho, P.tau, r, P.backbone)), length / solver.steps
        ys.append(y)
        for _ in range(solver.steps):
            k1 = f(y)
            k2 = f(axpy(h / 2, k1, y))
            k3 = f(axpy(h / 2, k2, y))
            k4 = f(axpy(h, k3, y))
            y = State(*(yi + h / 6 * (a + 2 * b + 2 * c + d) for yi, a, b, c, d in zip(y, k1, k2, k3, k4, strict=True)))
            y = y._replace(R=orthonormalize(y.R))
            ys.append(y)
    flat = jax.tree.map(lambda a: np.asarray(a).reshape(-1, *a.shape[2:]), nodes)
    np.testing.assert_allclose(flat.p, np.stack([y.p for y in ys]), rtol=0, atol=1e-13)
    np.testing.assert_allclose(flat.R, np.stack([y.R for y in ys]), rtol=0, atol=1e-12)
    for name in ("N", "M"):
        ref = np.stack([getattr(y, name) for y in ys])
        assert rel_err(getattr(flat, name), ref) < 1e-12


def test_rotations_stay_on_so3(paper_case):
    R = np.asarray(paper_case[3].rotation)
    assert np.abs(np.einsum("nji,njk->nik", R, R) - np.eye(3)).max() < 1e-12


@pytest.fixture(scope="session")
def tip_vs_insertion(robot):
    load = tdct.Loads.from_mass(0.05)
    tensions = (10.0, 0, 0, 0)

    def tip(d):
        return tdct.solve(robot, tdct.Actuation(tensions, d), load).tip_position

    def dtip(d):
        return tdct.kinematic_jacobian(robot, tdct.Actuation(tensions, d), load)[:3, -1]

    return tip, dtip


@pytest.mark.parametrize("d", [0.0, 0.16])
def test_tip_and_its_insertion_derivative_are_continuous_at_the_limits(robot, tip_vs_insertion, d):
    tip, dtip = tip_vs_insertion
    sign = 1.0 if d == 0 else -1.0

    # No jump and no kink: the Taylor remainder of a step toward the interior falls as its square.
    def remainder(eps):
        return np.linalg.norm(np.asarray(tip(d + eps) - tip(d)) - eps * np.asarray(dtip(d)))

    assert remainder(sign * 1e-6) < remainder(sign * 1e-5) / 30
    assert rel_err(dtip(d + sign * 1e-7), dtip(d)) < 1e-3
    # The implicit derivative agrees with central differences of the solve.
    h = 1e-5
    fd = (tip(0.08 + h) - tip(0.08 - h)) / (2 * h)
    assert rel_err(dtip(0.08), fd) < 1e-6


def test_soft_tube_reproduces_the_silicone_only_robot():
    # With a tube of negligible stiffness and mass, d = L differs from d = 0 only by shear,
    # which nu near -1 makes negligible.
    soft = tdct.Robot.paper(E_tube=1e-3, density_tube=0.0, nu_silicone=-0.999)
    act, load = tdct.Actuation(tensions=(5.0, 2.0, 0, 0)), tdct.Loads.from_mass(0.02)
    free = tdct.solve(soft, act, load, throw=True)
    full = tdct.solve(soft, tdct.Actuation(tensions=act.tensions, insertions=soft.length), load, throw=True)
    n = len(free.s) // 2  # both grids: steps + 1 nodes over [0, L], in the first or the second interval
    assert rel_err(full.position[:n], free.position[-n:]) < 1e-4
