"""Calibration: ``calibrate`` fits a model to measurements, shapes or a rig recording; the fit to
measured shapes (paper Sec. III.B) and synthetic shape data live here, the fit to a recording in
``calibrate_rig.py``.

The paper fits the silicone's Young's modulus by minimising the error between five measured shapes
and the model. Here any subset of any robot's scalar fields (``fields.py``: "sections[*].E",
"tendons[0].offset", "tubes[0].E", ...; the paper's former names such as "E_silicone" resolve with
a FutureWarning) is fitted to any number of experiments by Levenberg-Marquardt on the point-wise shape residuals, with the Jacobian
exact (forward-mode autodiff through the implicitly differentiated shooting solution, vmapped over
experiments).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from functools import partial
from time import perf_counter

import jax
import jax.numpy as jnp
import numpy as np
from tqdm import tqdm

from . import fields, status
from .calibrate_rig import RigCalibration, fit_recording
from .checks import check_integer
from .data import Experiment, stack
from .description import Robot
from .inputs import STANDARD_GRAVITY, Actuation, Loads, gravity_vector
from .lm import covariance, levenberg_marquardt
from .mechanics import check_params, shape_errors
from .options import DEFAULT_SOLVER, SolverOptions
from .recording import Recording
from .rig import Rig
from .solve import Solution, check_solution, problem, solve

FBG_POINTS = 33
"""Points per synthetic shape: every 5 mm along the paper's 160 mm robot."""


def _values(x, params) -> dict:
    """Field values from the fitted coordinates: as they are where ``fields.is_linear``, else exp."""
    return {p: x[i] if fields.is_linear(p) else jnp.exp(x[i]) for i, p in enumerate(params)}


def _deviations(robot, batch: Experiment, gravity, solver):
    """Model minus measured positions (E, n, 3) [m], and per experiment: result code, RMSE, tip
    error and the Solution."""

    def one(e):
        sol = solve(robot, e.act, e.tip_load(gravity), gravity=gravity, solver=solver, throw=False)
        dev, e_rms, e_tip = shape_errors(sol, e)
        return dev, (sol.result, e_rms, e_tip, sol)

    return jax.vmap(one)(batch)


@partial(jax.jit, static_argnames=("params",))
def _fit_step(x, robot, batch, gravity, solver, params):
    """Weighted residuals (E n 3,), their exact Jacobian in x, and per-experiment statistics."""

    def residual(x):
        dev, stats = _deviations(fields.replace(robot, _values(x, params)), batch, gravity, solver)
        r = (dev * jnp.sqrt(batch.weight)[..., None]).ravel()
        return r, (r, stats)

    J, (r, stats) = jax.jacfwd(residual, has_aux=True)(x)
    return r, J, stats


_model_shapes = jax.jit(_deviations)


