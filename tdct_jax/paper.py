"""The paper's simulation studies (Secs. III.B, IV and V.A) as functions that return data.

Each function computes; ``plotting`` draws; ``reproduce`` runs them all and writes the summary.
Grids default to the paper's; the constants below hold the numbers the paper reports.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from tqdm import tqdm

from . import fields
from .description import Robot
from .ik import Bounds, LeastTension, Stiffness, Target, inverse_kinematics
from .inputs import Actuation, Loads
from .lm import levenberg_marquardt
from .manipulation import capacity, optimal_insertion
from .mechanics import compliance, compliance_ellipsoid
from .options import DEFAULT_SOLVER
from .scene import Capsule, Plane, Scene
from .solve import solve
from .sweep import sweep

MM = 1e-3
G = 1e-3

FIG8A_TENSION = 10.0
"""Fig. 8A: tension on tendon 1 [N] while the tube goes in (no tip load)."""
FIG8A_INSERTIONS = tuple(MM * d for d in (0, 30, 60, 90, 120, 150))
FIG9_TENSIONS = tuple(float(t) for t in range(11))
"""Figs. 8B and 9: tendon-1 tensions [N], 0 to 10 N in 1 N steps."""
FIG9_INSERTIONS = tuple(MM * d for d in range(0, 151, 10))
"""Figs. 8B, 9 and 11: insertion depths [m], 0 to 150 mm in 10 mm steps."""
FIG10_TENSION = 6.0
"""Fig. 10: tension on tendon 1 [N] (the paper says only "constant"; 6 N is ours)."""
FIG11_TENSIONS = (0.0, 2.0, 4.0, 6.0, 8.0)
FIG11_INSERTIONS = FIG9_INSERTIONS
PAPER_LAMBDA2_MM_PER_N = (203.5, 86.1)
"""The paper's lambda_2 at insertion 0 and 150 mm (Fig. 11): a 57.7% reduction."""
FIG13_TENSIONS = (10.0, 5.0)
"""Fig. 13A and B: tendon-1 tension [N]."""
FIG13_MASSES = tuple(G * m for m in (0, 10, 20, 30, 40, 50))
"""Fig. 13: tip masses [kg] (the paper does not list its curves' masses; 50 g is the one it quotes)."""
PAPER_OPTIMUM = dict(tension_N=10.0, mass_g=50.0, insertion_mm=70.0)
"""Sec. V.A: 50 g at 10 N is lifted highest with about 70 mm of tube (Fig. 13A, 10 mm grid)."""
CAPACITY_TENSIONS = (6.0, 7.0, 8.0, 9.0, 10.0)
CAPACITY_INSERTIONS = (0.0, 0.07)
PAPER_CAPACITIES_G = ((7.20, 13.74, 20.35, 27.04, 33.82), (18.44, 26.15, 33.97, 41.91, 49.98))
"""Sec. V.A: load capacities [g] at 6..10 N, without the tube (first row) and with 70 mm of it."""
TABLE3_TENSIONS = (0.0, 3.0, 6.0, 8.0, 10.0)
TABLE3_INSERTIONS = tuple(MM * d for d in (0, 40, 80, 120))
TABLE3_MASSES = tuple(G * m for m in (0, 20, 50))
PAPER_BENDING_RANGE_DEG = (-57.1, 61.4)
"""Sec. III.B: tip bending angles over the Table III conditions."""
CALIBRATION_TENSIONS = (2.0, 4.0, 6.0, 8.0, 10.0)
"""Sec. III.B calibrates on "five distinct tendon forces" on one tendon without listing them: ours."""
CONTACT_TENSION = 6.0
"""Beyond the paper (issue 26): the tension [N] on tendon 3 (body -y) that presses the tip on a table."""
TABLE_HEIGHT = -0.04
"""The table's surface [m]: the plane y = TABLE_HEIGHT, solid below."""
CONTACT_INSERTIONS = tuple(MM * d for d in range(0, 161, 10))
CYLINDER = dict(a=(-0.05, -0.03, 0.04), b=(0.05, -0.03, 0.04), radius=0.01)
"""A horizontal cylinder [m] under the body near its base, across the bending plane: tendon 3 bends
the body down over it."""
CYLINDER_TENSION = 10.0
"""The tension [N] on tendon 3 that bends the body over ``CYLINDER``."""


