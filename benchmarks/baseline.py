"""The numpy/scipy baseline: the paper's approach, checked against tdct_jax and timed beside it.

What a user would otherwise write, ported the way the paper's MATLAB code works: the same model as
tdct_jax's defaults (transition "balanced", tendon_model "exact"; see docs/model.md and
tdct_jax/segments.py) with the right-hand side a Python function on numpy arrays, a Python loop of
classical RK4 steps per segment (R re-orthonormalised after each step, as in tdct_jax), shooting
on the six base unknowns N(0), M(0) with scipy.optimize.fsolve (MINPACK hybrd, forward-difference
Jacobian) from the straight-rod guess, and the compliance by central differences of the tip
position over the three tip-force components (step 1e-4 N, six more fsolves started from the
converged base wrench). Only the section properties (stiffness diagonals, linear densities, tendon
offsets) are taken from tdct_jax.Robot.paper(), converted to numpy floats once.

For each configuration it solves with both, raises unless the tips agree to 1e-6 relative (same
discretisation, same steps), and reports median wall-clock times of the baseline solve and FD
compliance against the warm tdct_jax solve and exact (autodiff) compliance, measured side by side
in the same run, with their ratios and fsolve's function evaluations.

Run: PYTHONPATH=. python benchmarks/baseline.py [--quick] [--out PATH]
Writes benchmarks/results/baseline.json (--quick: baseline_quick.json; two configurations,
the default steps only, fewer repeats, about a minute). For steady numbers pin to one core: taskset -c 0.
"""

from __future__ import annotations

import argparse
import copy
import time
from pathlib import Path

import jax
import numpy as np
from _common import paper_section, timings, write_result
from scipy.optimize import fsolve

import tdct_jax as tdct

STEPS = tdct.SolverOptions().steps

PAPER_SECONDS = 0.82
"""The paper's reported time per solve (MATLAB)."""
AGREEMENT = 1e-6
"""Largest allowed |tip_np - tip_jax| / |tip_jax|."""
FD_STEP = 1e-4
"""Finite-difference step on the tip force [N] (the paper's method)."""
GRAVITY = np.array([0.0, -9.81, 0.0])
NEWTON_STEPS = 3
E3 = np.array([0.0, 0.0, 1.0])
I3, I6 = np.eye(3), np.eye(6)

# name: (tensions [N], insertion [m], tip force [N], tip moment [N m])
CONFIGS = {
    "6 N, 80 mm, 20 g": ((6.0, 0, 0, 0), 0.080, (0.0, -0.02 * 9.81, 0.0), (0.0, 0.0, 0.0)),
    "3D: (6,0,3,2) N, 70 mm, F, M": ((6.0, 0, 3.0, 2.0), 0.070, (0.1, -0.2, 0.05), (1e-3, 0.0, 2e-3)),
    "10 N, no tube": ((10.0, 0, 0, 0), 0.0, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)),
    "2 N, tube to tip (160 mm)": ((2.0, 0, 0, 0), 0.160, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)),
}
QUICK_CONFIGS = ("6 N, 80 mm, 20 g", "3D: (6,0,3,2) N, 70 mm, F, M")


def hat(x):
    return np.array([[0.0, -x[2], x[1]], [x[2], 0.0, -x[0]], [-x[1], x[0], 0.0]])


def cross(a, b):
    """a x b over the last axis (np.cross costs ~20 us on these tiny arrays)."""
    a, b = np.broadcast_arrays(a, b)
    return np.stack(
        [
            a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1],
            a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
            a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0],
        ],
        -1,
    )


class Section:
    """One segment's section in numpy: K_se, K_bt diagonals, linear density, tendons."""

    def __init__(self, robot: tdct.Robot, tensions, backbone: bool):
        p = paper_section(robot)
        E, G, A, I_x, I_y = p["E"], p["G"], p["A"], p["I_x"], p["I_y"]
        extra = p["EI_tube"] if backbone else 0.0  # the tube's E I in bending (eq. 30)
        self.K_se = np.array([G * A, G * A, E * A])
        self.K_bt = np.array([E * I_x + extra, E * I_y + extra, G * (I_x + I_y)])
        self.rho = p["rho"] * A + (p["rho_tube"] if backbone else 0.0)
        self.tau = np.asarray(tensions, dtype=float)
        self.r = p["r"]
        self.rh = np.array([hat(r) for r in self.r])
        self.backbone = backbone
        self.m_straight = self.tau @ np.cross(self.r, E3)  # tendon moment of the straight rod