@dataclasses.dataclass(frozen=True)
class Calibration:
    """Result of ``calibrate``; SI units (lengths in m) unless a name says otherwise.

    Attributes:
        params: the fitted fields' names (``fields.py``).
        initial, values: their starting and fitted values.
        std_errors: standard errors from the Gauss-Newton covariance s^2 (J^T J)^-1, with s^2 the
            residual variance per coordinate (delta method for fields fitted in log space).
        correlation: correlation matrix of the fitted fields, (p, p).
        robot: the starting robot with the fitted values.
        names: experiment names.
        rmse_before, rmse_after, tip_error_before, tip_error_after: per experiment [m].
        solutions: the model's Solutions at the fitted values, batched (one per experiment), e.g.
            for ``plotting.plot_calibration``.
        noise: the estimated measurement noise s per coordinate [m].
        iterations, result, message: Levenberg-Marquardt's outcome (every shape must solve):
            steps taken, a ``tdct_jax.status`` code (``converged`` is result == SUCCESS) and what
            it means.
        seconds: wall time, compiles included.
    """

    params: tuple
    initial: dict
    values: dict
    std_errors: dict
    correlation: np.ndarray
    robot: Robot
    names: tuple
    rmse_before: np.ndarray
    rmse_after: np.ndarray
    tip_error_before: np.ndarray
    tip_error_after: np.ndarray
    solutions: Solution
    noise: float
    iterations: int
    result: int
    message: str
    seconds: float

    @property
    def converged(self) -> bool:
        return self.result == status.SUCCESS

    def to_dict(self) -> dict:
        """JSON-ready summary: fitted values in SI, errors in mm and in % of the robot length."""
        L = float(self.robot.length)
        per_file = [
            {
                "name": n,
                **{
                    f"{k}_mm": float(getattr(self, k)[i]) * 1e3
                    for k in ("rmse_before", "rmse_after", "tip_error_before", "tip_error_after")
                },
                "rmse_after_percent_of_length": 100 * float(self.rmse_after[i]) / L,
                "tip_error_after_percent_of_length": 100 * float(self.tip_error_after[i]) / L,
            }
            for i, n in enumerate(self.names)
        ]
        return {
            "params": list(self.params),
            "initial": self.initial,
            "values": self.values,
            "std_errors": self.std_errors,
            "correlation": self.correlation.tolist(),
            "noise_mm": self.noise * 1e3,
            "iterations": self.iterations,
            "converged": self.converged,
            "message": self.message,
            "seconds": self.seconds,
            "experiments": per_file,
        }

    def summary(self) -> str:
        """A text table: fitted values with standard errors, then RMSE and tip error per experiment."""
        L = float(self.robot.length)
        w = max(18, *(len(p) + 2 for p in self.params))
        lines = [f"{'field':<{w}}{'initial':>13}{'fitted':>13}{'std error':>12}"]
        for p in self.params:
            lines.append(f"{p:<{w}}{self.initial[p]:>13.6g}{self.values[p]:>13.6g}{self.std_errors[p]:>12.3g}")
        lines.append("")
        width = max(10, *(len(n) for n in self.names)) + 2
        lines.append(f"{'experiment':<{width}}{'RMSE before':>13}{'RMSE after':>20}{'tip error after':>22}")
        for i, n in enumerate(self.names):
            after, tip = self.rmse_after[i] * 1e3, self.tip_error_after[i] * 1e3
            lines.append(
                f"{n:<{width}}{self.rmse_before[i] * 1e3:>10.3f} mm{after:>10.3f} mm ({100 * after / (L * 1e3):.2f}%)"
                f"{tip:>10.3f} mm ({100 * tip / (L * 1e3):.2f}%)"
            )
        status = "converged" if self.converged else f"NOT converged: {self.message}"
        lines.append(
            f"\n{status} after {self.iterations} iterations in {self.seconds:.1f} s; "
            f"estimated noise {self.noise * 1e3:.3f} mm per coordinate"
        )
        return "\n".join(lines)


def calibrate(
    model: Robot | Rig,
    data: Sequence[Experiment] | Recording,
    params: Sequence[str] | None = None,
    *,
    pulls: Recording | None = None,
    bounds: Mapping[str, tuple] | None = None,
    max_steps: int | None = None,
    xtol: float | None = None,
    ftol: float | None = None,
    gravity=STANDARD_GRAVITY,
    solver: SolverOptions | None = None,
    progress: bool = True,
    throw: bool = True,
) -> Calibration | RigCalibration:
    """Fits a model's values to measurements by Levenberg-Marquardt with exact Jacobians.

    One verb for the two kinds of measurement:

    - **shapes**: ``model`` a Robot, ``data`` a sequence of Experiment (points along the body
      under known actuation and loads, paper Sec. III.B; ``data.read_experiments``). Fits robot
      fields (default ``("sections[*].E",)``); see ``fit_shapes``. Returns a Calibration.
    - **a rig recording**: ``model`` a Rig, ``data`` a Recording (servo readings in, measured
      tips out; ``read_recording``, ``read_dataset``). Fits robot fields and rig values (default
      ``calibrate_rig.default_params(rig)``), with ``bounds``, after a geometry step from
      single-tendon ``pulls`` where given (``Dataset.pulls``); see ``calibrate_rig.fit_recording``.
      Returns a RigCalibration. Gravity is the rig's own value.

    ``max_steps``, ``xtol``, ``ftol`` (the fit's own limit and tolerances) and ``solver`` default
    to each kind's own (None); ``progress`` shows a bar; ``throw`` raises ConvergenceError when
    the fit does not converge (default, as everywhere).
    """
    given = {k: v for k, v in dict(max_steps=max_steps, xtol=xtol, solver=solver).items() if v is not None}
    if isinstance(data, Recording):
        if not isinstance(model, Rig):
            raise TypeError(f"a recording is fitted on its rig: model must be a tdct.Rig, got {type(model).__name__}")
        if gravity is not STANDARD_GRAVITY:
            raise TypeError("gravity: a recording's gravity is its rig's own (Rig.g, gravity_azimuth, gravity_elevation)")
        rig_options = dict(given, **({} if ftol is None else {"ftol": ftol}))
        return fit_recording(model, data, params, pulls=pulls, bounds=bounds, progress=progress, throw=throw, **rig_options)
    if bounds is not None or ftol is not None or pulls is not None:
        raise TypeError("pulls, bounds and ftol apply to a rig recording's fit (data a tdct.Recording)")
    if not isinstance(model, Robot):
        raise TypeError(f"shapes are fitted on a robot: model must be a tdct.Robot, got {type(model).__name__}")
    params = ("sections[*].E",) if params is None else params
    return fit_shapes(model, data, params, gravity=gravity, progress=progress, throw=throw, **given)


