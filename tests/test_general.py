"""The one robot description: robot files, the paper's robot from its file, closed forms (tendon anchored inside the body, point force on a cantilever, point mass),
equilibrium of every piece between breakpoints, and a two-segment six-tendon robot against an
independent numpy/scipy implementation of the Rucker-Webster model.

Three compiled configurations besides the paper robot's: ``rod`` (one anchored tendon, a point
mass and a point load), ``two_segment`` (the shipped file plus a point mass and a point load).
"""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import fsolve, root

import tdct_jax as tdct
from tdct_jax.description import ROBOTS
from tdct_jax.mechanics import compliance_and_solution

PAPER_TIP_RTOL = 1e-12
PAPER_COMPLIANCE_RTOL = 1e-10
EQUILIBRIUM_ATOL = 1e-9  # N and N m
INDEPENDENT_ATOL = 1e-6  # m
G = (0.0, -9.81, 0.0)


def rel(a, b):
    a, b = np.asarray(a, float), np.asarray(b, float)
    return float(np.max(np.abs(a - b)) / np.max(np.abs(b)))


# ---- robot files -------------------------------------------------------------------------------


def test_paper_file_is_the_paper_robot():
    from_file, converted = tdct.Robot.from_toml(ROBOTS / "paper.toml"), tdct.Robot.paper()
    assert isinstance(from_file, tdct.Robot)
    assert jax.tree.structure(from_file) == jax.tree.structure(converted)
    for a, b in zip(jax.tree.leaves(from_file), jax.tree.leaves(converted), strict=True):
        assert float(a) == pytest.approx(float(b), rel=1e-15)


VALID = """
length = 0.4
[[sections]]
end = 0.2
outer_diameter = 0.02
inner_diameter = 0.002
tendon_channel_diameter = 0.001
E = 1e6
nu = 0.45
density = 1100.0
[[sections]]
end = 0.4
outer_diameter = 0.016
inner_diameter = 0.002
tendon_channel_diameter = 0.001
E = 1e6
nu = 0.45
density = 1100.0
[[tendons]]
offset = 0.006
angle_deg = 90
end = 0.2
[[tendons]]
offset = 0.006
angle_deg = 270
twist_deg_per_m = 90
max_tension = 10.0
[[tubes]]
outer_diameter = 0.0015
inner_diameter = 0.001
E = 80e9
nu = 0.33
density = 6450.0
[[masses]]
s = 0.4
mass = 0.01
"""


def write(tmp_path, text):
    path = tmp_path / "robot.toml"
    path.write_text(text)
    return path


def test_robot_file_reads_every_key(tmp_path):
    robot = tdct.Robot.from_toml(write(tmp_path, VALID))
    assert (len(robot.sections), robot.n_tendons, robot.n_tubes, len(robot.masses)) == (2, 2, 1, 1)
    assert float(robot.tendons[1].twist) == pytest.approx(np.pi / 2)
    assert float(robot.tendons[0].end) == 0.2 and robot.tendons[1].end is None
    assert float(robot.tendons[1].max_tension) == 10.0