def strains(sec: Section, R, N, M):
    """(v, u) from the total force and moment: 3 Newton steps on the constitutive relations."""
    bf, bm = R.T @ N, R.T @ M
    v = E3 + (bf - sec.tau.sum() * E3) / sec.K_se
    if sec.backbone:
        v = v * E3
    u = (bm - sec.m_straight) / sec.K_bt
    for _ in range(NEWTON_STEPS):
        pb = cross(u, sec.r) + v
        norm = np.sqrt(np.sum(pb**2, axis=1))
        t = pb / norm[:, None]
        F = np.concatenate([sec.K_se * (v - E3) + sec.tau @ t - bf, sec.K_bt * u + sec.tau @ cross(sec.r, t) - bm])
        P = (sec.tau / norm)[:, None, None] * (I3 - t[:, :, None] * t[:, None, :])
        PW = P @ sec.rh
        J = np.empty((6, 6))  # the symmetric stiffness of eq. 1
        J[:3, :3], J[:3, 3:] = np.diag(sec.K_se) + P.sum(0), -PW.sum(0)
        J[3:, :3], J[3:, 3:] = (sec.rh @ P).sum(0), np.diag(sec.K_bt) - (sec.rh @ PW).sum(0)
        if sec.backbone:  # no shear: v_x = v_y = 0 stay
            J[:2], F[:2] = I6[:2], 0.0
        w = np.concatenate([v, u]) - np.linalg.solve(J, F)
        v, u = w[:3], w[3:]
    return v, u


def rhs(sec: Section, y):
    """d/ds of y = (p, R row-major, N, M), 18 numbers."""
    R, N, M = y[3:12].reshape(3, 3), y[12:15], y[15:18]
    v, u = strains(sec, R, N, M)
    dp = R @ v
    return np.concatenate([dp, (R @ hat(u)).ravel(), -sec.rho * GRAVITY, -cross(dp, N)])


def rk4(sec: Section, y, s0, s1, steps):
    """Classical RK4 in ``steps`` equal steps, R projected toward SO(3) after each."""
    if s1 == s0:
        return y
    h = (s1 - s0) / steps
    for _ in range(steps):
        k1 = rhs(sec, y)
        k2 = rhs(sec, y + h / 2 * k1)
        k3 = rhs(sec, y + h / 2 * k2)
        k4 = rhs(sec, y + h * k3)
        y = y + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        R = y[3:12].reshape(3, 3)
        y[3:12] = (R @ (1.5 * I3 - 0.5 * R.T @ R)).ravel()
    return y