def tendon1(robot: Robot, tensions) -> np.ndarray:
    """Tension vectors [N] that pull tendon 1 only, one row per tension."""
    t = np.zeros((len(tensions), robot.n_tendons))
    t[:, 0] = tensions
    return t


def fig8a_shapes(robot: Robot, tension=FIG8A_TENSION, insertions=FIG8A_INSERTIONS, **options):
    """Fig. 8A: full shapes as the tube goes in, at one tendon-1 tension (SweepResult with shapes)."""
    return sweep(robot, grid={"insertion": np.asarray(insertions), "tensions": tendon1(robot, [tension])}, shapes=True, **options)


def tip_pose_grid(robot: Robot, tensions=FIG9_TENSIONS, insertions=FIG9_INSERTIONS, **options):
    """Figs. 8B and 9: tip poses on a tendon-1 tension x insertion grid, no tip load (SweepResult)."""
    return sweep(robot, grid={"tensions": tendon1(robot, tensions), "insertion": np.asarray(insertions)}, **options)


def fig10_compliances(robot: Robot, tension: float = FIG10_TENSION, insertions=(0.0, 0.05, 0.10, 0.15), **solve_options) -> dict:
    """Fig. 10: CM [m/N] for several insertion depths [m] at one tension on tendon 1, no tip load."""
    (tau,) = tendon1(robot, [tension])
    return {f"insertion {1e3 * d:.0f} mm": compliance(robot, Actuation(tau, d), Loads(), **solve_options) for d in insertions}


def fig11_eigenvalues(robot: Robot, tensions=FIG11_TENSIONS, insertions=FIG11_INSERTIONS, **options):
    """Fig. 11: eigenvalues lambda_1..3 [m/N] of CM on a tendon-1 tension x insertion grid.

    Returns:
        Array (len(tensions), len(insertions), 3), ascending; NaN where a solve did not converge.
    """
    res = sweep(
        robot, grid={"tensions": tendon1(robot, tensions), "insertion": np.asarray(insertions)}, compliance=True, **options
    )
    return np.asarray(compliance_ellipsoid(res.compliance).eigenvalues)


def compliance_headline(tensions, insertions, lam) -> list[dict]:
    """lambda_2 at the smallest and largest insertion for each tension, beside the paper's values."""
    paper0, paper1 = PAPER_LAMBDA2_MM_PER_N
    rows = []
    for i, tau in enumerate(tensions):
        first, last = 1e3 * lam[i, 0, 1], 1e3 * lam[i, -1, 1]
        rows.append(
            dict(
                tension_N=float(tau),
                insertion_mm=(1e3 * float(insertions[0]), 1e3 * float(insertions[-1])),
                lambda2_mm_per_N=(float(first), float(last)),
                reduction_percent=float(100 * (1 - last / first)),
                paper_lambda2_mm_per_N=(paper0, paper1),
                paper_reduction_percent=100 * (1 - paper1 / paper0),
            )
        )
    return rows


def fig13_optima(robot: Robot, tension: float, masses=FIG13_MASSES, n_curve: int = 33, **options):
    """Fig. 13: y_tip vs insertion for several tip masses at one tendon-1 tension, optimum of each."""
    (tau,) = tendon1(robot, [tension])
    return optimal_insertion(robot, Actuation(tau), grid={"tip_mass": np.asarray(masses)}, n_curve=n_curve, **options)


def fig14_capacities(robot: Robot, tensions=CAPACITY_TENSIONS, insertions=FIG9_INSERTIONS, **options):
    """Fig. 14: load capacity [kg] (tip brought to y = 0) on a tendon-1 tension x insertion grid."""
    return capacity(robot, grid={"tensions": tendon1(robot, tensions), "insertion": np.asarray(insertions)}, **options)


def ten_capacities(robot: Robot, **options):
    """The ten load capacities the paper reports (Sec. V.A): insertion (0, 70 mm) x tendon 1 at 6..10 N."""
    grid = {"insertion": np.asarray(CAPACITY_INSERTIONS), "tensions": tendon1(robot, CAPACITY_TENSIONS)}
    return capacity(robot, grid=grid, **options)