def fit_shapes(
    robot: Robot,
    experiments: Sequence[Experiment],
    params: Sequence[str] = ("sections[*].E",),
    *,
    max_steps: int = 30,
    xtol: float = 1e-8,
    gravity=STANDARD_GRAVITY,
    solver: SolverOptions = DEFAULT_SOLVER,
    progress: bool = True,
    throw: bool = True,
) -> Calibration:
    """Fits robot fields to measured shapes by Levenberg-Marquardt with exact Jacobians (Sec. III.B;
    ``tdct.calibrate(robot, experiments)``).

    The residuals are model minus measured positions at every measured point of every experiment
    (weighted by ``Experiment.weight``), so the cost is the sum of the experiments' squared RMSEs
    (eq. 39) times their point counts. Fields are fitted in log space unless ``fields.is_linear``
    (Poisson ratios, tendon angles and twists are fitted as they are).

    Args:
        robot: the robot with the starting values of ``params`` and every other field fixed.
        experiments: measured shapes and their conditions (``tdct_jax.data.read_experiments``):
            Actuations (empty tensions or insertions: zeros of the robot's counts) and Loads.
        params: field names to fit (``fields.names``), e.g. ("sections[*].E",
            "tendons[*].offset"), "[*]" fitting one value shared by every item; a single name may
            be given as a string. The default fits one modulus for the whole body. The paper's
            former names ("E_silicone", "tendon_offset", ...) resolve with a FutureWarning; the
            Calibration keeps the names as given.
        max_steps: most Levenberg-Marquardt trial steps (the fit's own limit).
        xtol: converged when the Gauss-Newton step changes no field by more than this (relative
            for log-space fields, absolute for Poisson ratios): the fit's own tolerance.
        gravity: world gravity [m/s^2] the shapes were measured under (None: none).
        solver: SolverOptions for every solve.
        progress: show a progress bar (the first step includes the compile).
        throw: raise ConvergenceError when the fit does not converge (default, as everywhere);
            with False check ``converged`` / ``result``.

    Returns:
        Calibration.

    Raises:
        ValueError: unknown or repeated params, no experiments, experiments that do not fit the robot.
        ConvergenceError: with ``throw=True``, when the fit did not converge.
    """
    params = _as_names(params)
    _check_params(robot, params)
    experiments = list(experiments)
    if not experiments or not all(isinstance(e, Experiment) for e in experiments):
        raise ValueError("experiments must be a non-empty sequence of tdct_jax.data.Experiment")
    experiments = _checked_experiments(robot, experiments, solver)
    max_steps = check_integer("max_steps", max_steps)
    batch, g = stack(experiments), gravity_vector(gravity)

    start = perf_counter()
    bar = tqdm(desc="calibrating", unit="step", disable=not progress, leave=False)
    bar.set_postfix_str("compiling")
    first = []

    def evaluate(x):
        r, J, (codes, e_rms, e_tip, sol) = _fit_step(jnp.asarray(x), robot, batch, g, solver, params)
        stats = (np.asarray(e_rms), np.asarray(e_tip), sol)
        first[:] = first or [stats]
        return np.asarray(r), np.asarray(J), status.first_failure(codes), stats

    def report(it, r, step):
        bar.update(it - bar.n)
        bar.set_postfix_str(f"rms {np.sqrt(np.mean(r**2) * 3) * 1e3:.4f} mm, step {np.abs(step).max():.1e}")

    initial = {p: fields.value(robot, p) for p in params}
    x0 = np.array([v if fields.is_linear(p) else np.log(v) for p, v in initial.items()])
    fit = levenberg_marquardt(evaluate, x0, max_steps=max_steps, xtol=xtol, callback=report)
    bar.close()
    before = first[0]

    values = {p: float(v) for p, v in _values(fit.x, params).items()}
    _, se_x, correlation, s2 = covariance(fit, 3 * int(np.count_nonzero(np.asarray(batch.weight))))
    scale = np.array([1.0 if fields.is_linear(p) else values[p] for p in params])
    result = Calibration(
        params=params,
        initial=initial,
        values=values,
        std_errors={p: float(scale[i] * se_x[i]) for i, p in enumerate(params)},
        correlation=correlation,
        robot=fields.replace(robot, values),
        names=tuple(e.name for e in experiments),
        rmse_before=before[0],
        rmse_after=fit.aux[0],
        tip_error_before=before[1],
        tip_error_after=fit.aux[1],
        solutions=fit.aux[2],
        noise=float(np.sqrt(s2)),
        iterations=fit.iterations,
        result=fit.result,
        message=fit.message,
        seconds=perf_counter() - start,
    )
    status.check(fit.result, throw=throw, what=f"the calibration of {', '.join(params)}", max_steps=max_steps)
    return result