class Problem:
    """One configuration: sections, loads, and the residual scale F_c (as tdct_jax's _scale)."""

    def __init__(self, robot: tdct.Robot, tensions, insertion, force, moment):
        self.L, self.d = float(robot.length), float(insertion)
        self.back, self.sil = Section(robot, tensions, True), Section(robot, tensions, False)
        self.force, self.moment = np.asarray(force, dtype=float), np.asarray(moment, dtype=float)
        self.rho_tube = paper_section(robot)["rho_tube"]
        self.F_c = self._typical_force()

    def _typical_force(self):
        weight = np.linalg.norm(GRAVITY) * (self.sil.rho * self.L + self.rho_tube * self.d)
        F_c = self.sil.tau.sum() + np.linalg.norm(self.force) + np.linalg.norm(self.moment) / self.L + weight
        return max(F_c, 1e-3)

    def with_force(self, force) -> Problem:
        """The same configuration under another tip force."""
        other = copy.copy(self)
        other.force = np.asarray(force, dtype=float)
        other.F_c = other._typical_force()
        return other

    def scale(self, wrench):
        return np.concatenate([wrench[:3] / self.F_c, wrench[3:] / (self.F_c * self.L)])

    def unscale(self, x):
        return np.concatenate([x[:3] * self.F_c, x[3:] * self.F_c * self.L])

    def straight_guess(self):
        """Base wrench of the straight rod: exact in force, first-order in moment."""
        L, d, rho1 = self.L, self.d, self.sil.rho
        N0 = self.force + GRAVITY * (rho1 * L + self.rho_tube * d)
        M0 = self.moment + np.cross(L * E3, self.force) + np.cross(E3, GRAVITY) * (rho1 * L**2 + self.rho_tube * d**2) / 2
        return np.concatenate([N0, M0])

    def shoot(self, x, steps):
        """State at s = L from scaled base unknowns x (balanced transition: the state is continuous)."""
        y = np.concatenate([np.zeros(3), I3.ravel(), self.unscale(x)])
        y = rk4(self.back, y, 0.0, self.d, steps)
        return rk4(self.sil, y, self.d, self.L, steps)

    def residual(self, x, steps):
        y = self.shoot(x, steps)
        return np.concatenate([(y[12:15] - self.force) / self.F_c, (y[15:18] - self.moment) / (self.F_c * self.L)])

    def solve(self, steps, wrench0=None):
        """fsolve on the base wrench; returns (tip position, base wrench, nfev).

        fsolve's forward-difference step is sqrt(eps) |z_j|, which breaks down for unknowns that
        vanish by symmetry but come out of a solve as 1e-35 (the warm starts of compliance_fd):
        it solves for z = x + 1, so each step is about 1.5e-8 of the O(1) scaled unknowns x.
        """
        x0 = self.scale(self.straight_guess() if wrench0 is None else wrench0)
        z, info, ier, msg = fsolve(lambda z: self.residual(z - 1, steps), x0 + 1, xtol=1e-12, full_output=True)
        res = np.abs(info["fvec"]).max()
        if ier != 1 and res > 1e-10:  # ier 4/5 (no more progress) at round-off is a root all the same
            raise RuntimeError(f"fsolve did not converge (scaled residual {res:.1e}): {msg}")
        x = z - 1
        return self.shoot(x, steps)[:3], self.unscale(x), int(info["nfev"])


def compliance_fd(problem: Problem, steps, wrench, h=FD_STEP):
    """3x3 compliance d p(L) / d F_e [m/N] by central differences, each solve warm-started at ``wrench``."""
    CM = np.zeros((3, 3))
    for k in range(3):
        dF = h * I3[k]
        tip_p = problem.with_force(problem.force + dF).solve(steps, wrench)[0]
        tip_m = problem.with_force(problem.force - dF).solve(steps, wrench)[0]
        CM[:, k] = (tip_p - tip_m) / (2 * h)
    return CM


def _timed(f, repeats):
    """f's first result and the median wall-clock seconds of ``repeats`` calls (the first included)."""
    t = time.perf_counter()
    result = f()
    times = [time.perf_counter() - t]
    for _ in range(repeats - 1):
        t = time.perf_counter()
        f()
        times.append(time.perf_counter() - t)
    return result, float(np.median(times))