@pytest.mark.parametrize(
    "old, new, words",
    [
        ("outer_diameter = 0.02\n", "outer_diamter = 0.02\n", ["sections[0]", "outer_diamter", "allowed"]),
        ("length = 0.4\n", "length = 0.4\ncolour = 1\n", ["colour"]),
        ("end = 0.2\nouter_diameter = 0.02", "start = 0.01\nend = 0.2\nouter_diameter = 0.02", ["sections[0].start", "gap"]),
        ("end = 0.4\nouter_diameter = 0.016", "end = 0.1\nouter_diameter = 0.016", ["sections[1].end = 0.1", "greater than 0.2"]),
        ("end = 0.4\nouter_diameter = 0.016", "end = 0.3\nouter_diameter = 0.016", ["sections[1].end = 0.3", "length = 0.4"]),
        ("angle_deg = 90\nend = 0.2", "angle_deg = 90\nend = 0.5", ["tendons[0].end = 0.5", "(0, 0.4]"]),
        ("angle_deg = 90\nend = 0.2", "angle_deg = 90\nend = 0.0", ["tendons[0].end = 0 is outside", "(0, "]),
        ("outer_diameter = 0.0015", "outer_diameter = 0.0025", ["tubes[0].outer_diameter = 0.0025", "channel"]),
        ("angle_deg = 270", "angle_deg = 95", ["tendons[0] and tendons[1]", "overlap"]),
        ("offset = 0.006\nangle_deg = 90", "offset = 0.0099\nangle_deg = 90", ["tendons[0].offset = 0.0099", "0.0095"]),
        ("s = 0.4", "s = 0.41", ["masses[0].s = 0.41", "[0, 0.4]"]),
        ("nu = 0.33", "nu = 0.7", ["tubes[0].nu = 0.7", "(-1, 0.5]"]),
    ],
)
def test_robot_file_errors_name_field_value_and_range(tmp_path, old, new, words):
    assert old in VALID
    with pytest.raises(ValueError) as e:
        tdct.Robot.from_toml(write(tmp_path, VALID.replace(old, new, 1)))
    for w in words:
        assert w in str(e.value), (w, str(e.value))


def test_inputs_are_checked_against_the_robot(tmp_path):
    robot = tdct.Robot.from_toml(write(tmp_path, VALID))
    with pytest.raises(ValueError, match="2 tendons"):
        tdct.solve(robot, tdct.Actuation([1.0, 2.0, 3.0], [0.1]))
    with pytest.raises(ValueError, match=r"tensions\[1\] = 12 .*max_tension"):
        tdct.solve(robot, tdct.Actuation([1.0, 12.0], [0.1]))
    with pytest.raises(ValueError, match=r"point_s = \[0.5\] is outside"):
        tdct.solve(robot, tdct.Actuation([1.0, 2.0], [0.1]), tdct.Loads(point_s=[0.5], point_force=[[0, 0, 1.0]]))
    with pytest.raises(ValueError, match="insertions"):
        tdct.solve(robot, tdct.Actuation([1.0, 2.0], [0.5]))
    rod_only = tdct.Robot(0.3, (tdct.Section(end=0.3, outer_diameter=2e-3, E=1e9, nu=0.3, density=0.0),))
    with pytest.raises(ValueError, match="the paper's variants act where a tube is inside .* this robot has no tube"):
        tdct.solve(rod_only, solver=tdct.SolverOptions(transition="paper"))


# ---- (a) the paper's robot from its file --------------------------------------------------------

PAPER_CASES = [((6.0, 0.0, 0.0, 1.0), 0.08, 0.02), ((3.0, 0.0, 0.0, 5.0), 0.0, 0.0), ((10.0, 0.0, 0.0, 0.0), 0.16, 0.05)]


@pytest.mark.parametrize("tensions, insertion, mass", PAPER_CASES)
def test_paper_robot_from_its_file_solves_as_the_preset(tensions, insertion, mass):
    act, load = tdct.Actuation(tensions, insertion), tdct.Loads.from_mass(mass)
    # one compiled program per robot: the Solution and the 6x6 compliance from the same solve
    C_ref, reference = compliance_and_solution(tdct.Robot.paper(), act, load)
    C_gen, from_file = compliance_and_solution(tdct.Robot.from_toml(ROBOTS / "paper.toml"), act, load)
    assert rel(from_file.tip_position, reference.tip_position) < PAPER_TIP_RTOL
    assert rel(from_file.tip_rotation, reference.tip_rotation) < PAPER_TIP_RTOL
    assert rel(C_gen, C_ref) < PAPER_COMPLIANCE_RTOL
    assert rel(C_gen[:3, :3], tdct.compliance(tdct.Robot.paper(), act, load)) < PAPER_COMPLIANCE_RTOL


# ---- (b), (c): one uniform rod, one tendon anchored inside, a point mass and a point load ----------

ROD_L, ROD_D, ROD_E, ROD_NU = 0.3, 2e-3, 1e9, 0.3
OFFSET, ANCHOR, TENSION = 5e-3, 0.18, 0.5
MID = ROD_L / 2
ARC_ATOL = 5e-9  # RK4's own error on the arc with 20 steps per interval: 3.6e-10 m in position, 1.1e-9 in the tangent