def bending_range(robot: Robot, tensions=TABLE3_TENSIONS, insertions=TABLE3_INSERTIONS, masses=TABLE3_MASSES, **options):
    """Tip angles [rad] over the Table III conditions (tendon 1 x insertion x tip mass), SweepResult."""
    grid = {"tensions": tendon1(robot, tensions), "insertion": np.asarray(insertions), "tip_mass": np.asarray(masses)}
    return sweep(robot, grid=grid, **options)


class Fit(NamedTuple):
    """Least-squares fit of robot fields to the paper's ten load capacities.

    values: fitted fields by name (SI). capacities_g, paper_g: model and paper, (2, 5): rows
    without tube and with 70 mm, columns 6..10 N. residual_percent: relative misfit [%].
    """

    values: dict
    capacities_g: np.ndarray
    paper_g: np.ndarray
    residual_percent: np.ndarray
    iterations: int
    converged: bool


def fit_load_capacities(
    robot: Robot, params=("tendons[*].offset",), *, max_steps: int = 12, xtol: float = 1e-8, progress=print, solver=DEFAULT_SOLVER
) -> Fit:
    """Fits robot fields (fields.py names: "tendons[*].offset", "sections[*].density", ...) to the
    ten load capacities of Sec. V.A by Levenberg-Marquardt in log space.

    Residuals are relative misfits (model - paper) / paper; the Jacobian is exact (jacfwd through
    the implicitly differentiated capacity root, vmapped over the ten conditions). ``max_steps``
    and ``xtol`` are the fit's own limit and tolerance; ``solver`` goes to every solve.
    """
    tensions = jnp.asarray(np.tile(tendon1(robot, CAPACITY_TENSIONS), (2, 1)))
    depths = jnp.repeat(jnp.asarray(CAPACITY_INSERTIONS), len(CAPACITY_TENSIONS))
    target = G * np.asarray(PAPER_CAPACITIES_G).ravel()

    def residual(log_values):
        r = robot.replace({p: jnp.exp(log_values[i]) for i, p in enumerate(params)})
        c = jax.vmap(lambda t, d: capacity(r, Actuation(t, d), solver=solver, throw=False))(tensions, depths)
        misfit = (c.mass - target) / target
        return misfit, (misfit, c.result)

    jac_and_res = jax.jit(jax.jacfwd(residual, has_aux=True))

    def evaluate(x):
        J, (r, codes) = jac_and_res(x)
        return np.asarray(r), np.asarray(J), int(np.max(np.asarray(codes))), None

    def report(it, r, step):
        progress(f"  fit iteration {it}: rms misfit {100 * np.sqrt(np.mean(np.square(r))):.3f}%, step {np.abs(step).max():.2e}")

    x0 = np.log([fields.value(robot, p) for p in params])
    fit = levenberg_marquardt(evaluate, x0, max_steps=max_steps, xtol=xtol, callback=report if progress else None)
    mass = fit.residual * target + target
    return Fit(
        values={p: float(np.exp(fit.x[i])) for i, p in enumerate(params)},
        capacities_g=(mass / G).reshape(2, -1),
        paper_g=np.asarray(PAPER_CAPACITIES_G),
        residual_percent=100 * fit.residual.reshape(2, -1),
        iterations=fit.iterations,
        converged=fit.converged,
    )


def calibration_conditions(robot: Robot, tensions=CALIBRATION_TENSIONS) -> list[Actuation]:
    """Sec. III.B's calibration protocol: tendon 1 alone at five tensions, no tube, no tip load."""
    return [Actuation(t, (0.0,) * robot.n_tubes) for t in tendon1(robot, tensions)]


# ----------------------------------------------------------------------------- Secs. V.A and V.B as inverse kinematics