def compare(robot: tdct.Robot, name: str, steps: int, reps: dict) -> dict:
    """Solves one configuration with both, checks the agreement, times solve and compliance side by side."""
    tensions, insertion, force, moment = CONFIGS[name]
    act, load = tdct.Actuation(tensions, insertion), tdct.Loads(tip_force=force, tip_moment=moment)
    problem = Problem(robot, tensions, insertion, force, moment)

    (tip_np, wrench, nfev), np_solve_s = _timed(lambda: problem.solve(steps), reps["np_solve"])
    solver = tdct.SolverOptions(steps=steps)
    sol = tdct.solve(robot, act, load, solver=solver)
    tip_jax = np.asarray(sol.tip_position)
    tip_diff = float(np.linalg.norm(tip_np - tip_jax) / np.linalg.norm(tip_jax))
    if not tip_diff <= AGREEMENT:
        raise AssertionError(
            f"{name}, steps {steps}: baseline and tdct_jax tips differ by {tip_diff:.2e} relative > {AGREEMENT:g}: "
            f"numpy {tip_np}, tdct_jax {tip_jax} [m]"
        )
    jax_solve_s = float(np.median(timings(lambda: tdct.solve(robot, act, load, solver=solver).position, reps["jax_solve"])))

    CM_fd, np_cm_s = _timed(lambda: compliance_fd(problem, steps, wrench), reps["np_fd"])
    CM = np.asarray(tdct.compliance(robot, act, load, solver=solver))
    jax_cm_s = float(np.median(timings(lambda: tdct.compliance(robot, act, load, solver=solver), reps["jax_cm"])))
    return dict(
        config=name,
        steps=steps,
        tip_relative_difference=tip_diff,
        tip_position_mm=(tip_jax * 1e3).round(4).tolist(),
        baseline_solve_ms=np_solve_s * 1e3,
        tdct_jax_solve_ms=jax_solve_s * 1e3,
        solve_ratio=np_solve_s / jax_solve_s,
        baseline_fd_compliance_ms=np_cm_s * 1e3,
        tdct_jax_compliance_ms=jax_cm_s * 1e3,
        compliance_ratio=np_cm_s / jax_cm_s,
        compliance_fd_vs_exact=float(np.abs(CM_fd - CM).max() / np.abs(CM).max()),
        fsolve_nfev=nfev,
        tdct_jax_newton_iterations=int(sol.iterations),
    )


def _format(row: dict) -> str:
    return (
        f"{row['config']:30s} {row['steps']:5d}  {row['tip_relative_difference']:8.1e}  {row['baseline_solve_ms']:8.0f} "
        f"{row['tdct_jax_solve_ms']:7.1f} {row['solve_ratio']:6.0f}x  {row['baseline_fd_compliance_ms']:8.0f} "
        f"{row['tdct_jax_compliance_ms']:7.1f} {row['compliance_ratio']:6.0f}x  {row['fsolve_nfev']:5d}  {row['compliance_fd_vs_exact']:8.1e}"
    )


HEADER = (
    f"{'configuration':30s} {'steps':>5s}  {'tip diff':>8s}  {'np solve':>8s} {'jax':>7s} {'ratio':>7s}  "
    f"{'np FD CM':>8s} {'jax CM':>7s} {'ratio':>7s}  {'nfev':>5s}  {'FD-exact':>8s}   (times in ms)"
)


def main(quick: bool, out: str | None = None) -> None:
    steps_list = (STEPS,) if quick else (STEPS, 50)
    names = QUICK_CONFIGS if quick else tuple(CONFIGS)
    reps = dict(np_solve=1 if quick else 5, np_fd=1 if quick else 3, jax_solve=5 if quick else 30, jax_cm=3 if quick else 20)
    out = Path(out or Path(__file__).parent / "results" / ("baseline_quick.json" if quick else "baseline.json"))
    robot = tdct.Robot.paper()
    t_start = time.perf_counter()

    compile_s, rows = {}, []
    for steps in steps_list:
        t = time.perf_counter()
        jax.block_until_ready(tdct.solve(robot, tdct.Actuation(), solver=tdct.SolverOptions(steps=steps)).position)
        t1 = time.perf_counter()
        jax.block_until_ready(tdct.compliance(robot, tdct.Actuation(), solver=tdct.SolverOptions(steps=steps)))
        compile_s[steps] = dict(solve=t1 - t, compliance=time.perf_counter() - t1)
        print(f"steps {steps}: compile + first tdct_jax solve {t1 - t:.1f} s, compliance {compile_s[steps]['compliance']:.1f} s")
        print(HEADER)

        for name in names:
            rows.append(compare(robot, name, steps, reps))
            print(_format(rows[-1]))

    write_result(
        out,
        quick=quick,
        paper_seconds_per_solve=PAPER_SECONDS,
        agreement_tolerance=AGREEMENT,
        fd_step_N=FD_STEP,
        repeats=reps,
        compile_and_first_call_s=compile_s,
        total_s=time.perf_counter() - t_start,
        configs=rows,
    )
    print(f"total {time.perf_counter() - t_start:.0f} s; wrote {out}")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="two configurations, 50 steps, fewer repeats")
    parser.add_argument("--out", default=None, help="results JSON (default benchmarks/results/baseline[_quick].json)")
    args = parser.parse_args()
    main(args.quick, args.out)