def _as_names(params) -> tuple:
    """A field name, or a sequence of them, as a tuple of names (a string is one name)."""
    if isinstance(params, str):
        return (params,)
    try:
        return tuple(params)
    except TypeError:
        raise ValueError(f"params = {params!r} must be a Robot field name or a sequence of them") from None


def _check_params(robot: Robot, params: tuple) -> None:
    if not params or len(set(params)) != len(params):
        raise ValueError(f"params = {params!r} must name at least one Robot field, each once")
    check_params(robot, params)
    for p in params:
        if not fields.is_linear(p) and not fields.value(robot, p) > 0:
            raise ValueError(f"{p} = {fields.value(robot, p):g} must start positive: it is fitted in log space")


def _checked_experiments(robot: Robot, experiments: list, solver: SolverOptions) -> list:
    """The experiments checked against the robot (``solve.problem``), with their actuations'
    defaults filled in (``Actuation.of``)."""
    out = []
    for e in experiments:
        _, act, load = problem(robot, e.act, e.load, solver)
        out.append(dataclasses.replace(e, act=act, load=load))
    return out


def synthesize(
    robot: Robot,
    actuations: Sequence[Actuation],
    *,
    tip_masses: Sequence[float] | None = None,
    loads: Sequence[Loads] | None = None,
    n_points: int = FBG_POINTS,
    noise: float = 1e-4,
    seed: int = 0,
    gravity=STANDARD_GRAVITY,
    solver: SolverOptions = DEFAULT_SOLVER,
) -> list[Experiment]:
    """FBG-like measured shapes from the model: positions at ``n_points`` equally spaced arc
    lengths from base to tip, plus Gaussian noise of standard deviation ``noise`` [m] on every
    coordinate (numpy's default generator seeded with ``seed``).

    Args:
        robot: the robot that "is measured".
        actuations: one Actuation per experiment.
        tip_masses: tip mass per experiment [kg] (default none).
        loads: further loads per experiment, world frame (Loads; default none).
        n_points: points per shape (>= 2).
        noise: noise standard deviation [m] (>= 0).
        seed: random seed.
        gravity: world gravity [m/s^2] (None: none).
        solver: SolverOptions for the solves.

    Raises:
        ValueError: bad counts or values; ConvergenceError: a shape that did not solve (always:
            there is no shape to return for it).
    """
    n_exp = len(actuations)
    tip_masses = [0.0] * n_exp if tip_masses is None else list(tip_masses)
    loads = [Loads()] * n_exp if loads is None else list(loads)
    if n_exp == 0 or len(tip_masses) != n_exp or len(loads) != n_exp:
        raise ValueError(f"need one actuation, tip mass and load per experiment, got {n_exp}, {len(tip_masses)} and {len(loads)}")
    n_points = check_integer("n_points", n_points, 2)
    if not (np.isfinite(noise) and noise >= 0):
        raise ValueError(f"noise = {noise!r} must be a finite standard deviation >= 0 [m]")
    s = np.linspace(0.0, float(robot.length), n_points)
    actuations = [Actuation.of(a, robot) for a in actuations]
    exact = [
        Experiment(s, np.zeros((n_points, 3)), a, ld, m, name=condition_name(a, m))
        for a, ld, m in zip(actuations, loads, tip_masses, strict=True)
    ]
    exact = _checked_experiments(robot, exact, solver)
    dev, (_, _, _, sol) = _model_shapes(robot, stack(exact), gravity_vector(gravity), solver)
    names = ", ".join(e.name for e in exact)
    check_solution(sol, solver, True, what=f"synthesize (experiments {names})")
    rng = np.random.default_rng(seed)
    return [
        dataclasses.replace(e, position=np.asarray(p) + noise * rng.standard_normal((n_points, 3)))
        for e, p in zip(exact, dev, strict=True)
    ]


def condition_name(act: Actuation, tip_mass: float = 0.0) -> str:
    """A file-name-safe label of a measurement condition, e.g. "t6-0-0-0N_d80mm_m20g": the
    tensions, the driven tendons' displacements and every tube's depth, e.g.
    "t0-0.4N_x3-1mm_d80-20mm_m0g" (displacements 3 and 1 mm, tubes at 80 and 20 mm)."""

    def joined(values, scale=1.0):
        return "-".join(f"{v * scale:g}" for v in np.asarray(values, dtype=float))

    moved = f"_x{joined(act.displacements, 1e3)}mm" if act.driven else ""
    depths = f"_d{joined(act.insertions, 1e3)}mm" if np.size(act.insertions) else ""
    return f"t{joined(act.tensions)}N{moved}{depths}_m{float(tip_mass) * 1e3:g}g"