VB_HEIGHTS = tuple(MM * y for y in (0, 20, 40, 60))
"""Sec. V.B study: fixed tip heights y [m] in the z-y plane."""
VB_INSERTIONS = tuple(MM * d for d in range(0, 161, 10))
"""Sec. V.B study: the tube depths [m] at which tendon 1 is re-solved to hold each height."""
VA_HEIGHTS = tuple(MM * y for y in (-60, -40, -20, -10, -5, -2, -1))
"""Sec. V.A as IK: tip heights [m] to reach with 50 g at the tip, the stiffest way; all below the
highest reach (-0.5 mm with tendon 1 up to 10 N), where only one actuation is left."""
VA_MASS = 50 * G
MAP_TENSIONS = tuple(float(t) for t in np.linspace(2.0, 10.0, 9))
MAP_INSERTIONS = tuple(MM * d for d in range(0, 161, 20))
MAP_COUNTER = 1.0
"""Stiffness map: its in-plane tip targets are the tips of tendon 1 at MAP_TENSIONS [N] with
MAP_COUNTER [N] on tendon 3, at MAP_INSERTIONS [m]: reachable by construction, with every input
inside its bounds, so that one input is to spare (the reachable set is a band a few millimetres
wide, which a grid of targets in z and y would mostly miss)."""
MAP_CHUNK = 16
"""Stiffness map: most targets per inverse-kinematics call (the progress bar moves once per call)."""


def _bar(total: int, desc: str, unit: str, progress: bool):
    """A progress bar on stderr, like the batch engine's (none without ``progress``)."""
    return tqdm(total=total, desc=desc, unit=unit, disable=not progress, dynamic_ncols=True)


def _reach(robot: Robot, positions, axes: str, chunk: int, bar=None, label: str = "", **options) -> dict:
    """``inverse_kinematics`` over target positions (k, 3) [m] in calls of at most ``chunk`` targets,
    all of one size (the last padded by repeating its final target: one compiled program serves them),
    ticking ``bar`` per target with ``label`` beside it. Returns numpy tensions, insertion,
    tip_angle and result, (k, ...)."""
    positions = np.asarray(positions)
    chunk = -(-len(positions) // -(-len(positions) // chunk))  # calls of equal size, at most chunk
    parts = []
    for start in range(0, len(positions), chunk):
        if bar is not None:
            bar.set_postfix_str(label + (": compiling" if start == 0 else ""))
        rows = np.arange(start, min(start + chunk, len(positions)))
        index = np.concatenate([rows, np.full(chunk - len(rows), rows[-1])])
        r = inverse_kinematics(robot, Target(positions[index], axes=axes), throw=False, **options)
        out = dict(tensions=r.actuation.tensions, insertion=r.actuation.insertion, tip_angle=r.tip_angle, result=r.result)
        parts.append({k: np.asarray(v)[: len(rows)] for k, v in out.items()})
        if bar is not None:
            bar.update(len(rows))
    return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}


def _compliance_along(robot: Robot, reached: dict, direction, load: Loads, bar=None) -> np.ndarray:
    """direction^T CM direction [m/N] at each actuation ``_reach`` found, NaN where it did not reach."""
    out = []
    for t, d, code in zip(reached["tensions"], reached["insertion"], reached["result"], strict=True):
        c = np.asarray(compliance(robot, Actuation(t, d), load, throw=False)) if code == 0 else np.full((3, 3), np.nan)
        out.append(direction @ c @ direction)
        if bar is not None:
            bar.update()
    return np.asarray(out)


class AngleFamily(NamedTuple):
    """Sec. V.B: at each fixed tip height (rows), the tip angle [rad], tendon-1 tension [N] and
    whether the height was reached, as the tube goes in (columns: ``insertions`` [m]).
    Insertion 0 is the tendon-only robot: one angle per height; the tube makes it a range."""

    heights: np.ndarray
    insertions: np.ndarray
    tip_angle: np.ndarray
    tension: np.ndarray
    reached: np.ndarray


def tip_angle_family(
    robot: Robot, heights=VB_HEIGHTS, insertions=VB_INSERTIONS, tension: float = FIG8A_TENSION, *, progress=True, **options
) -> AngleFamily:
    """Sec. V.B: how far the tube lets the tip angle vary while the tip holds a height (tendon 1
    re-solved by inverse kinematics at every depth, up to ``tension`` [N]). ``progress``: a bar
    over the depths on stderr; ``options`` go to ``inverse_kinematics``."""
    positions = np.column_stack([np.zeros(len(heights)), heights, np.zeros(len(heights))])
    common = dict(tendons=(1,), bounds=Bounds(tension=(0.0, tension)), **options)
    rows = []
    with _bar(len(insertions), "Sec. V.B inverse kinematics", "depth", progress) as bar:
        for k, d in enumerate(insertions):
            bar.set_postfix_str("" if k else "compiling")
            r = _reach(robot, positions, "y", len(heights), insertion=d, **common)
            rows.append((r["tip_angle"], r["tensions"][:, 0], r["result"] == 0))
            bar.update()
        bar.set_postfix_str("")
    angle, tau, ok = (np.stack(x, axis=1) for x in zip(*rows, strict=True))
    return AngleFamily(np.asarray(heights), np.asarray(insertions), angle, tau, ok)