def rod(anchor=ANCHOR, mass=0.0):
    """Weightless (density 0) uniform rod, one tendon at body +y anchored at ``anchor``, a point
    mass at mid-length."""
    section = tdct.Section(end=ROD_L, outer_diameter=ROD_D, E=ROD_E, nu=ROD_NU, density=0.0)
    tendon = tdct.Tendon(offset=OFFSET, angle=np.pi / 2, end=anchor)
    return tdct.Robot(ROD_L, (section,), (tendon,), masses=(tdct.PointMass(MID, mass),))


def point_load(force):
    return tdct.Loads(point_s=[MID], point_force=[force])


def rod_stiffness():
    A, I = np.pi / 4 * ROD_D**2, np.pi / 64 * ROD_D**4
    G = ROD_E / (2 * (1 + ROD_NU))
    return G * A, ROD_E * A, ROD_E * I


@pytest.fixture(scope="session")
def anchored():
    return tdct.solve(rod(), tdct.Actuation([TENSION]), point_load([0.0, 0.0, 0.0]), gravity=G)


def constant_strains():
    """The rod's strains where no external load acts (N = M = 0) and the tendon at r = (0, rho, 0)
    pulls: with u = (u_x, 0, 0), v = (0, v_y, v_z), the constitutive relations reduce to
        GA v_y + tau t_y = 0,   EA (v_z - 1) + tau t_z = 0,   EI u_x + tau rho t_z = 0,
    t = (0, v_y, v_z + u_x rho) / |.|; to leading order u_x = -tau rho / EI."""
    GA, EA, EI = rod_stiffness()

    def F(w):
        vy, vz, ux = w
        pb = np.array([0.0, vy, vz + ux * OFFSET])
        t = pb / np.linalg.norm(pb)
        return [GA * vy + TENSION * t[1], EA * (vz - 1) + TENSION * t[2], EI * ux + TENSION * OFFSET * t[2]]

    vy, vz, ux = fsolve(F, [0.0, 1.0, -TENSION * OFFSET / EI], xtol=1e-15)
    return np.array([0.0, vy, vz]), np.array([ux, 0.0, 0.0])