class HighestReach(NamedTuple):
    """Sec. V.A: the highest tip height [m] with ``mass`` [kg] at the tip over tendon 1 in
    [0, ``tension_bound``] [N] and the insertion in [0, L], the actuation that reaches it (tension
    [N], insertion [m]) and its compliance along -y [m/N]; the first-order conditions there:
    ``slope_insertion`` = dy/dd (0 at an interior maximum) and ``slope_tension`` = dy/dtau [m/N]
    (> 0: the bound holds the tension), exact; ``on_bound``: the coarse grid's highest point has
    the largest tension. ``grid_*``: that grid (heights [m], NaN where a solve failed)."""

    height: float
    tension: float
    insertion: float
    compliance: float
    slope_insertion: float
    slope_tension: float
    on_bound: bool
    converged: bool
    mass: float
    tension_bound: float
    grid_tensions: np.ndarray
    grid_insertions: np.ndarray
    grid_height: np.ndarray


@jax.jit
def _refine(robot: Robot, load: Loads, tension, lo, hi, solver):
    """The insertion in [lo, hi] [m] that maximises y_tip with ``tension`` [N] on tendon 1
    (``optimal_insertion`` in a bracket), and there: y_tip [m], its exact gradient (d/dtau [m/N], d/dd), the
    compliance along -y [m/N], and whether every step converged. One compiled program."""
    tau = jnp.zeros(robot.n_tendons).at[0].set(tension)
    opt = optimal_insertion(robot, Actuation(tau), load, bracket=(lo, hi), solver=solver, throw=False)

    def height(x):
        act = Actuation(jnp.zeros(robot.n_tendons).at[0].set(x[0]), x[1])
        return solve(robot, act, load, solver=solver, throw=False).tip_position[1]

    x = jnp.stack([jnp.asarray(tension, float), opt.insertion])
    down = jnp.array([0.0, -1.0, 0.0])
    CM = compliance(robot, Actuation(tau, opt.insertion), load, solver=solver, throw=False)
    ok = opt.converged & jnp.all(jnp.isfinite(CM))
    return opt.insertion, height(x), jax.jacfwd(height)(x), down @ CM @ down, ok


def highest_reach(
    robot: Robot,
    mass: float = VA_MASS,
    tension: float = FIG8A_TENSION,
    *,
    n_tensions: int = 11,
    n_insertions: int = 33,
    solver=DEFAULT_SOLVER,
    **options,
) -> HighestReach:
    """Sec. V.A as an optimisation: the highest tip height with ``mass`` [kg] at the tip, over the
    tension on tendon 1 in [0, ``tension``] [N] and the insertion in [0, L].

    A grid of n_tensions x n_insertions forward solves locates the maximum. Where it lies on the
    tension bound (it does for the paper's 50 g at 10 N: pulling harder lifts higher), the problem
    is one-dimensional in the insertion: ``optimal_insertion`` refines it, between the grid's
    neighbours of the highest point, to a zero of the exact slope dy/dd (as ``optimal_insertion``
    does for Fig. 13). The exact gradient there (``jax.jacfwd`` through the implicitly
    differentiated solve) checks the first-order conditions: dy/dd = 0, dy/dtau > 0. No offset or
    target height enters the answer.

    Args:
        robot: the robot.
        mass: tip mass [kg].
        tension: the largest tension on tendon 1 [N].
        n_tensions, n_insertions: the locating grid: tensions 0 to ``tension``, depths 0 to L.
        solver: SolverOptions for every solve.
        **options: ``tdct.sweep``'s batching options (progress, chunk_size, devices) and throw.

    Returns:
        HighestReach.
    """
    load = Loads.from_mass(mass)
    taus = np.linspace(0.0, tension, n_tensions)
    depths = np.linspace(0.0, float(robot.length), n_insertions)
    grid = sweep(robot, None, load, grid={"tensions": tendon1(robot, taus), "insertion": depths}, solver=solver, **options)
    heights = np.where(grid.converged, grid.tip_position[..., 1], np.nan)
    i, k = np.unravel_index(np.nanargmax(heights), heights.shape)
    lo, hi = depths[max(k - 1, 0)], depths[min(k + 1, n_insertions - 1)]
    if k in (0, n_insertions - 1):  # an optimum at d = 0 or L: that end
        lo = hi = depths[k]
    with _bar(1, "highest reach: insertion refined", "optimum", options.get("progress", True)) as bar:
        bar.set_postfix_str("compiling")
        d, y, slopes, c, ok = jax.block_until_ready(_refine(robot, load, float(tension), lo, hi, solver))
        bar.set_postfix_str("")
        bar.update()
    return HighestReach(
        height=float(y),
        tension=float(tension),
        insertion=float(d),
        compliance=float(c),
        slope_insertion=float(slopes[1]),
        slope_tension=float(slopes[0]),
        on_bound=bool(i == n_tensions - 1),
        converged=bool(ok) and bool(grid.converged[-1].all()),
        mass=float(mass),
        tension_bound=float(tension),
        grid_tensions=taus,
        grid_insertions=depths,
        grid_height=heights,
    )