def test_anchored_tendon_bends_a_circular_arc_then_straight(anchored):
    sol = anchored
    v, u = constant_strains()
    assert u[0] == pytest.approx(-TENSION * OFFSET / rod_stiffness()[2], rel=1e-3)
    s, p = np.asarray(sol.s), np.asarray(sol.position)
    # nodes come interval by interval; those up to the anchor on its near side
    n_nodes = tdct.SolverOptions().steps + 1
    before = np.zeros(s.size, bool)
    for k in range(s.size // n_nodes):
        i = slice(k * n_nodes, (k + 1) * n_nodes)
        if s[i][-1] <= ANCHOR + 1e-15 and s[i][-1] > s[i][0]:
            before[i] = True
    after = s > ANCHOR
    assert before.sum() >= 2 * n_nodes and after.sum() >= n_nodes - 1
    np.testing.assert_allclose(np.asarray(sol.curvature)[before], np.broadcast_to(u, (before.sum(), 3)), rtol=0, atol=1e-9)
    np.testing.assert_allclose(np.asarray(sol.strain)[before], np.broadcast_to(v, (before.sum(), 3)), rtol=0, atol=1e-12)
    # the arc: R(s) = rotation about x by u_x s, p(s) = integral of R v
    th = u[0] * s[before]
    arc = np.stack(
        [0 * th, (v[1] * np.sin(th) + v[2] * (np.cos(th) - 1)) / u[0], (v[1] * (1 - np.cos(th)) + v[2] * np.sin(th)) / u[0]], -1
    )
    np.testing.assert_allclose(p[before], arc, rtol=0, atol=ARC_ATOL)
    # straight beyond the anchor, along the tangent there
    np.testing.assert_allclose(np.asarray(sol.curvature)[after], 0.0, atol=1e-12)
    np.testing.assert_allclose(np.asarray(sol.strain)[after], np.broadcast_to([0, 0, 1.0], (after.sum(), 3)), atol=1e-12)
    i_a = np.flatnonzero(before)[-1]
    t_a = np.asarray(sol.rotation)[i_a, :, 2]
    np.testing.assert_allclose(t_a, [0.0, -np.sin(u[0] * ANCHOR), np.cos(u[0] * ANCHOR)], rtol=0, atol=ARC_ATOL)
    np.testing.assert_allclose(p[after], p[i_a] + np.outer(s[after] - ANCHOR, t_a), rtol=0, atol=1e-13)
    # the tendon's length is s_a |pb| (pb constant along the arc): its displacement s_a (1 - |pb|)
    pb = np.array([0.0, v[1], v[2] + u[0] * OFFSET])
    assert float(sol.displacements[0]) == pytest.approx(ANCHOR * (1 - np.linalg.norm(pb)), rel=1e-9)


def test_point_force_on_a_cantilever_matches_beam_theory():
    F = 1e-5  # N: tip deflection ~ 4e-5 L, geometric nonlinearity ~ 1e-9
    sol = tdct.solve(rod(), tdct.Actuation([0.0]), point_load([0.0, -F, 0.0]), gravity=G)
    GA, _, EI = rod_stiffness()
    a, L = MID, ROD_L
    # Euler-Bernoulli, plus the shear of the model's K_se (no shear coefficient): F a / (G A)
    expected = F * a**2 * (3 * L - a) / (6 * EI) + F * a / GA
    assert float(-sol.tip_position[1]) == pytest.approx(expected, rel=1e-6)


def test_distributed_force_on_a_cantilever_matches_beam_theory():
    w = 1e-5  # N/m, along -y: tip deflection ~ 4e-5 L
    load = tdct.Loads(point_s=[MID], point_force=[[0.0, 0.0, 0.0]], distributed_force=[0.0, -w, 0.0])
    sol = tdct.solve(rod(), tdct.Actuation([0.0]), load, gravity=G)
    GA, _, EI = rod_stiffness()
    expected = w * ROD_L**4 / (8 * EI) + w * ROD_L**2 / (2 * GA)
    assert float(-sol.tip_position[1]) == pytest.approx(expected, rel=1e-6)
    np.testing.assert_allclose(sol.total_force[0], [0.0, -w * ROD_L, 0.0], rtol=0, atol=1e-18)


def test_point_mass_gives_the_shape_of_the_equal_point_force():
    m = 2e-3
    act = tdct.Actuation([0.3])
    by_force = tdct.solve(rod(), act, point_load(m * np.asarray(G)), gravity=G)
    by_mass = tdct.solve(rod(mass=m), act, point_load([0.0, 0.0, 0.0]), gravity=G)
    np.testing.assert_allclose(by_mass.position, by_force.position, rtol=0, atol=1e-14)
    np.testing.assert_allclose(by_mass.total_force[0], m * np.asarray(G), rtol=0, atol=1e-16)


@pytest.mark.slow
def test_derivatives_in_anchor_and_tension_match_central_differences():
    def tip(anchor, tension):
        return tdct.solve(rod(anchor), tdct.Actuation(jnp.stack([tension])), point_load([0.0, 0.0, 0.0]), gravity=G).tip_position

    J = jax.jacfwd(tip, argnums=(0, 1))(ANCHOR, TENSION)
    h_a, h_t = 1e-4, 1e-4
    fd_a = (tip(ANCHOR + h_a, TENSION) - tip(ANCHOR - h_a, TENSION)) / (2 * h_a)
    fd_t = (tip(ANCHOR, TENSION + h_t) - tip(ANCHOR, TENSION - h_t)) / (2 * h_t)
    assert rel(J[0], fd_a) < 1e-6
    assert rel(J[1], fd_t) < 1e-6


# ---- (d), (e): the two-segment six-tendon robot ----------------------------------------------------

TWO_TENSIONS = [1.5, 0.0, 0.4, 0.0, 0.8, 0.3]
TWO_TIP_FORCE = np.array([0.02, 0.0, 0.0])
MASS_S = 0.3
POINT_S, POINT_F, POINT_C = 0.1, np.array([0.0, 0.05, -0.02]), np.array([1e-3, 0.0, 5e-4])


def two_segment(mass):
    """The shipped two_segment.toml (segment 1's tendons at 90, -30, 210 deg anchored at 0.2 m,
    segment 2's staggered by 60 deg to 150, 30, 270 deg at the tip) with a point mass at 0.3 m."""
    robot = tdct.Robot.from_toml(ROBOTS / "two_segment.toml")
    return dataclasses.replace(robot, masses=(tdct.PointMass(MASS_S, mass),))


@pytest.fixture(scope="session")
def loaded_two_segment():
    load = tdct.Loads(
        tip_force=TWO_TIP_FORCE, tip_moment=[0.0, 0.0, 2e-3], point_s=[POINT_S], point_force=[POINT_F], point_moment=[POINT_C]
    )
    mass = 0.005
    return tdct.solve(two_segment(mass), tdct.Actuation(TWO_TENSIONS), load, gravity=G), load, mass


def simpson(y, s):
    h = (s[-1] - s[0]) / (len(s) - 1)
    return h / 3 * (y[0] + y[-1] + 4 * y[1:-1:2].sum(0) + 2 * y[2:-1:2].sum(0))


def test_equilibrium_of_the_whole_robot_and_of_every_piece(loaded_two_segment):
    sol, load, mass = loaded_two_segment
    g = np.asarray(G)
    rho = 6450.0 * np.pi / 4 * 1.4e-3**2 * g  # weight per length [N/m]
    s, p = np.asarray(sol.s), np.asarray(sol.position)
    N, M = np.asarray(sol.total_force), np.asarray(sol.total_moment)
    m = tdct.SolverOptions().steps + 1
    K = s.size // m
    weight_moment = np.zeros(3)
    for k in range(K):
        i0, i1 = k * m, k * m + m - 1
        piece = slice(i0, i1 + 1)
        length = s[i1] - s[i0]
        lever = simpson(np.cross(p[piece] - p[i0], rho), s[piece]) if length > 0 else 0.0
        np.testing.assert_allclose(N[i0] - N[i1], rho * length, rtol=0, atol=EQUILIBRIUM_ATOL)
        np.testing.assert_allclose(M[i0] - M[i1] - np.cross(p[i1] - p[i0], N[i1]) - lever, 0.0, rtol=0, atol=EQUILIBRIUM_ATOL)
        weight_moment += simpson(np.cross(p[piece], rho), s[piece]) if length > 0 else 0.0
        if k + 1 < K:  # the jump at the breakpoint between pieces k and k + 1
            dN, dM = N[i1 + 1] - N[i1], M[i1 + 1] - M[i1]
            F = -POINT_F if s[i1] == POINT_S else -mass * g if s[i1] == MASS_S else np.zeros(3)
            C = -POINT_C if s[i1] == POINT_S else np.zeros(3)
            np.testing.assert_allclose(dN, F, rtol=0, atol=EQUILIBRIUM_ATOL)
            np.testing.assert_allclose(dM, C, rtol=0, atol=EQUILIBRIUM_ATOL)
    at = {x: p[np.flatnonzero(s == x)[0]] for x in (POINT_S, MASS_S)}
    base_force = TWO_TIP_FORCE + POINT_F + mass * g + rho * 0.4
    base_moment = (
        np.asarray(load.tip_moment)
        + np.cross(p[-1], TWO_TIP_FORCE)
        + POINT_C
        + np.cross(at[POINT_S], POINT_F)
        + np.cross(at[MASS_S], mass * g)
        + weight_moment
    )
    np.testing.assert_allclose(sol.total_force[0], base_force, rtol=0, atol=EQUILIBRIUM_ATOL)
    np.testing.assert_allclose(sol.total_moment[0], base_moment, rtol=0, atol=EQUILIBRIUM_ATOL)


def test_anchor_force_is_the_change_in_the_rods_own_force(loaded_two_segment):
    """Across s = 0.2 m the rod's n, m change by segment 1's tendons' pull at their anchor, tau R t,
    and by the kink of segment 2's tendons, whose tangent follows the jump in curvature: the total
    N, M carry on unchanged."""
    sol = loaded_two_segment[0]
    s = np.asarray(sol.s)
    before, after = np.flatnonzero(s == 0.2)[[0, -1]]
    R = np.asarray(sol.rotation)[before]
    n, m = np.asarray(sol.force), np.asarray(sol.moment)
    U, V = np.asarray(sol.curvature), np.asarray(sol.strain)
    dn, dm = np.zeros(3), np.zeros(3)
    for i, (angle, tau) in enumerate(zip([90, -30, 210, 150, 30, 270], TWO_TENSIONS, strict=True)):
        r = 0.01 * np.array([np.cos(np.radians(angle)), np.sin(np.radians(angle)), 0.0])
        pb = [np.cross(U[j], r) + V[j] for j in (before, after)]
        t = [x / np.linalg.norm(x) for x in pb]
        f = tau * R @ (t[0] if i < 3 else t[0] - t[1])
        dn, dm = dn + f, dm + np.cross(R @ r, f)
    np.testing.assert_allclose(n[after] - n[before], dn, rtol=0, atol=1e-12)
    np.testing.assert_allclose(m[after] - m[before], dm, rtol=0, atol=1e-14)
    np.testing.assert_allclose(sol.total_force[after], sol.total_force[before], rtol=0, atol=1e-14)


def hat(x):
    return np.array([[0, -x[2], x[1]], [x[2], 0, -x[0]], [-x[1], x[0], 0]])


def rucker_webster_tip(L, D, E, nu, density, tendons, gravity, tip_force):
    """Independent reference, numpy/scipy only: Rucker and Webster (2011), general tendon routing,
    the rod's own strains (v, u) as state with eq. 1's linear system for (v', u'), DOP853, shooting
    on the rod's base force and moment with scipy's hybr. Tendons (offset, angle [rad], anchor,
    tension, twist [rad/m]) at r(s) = offset (cos(angle + twist s), sin(...), 0), so that
    pb = u x r + v + r' and a = A (u x pb + u x r' + r''); a solid round backbone; gravity and a
    tip force.

    At an anchor inside the body the rod takes the ending tendons' pull tau R t (n(s+) = n(s-) +
    tau R t) and, for every tendon that passes on, the kink its tangent makes where the curvature
    jumps, tau R (t(s-) - t(s+)) with t(s+) from the new strains (solved with fsolve): without
    that kink this robot's tip moves by 1.4e-6 m and the balance of the rod plus tendons fails.
    """
    e3 = np.array([0.0, 0.0, 1.0])
    A, I = np.pi / 4 * D**2, np.pi / 64 * D**4
    Gm = E / (2 * (1 + nu))
    Kse, Kbt = np.diag([Gm * A, Gm * A, E * A]), np.diag([E * I, E * I, Gm * 2 * I])
    f = density * A * np.asarray(gravity, float)

    def routing(off, a0, k):
        """s -> (r, r', r''), body frame."""

        def route(s):
            c, sn = np.cos(a0 + k * s), np.sin(a0 + k * s)
            return off * np.array([c, sn, 0.0]), off * k * np.array([-sn, c, 0.0]), -off * k**2 * np.array([c, sn, 0.0])

        return route

    tend = [(routing(t[0], t[1], t[4] if len(t) > 4 else 0.0), t[2], t[3]) for t in tendons]
    cuts = sorted({s_a for _, s_a, _ in tend} | {L})

    def rhs(s, y, active):
        R, v, u = y[3:12].reshape(3, 3), y[12:15], y[15:18]
        Am, Bm, Gmat, Hm, a, b = np.zeros((3, 3)), np.zeros((3, 3)), np.zeros((3, 3)), np.zeros((3, 3)), np.zeros(3), np.zeros(3)
        for route, tau in active:
            r, dr, ddr = route(s)
            pb = np.cross(u, r) + v + dr
            At = -tau * hat(pb) @ hat(pb) / np.linalg.norm(pb) ** 3
            Bt, at = hat(r) @ At, At @ (np.cross(u, pb) + np.cross(u, dr) + ddr)
            Am, Bm, Gmat, Hm, a, b = Am + At, Bm + Bt, Gmat - At @ hat(r), Hm - Bt @ hat(r), a + at, b + hat(r) @ at
        c = -np.cross(u, Kbt @ u) - np.cross(v, Kse @ (v - e3)) - b
        d = -np.cross(u, Kse @ (v - e3)) - R.T @ f - a
        w = np.linalg.solve(np.block([[Kse + Am, Gmat], [Bm, Kbt + Hm]]), np.concatenate([d, c]))
        return np.concatenate([R @ v, (R @ hat(u)).ravel(), w])

    def pull(s, R, v, u, group):
        F, C = np.zeros(3), np.zeros(3)
        for route, tau in group:
            r, dr, _ = route(s)
            pb = np.cross(u, r) + v + dr
            Ft = -tau * R @ pb / np.linalg.norm(pb)
            F, C = F + Ft, C + np.cross(R @ r, Ft)
        return F, C

    def integrate(x):
        n0, m0 = x[:3], x[3:] * L
        y = np.concatenate([np.zeros(3), np.eye(3).ravel(), e3 + np.linalg.solve(Kse, n0), np.linalg.solve(Kbt, m0)])
        s0 = 0.0
        for s1 in cuts:
            active = [(r, tau) for r, s_a, tau in tend if s_a >= s1]
            y = solve_ivp(rhs, (s0, s1), y, args=(active,), method="DOP853", rtol=1e-11, atol=1e-14).y[:, -1]
            R, v, u = y[3:12].reshape(3, 3), y[12:15], y[15:18]
            n, m = R @ Kse @ (v - e3), R @ Kbt @ u
            F, C = pull(s1, R, v, u, [(r, tau) for r, s_a, tau in tend if s_a == s1])
            if s1 == L:
                return y, np.concatenate([n - (tip_force + F), (m - C) / L])
            passing = [(r, tau) for r, s_a, tau in tend if s_a > s1]
            Fp, Cp = pull(s1, R, v, u, passing)

            def after(w, s1=s1, R=R, n=n, m=m, F=F, C=C, Fp=Fp, Cp=Cp, passing=passing):
                Fq, Cq = pull(s1, R, w[:3], w[3:], passing)
                return np.concatenate([Kse @ (w[:3] - e3) - R.T @ (n - F + Fq - Fp), Kbt @ w[3:] - R.T @ (m - C + Cq - Cp)])

            y = np.concatenate([y[:12], fsolve(after, np.concatenate([v, u]), xtol=1e-13)])
            s0 = s1

    x0 = -sum(np.concatenate([tau * e3, tau * np.cross(route(0.0)[0], e3) / L]) for route, _, tau in tend)
    sol = root(lambda x: integrate(x)[1], x0, method="hybr", options=dict(xtol=1e-13))
    y, res = integrate(sol.x)
    assert np.max(np.abs(res)) < 1e-9, res
    return y[:3]


def test_two_segment_robot_matches_an_independent_implementation():
    """Acceptance item 4; the robot of ``two_segment`` with its point mass and point load at zero."""
    sol = tdct.solve(
        two_segment(0.0),
        tdct.Actuation(TWO_TENSIONS),
        tdct.Loads(tip_force=TWO_TIP_FORCE, point_s=[POINT_S], point_force=[[0.0, 0.0, 0.0]]),
        gravity=G,
    )
    angles = np.radians([90, -30, 210, 150, 30, 270])
    anchors = [0.2] * 3 + [0.4] * 3
    tendons = [(0.01, a, e, t) for a, e, t in zip(angles, anchors, TWO_TENSIONS, strict=True)]
    reference = rucker_webster_tip(0.4, 1.4e-3, 54e9, 0.3, 6450.0, tendons, G, TWO_TIP_FORCE)
    np.testing.assert_allclose(sol.tip_position, reference, rtol=0, atol=INDEPENDENT_ATOL)
    assert np.max(np.abs(np.asarray(sol.tip_position) - reference)) < 1e-8  # measured 3e-10 m


HELIX = np.radians(90.0)  # rad/m


def test_helical_tendons_match_the_independent_implementation():
    """Segment 2's tendons wound helically, 90 deg per metre (36 deg over the robot): the tendon
    tangent gains r_t' and the distributed load u x r_t' + r_t''."""
    robot = two_segment(0.0)
    tendons = tuple(dataclasses.replace(t, twist=HELIX) if i >= 3 else t for i, t in enumerate(robot.tendons))
    robot = dataclasses.replace(robot, tendons=tendons)
    sol = tdct.solve(robot, tdct.Actuation(TWO_TENSIONS), tdct.Loads(tip_force=TWO_TIP_FORCE), gravity=G)
    angles = np.radians([90, -30, 210, 150, 30, 270])
    anchors = [0.2] * 3 + [0.4] * 3
    twists = [0.0] * 3 + [HELIX] * 3
    tendons = [(0.01, a, e, t, k) for a, e, t, k in zip(angles, anchors, TWO_TENSIONS, twists, strict=True)]
    reference = rucker_webster_tip(0.4, 1.4e-3, 54e9, 0.3, 6450.0, tendons, G, TWO_TIP_FORCE)
    np.testing.assert_allclose(sol.tip_position, reference, rtol=0, atol=INDEPENDENT_ATOL)
    assert np.max(np.abs(np.asarray(sol.tip_position) - reference)) < 1e-8


# ---- displacement control ----------------------------------------------------------------------

DRIVEN = (0, 2, 4, 5)  # mixed control: tendons 1 and 3 (zero tension) stay tension-controlled


@pytest.fixture(scope="session")
def by_tension():
    robot = tdct.Robot.from_toml(ROBOTS / "two_segment.toml")
    load = tdct.Loads(tip_force=TWO_TIP_FORCE)
    return robot, load, tdct.solve(robot, tdct.Actuation(TWO_TENSIONS), load, gravity=G)


@pytest.mark.slow
def test_displacements_fed_back_return_the_tensions_and_the_shape(by_tension):
    """Acceptance item 5: a tension-controlled solution's displacements, fed back as displacement
    control (from zero tensions), give back its tensions and shape."""
    robot, load, sol = by_tension
    d = np.asarray(sol.displacements)
    act = tdct.Actuation(np.zeros(6), displacements=d[list(DRIVEN)], driven=DRIVEN)
    # the residual tolerance is relative to the typical force, which counts the pulls' tensions
    back = tdct.solve(robot, act, load, gravity=G, solver=tdct.SolverOptions(tol=1e-12))
    assert rel(back.tensions, TWO_TENSIONS) < 1e-9
    assert rel(back.position, sol.position) < 1e-9
    assert not np.any(back.slack)
    np.testing.assert_allclose(back.displacements, d, rtol=1e-9)


@pytest.mark.slow
def test_slack_exactly_where_the_tension_would_be_negative(by_tension):
    """Tendon 1 carries no tension in the reference: commanded a little less than its reading it
    goes slack (tension exactly 0, the shape unchanged), a little more and it pulls."""
    robot, load, sol = by_tension
    d = np.asarray(sol.displacements)
    driven = (0, 1, 2, 4, 5)
    eps = 1e-5  # m
    results = []
    for delta in (-eps, eps):
        command = d[list(driven)] + np.array([0.0, delta, 0.0, 0.0, 0.0])
        results.append(tdct.solve(robot, tdct.Actuation(np.zeros(6), displacements=command, driven=driven), load, gravity=G))
    slack, taut = results
    assert list(np.asarray(slack.slack)) == [False, True, False, False, False, False]
    assert float(slack.tensions[1]) == 0.0
    assert rel(slack.tensions, TWO_TENSIONS) < 1e-9 and rel(slack.position, sol.position) < 1e-9
    assert not np.any(taut.slack) and float(taut.tensions[1]) > 0.0