class StiffestReach(NamedTuple):
    """Sec. V.A as IK: for each target tip height (with ``mass`` [kg] at the tip), the stiffest
    actuation (tendon 1 [N], insertion [m]) and its compliance along -y [m/N], beside the
    tendon-only actuation reaching the same height (insertion 0) and its compliance."""

    heights: np.ndarray
    mass: float
    tension: np.ndarray
    insertion: np.ndarray
    compliance: np.ndarray
    reached: np.ndarray
    tendon_only_tension: np.ndarray
    tendon_only_compliance: np.ndarray


def stiffest_reach(
    robot: Robot, heights=VA_HEIGHTS, mass: float = VA_MASS, tension: float = FIG8A_TENSION, *, progress=True, **options
) -> StiffestReach:
    """Sec. V.A done as inverse kinematics: reach each tip height holding ``mass`` with tendon 1
    (at most ``tension`` [N]) and the tube, the stiffest way along -y, and with tendon 1 alone.
    ``progress``: a bar over the targets on stderr (one per call); ``options`` go to
    ``inverse_kinematics``."""
    positions = np.column_stack([np.zeros(len(heights)), heights, np.zeros(len(heights))])
    load = Loads.from_mass(mass)
    common = dict(load=load, tendons=(1,), bounds=Bounds(tension=(0.0, tension)), **options)
    down = np.array([0.0, -1.0, 0.0])
    with _bar(2 * len(heights), "Sec. V.A inverse kinematics", "target", progress) as bar:
        best = _reach(robot, positions, "y", 1, bar, "stiffest", objective=Stiffness(down), **common)
        plain = _reach(robot, positions, "y", 1, bar, "tendon 1 alone", insertion=0.0, **common)
        bar.set_postfix_str("")
    return StiffestReach(
        np.asarray(heights),
        mass,
        best["tensions"][:, 0],
        best["insertion"],
        _compliance_along(robot, best, down, load),
        best["result"] == 0,
        np.where(plain["result"] == 0, plain["tensions"][:, 0], np.nan),
        _compliance_along(robot, plain, down, load),
    )


class StiffnessMap(NamedTuple):
    """Over in-plane tip targets (rows: the tendon-1 tensions, columns: the insertions that made
    them), tendons 1 and 3 and the tube re-solved by inverse kinematics: the targets' z and y [m],
    the compliance along -y [m/N] of the least-tension solution and of the stiffest one, and their
    insertions [m] (NaN where the IK did not reach)."""

    tensions: np.ndarray
    insertions: np.ndarray
    z: np.ndarray
    y: np.ndarray
    least_tension: np.ndarray
    stiffest: np.ndarray
    insertion_least_tension: np.ndarray
    insertion_stiffest: np.ndarray


def stiffness_map(
    robot: Robot,
    tensions=MAP_TENSIONS,
    insertions=MAP_INSERTIONS,
    counter: float = MAP_COUNTER,
    *,
    progress=True,
    chunk: int = MAP_CHUNK,
    **options,
) -> StiffnessMap:
    """Where, and by how much, choosing the redundant input for stiffness (two in-plane
    coordinates, three inputs: tendons 1 and 3 and the insertion) lowers the tip compliance along
    -y against the least-tension choice, over targets made by forward solves (see MAP_COUNTER).
    ``progress``: bars on stderr; ``chunk``: targets per IK call; ``options`` go to
    ``inverse_kinematics``."""
    made = sweep(
        robot,
        grid={"tensions": np.outer(tensions, [1.0, 0, 0, 0]) + counter * np.array([0, 0, 1.0, 0]), "insertion": insertions},
        progress=progress,
    )
    tips = made.tip_position.reshape(-1, 3)
    positions = np.column_stack([np.zeros(len(tips)), tips[:, 1], tips[:, 2]])
    down = np.array([0.0, -1.0, 0.0])
    out = {}
    with _bar(2 * len(tips), "stiffness map inverse kinematics", "target", progress) as bar:
        for name, objective in (("least_tension", LeastTension()), ("stiffest", Stiffness(down))):
            label = name.replace("_", " ")
            r = _reach(robot, positions, "yz", chunk, bar, label, tendons=(1, 3), objective=objective, **options)
            ok = r["result"] == 0
            out[name] = (
                _compliance_along(robot, r, down, Loads()).reshape(made.shape),
                np.where(ok, r["insertion"], np.nan).reshape(made.shape),
            )
        bar.set_postfix_str("")
    return StiffnessMap(
        np.asarray(tensions),
        np.asarray(insertions),
        made.tip_position[..., 2],
        made.tip_position[..., 1],
        out["least_tension"][0],
        out["stiffest"][0],
        out["least_tension"][1],
        out["stiffest"][1],
    )


def contact_press(
    robot: Robot,
    tension: float = CONTACT_TENSION,
    insertions=CONTACT_INSERTIONS,
    *,
    every: int = 2,
    progress: bool = True,
    **options,
) -> dict:
    """Beyond the paper (issue 26): the tip pressed on a table (``TABLE_HEIGHT``) by tendon 3 at
    ``tension`` [N], per insertion [m]: the normal force on the table [N] and where it acts, and
    the tip compliance [m/N] in contact and free (the stiffness a hand feels at the tip).

    Returns:
        dict of arrays over insertions: insertion, force (total on the table), tip_force (its
        share at the tip candidate), contact_s (arc length of the largest contact force),
        compliance and free_compliance (6, 6 each), result (status codes).
    """
    scene = Scene((Plane(point=(0.0, TABLE_HEIGHT, 0.0), normal=(0.0, 1.0, 0.0), name="table"),), every=every)
    rows = []
    for d in tqdm(insertions, desc="tip on a table", unit="insertion", disable=not progress, leave=False):
        act = Actuation(np.array([0.0, 0.0, tension, 0.0]), d)
        sol = solve(robot, act, scene=scene, throw=False, **options)
        f = np.asarray(sol.contact.force[:, 0])
        CM = compliance(robot, act, scene=scene, throw=False, **options)
        rows.append(
            (
                d,
                f.sum(),
                f[-1],
                float(sol.contact.s[np.argmax(f)]),
                CM,
                compliance(robot, act, throw=False, **options),
                int(sol.result),
            )
        )
    names = ("insertion", "force", "tip_force", "contact_s", "compliance", "free_compliance", "result")
    return {n: np.array([r[i] for r in rows]) for i, n in enumerate(names)}


def body_contact(robot: Robot, tension: float = CYLINDER_TENSION, insertion: float = 0.0, *, every: int = 2, **options):
    """Beyond the paper (issue 26): the body bent by tendon 3 over a cylinder (``CYLINDER``).

    Returns:
        (Solution with its contacts, the Scene, the Actuation).
    """
    scene = Scene((Capsule(**CYLINDER, name="cylinder"),), every=every)
    act = Actuation(np.array([0.0, 0.0, tension, 0.0]), insertion)
    return solve(robot, act, scene=scene, throw=False, **options), scene, act
