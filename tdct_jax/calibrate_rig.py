"""Calibration of a robot on its rig from a recording (servo readings in, measured tips out), and
the prediction of a held-out recording with the fitted values frozen.

Any robot field and any rig value (``rig.py``: servo scale, pretensions, registration, gravity's
direction) is fitted by Levenberg-Marquardt with bounds on the tip residuals, model minus
measured in the measurement frame, with the Jacobian exact: forward-mode autodiff through the
implicitly differentiated displacement-driven solve of every sample. The first step solves along
the recorded sequence (``rig.along``); every later one starts each sample from its solution at the
step before, side by side (Newton without a load ramp); in a trial whose other samples already
lower the cost, a sample lost that way is reached along the recording at the trial's values
instead, and a trial where some sample still fails counts as a failed step (Levenberg-Marquardt
then takes a shorter one). With tendon friction every step solves along the sequence, each sample
taking the last one's tension profile as its memory, and the Jacobian carries each parameter's
tangent through the memory too.
"""

from __future__ import annotations

import dataclasses
import itertools
import warnings
from collections.abc import Mapping, Sequence
from functools import partial
from pathlib import Path
from time import perf_counter

import jax
import jax.numpy as jnp
import numpy as np
from tqdm import tqdm

from . import rig as rigs
from . import rod, status
from .checks import UnitWarning, check_integer, deprecated
from .data import _error
from .lm import covariance, levenberg_marquardt
from .options import SolverOptions
from .recording import Recording, check_tendons

RIG_SOLVER = SolverOptions(steps=8)
"""Solver for recordings: 8 RK4 steps per interval between breakpoints moves the tips of the
three-segment example by under 0.1 um against 40 steps, far below any motion capture's noise."""
RIG_PARAMS = ("sections[*].E", "scale", "rotation[0]", "rotation[1]", "translation[0]", "translation[1]", "translation[2]")
"""A small fit: the backbone's modulus, the servo scale and the registration (rotation about the
robot axis is left to the tendon angles, with which it is degenerate). The default is
``default_params``."""


def default_params(rig: rigs.Rig) -> tuple:
    """The default fit of a rig, for any robot: the servo scale; per segment (consecutive tendons
    anchored at the same arc length) one pretension and one tendon stiffness; every tendon's
    angle; each section's friction coefficient where it has one; the registration but its
    rotation about the robot's axis (the angles' common part).
    The backbone's E stays: without gravity, E, the tendons' stiffness and their pretension act
    only in ratio (and on the ftdcr-v4 recording, with gravity on, E correlates +1.00 with the
    pretensions)."""
    tendons = rig.robot.tendons
    segments = [list(run) for _, run in itertools.groupby(range(len(tendons)), key=lambda i: tendons[i].end)]
    groups = [f"{s[0]}-{s[-1]}" if len(s) > 1 else f"{s[0]}" for s in segments]
    params = ["scale", *(f"pretension[{g}]" for g in groups), *(f"tendons[{g}].stiffness" for g in groups)]
    params += [f"tendons[{i}].angle" for i in range(len(tendons))]
    params += [f"sections[{j}].friction" for j, sec in enumerate(rig.robot.sections) if sec.friction is not None]
    return (*params, "rotation[0]", "rotation[1]", "translation[0]", "translation[1]", "translation[2]")


def _values(x, params) -> dict:
    """Named values from the fitted coordinates: as they are where ``rig.is_linear``, else exp."""
    return {p: x[i] if rigs.is_linear(p) else jnp.exp(x[i]) for i, p in enumerate(params)}


def _coordinates(values, params) -> np.ndarray:
    return np.array([v if rigs.is_linear(p) else np.log(v) for p, v in zip(params, values, strict=True)], float)


@partial(jax.jit, static_argnames=("params", "solver"))
def _fit_step(x, rig, servos, guesses, measured, params, solver):
    """Tip residuals (3 n,) [m], their exact Jacobian in x, the unknowns found and status codes.
    Each sample starts from its guess, side by side; with tendon friction the samples are solved
    in order instead (``rig.along``; ``guesses`` unused), each with the last one's tension profile
    as memory, so that forward mode carries each parameter's tangent through the memory too
    (about twice the cost of the sequence itself)."""

    def residual(x):
        fitted = rigs.replace(rig, _values(x, params))
        if rig.robot.has_friction:
            tip, unknowns, code, _ = rigs._along(fitted, servos, solver)
        else:
            # warm starts need no load ramp from zero, and under vmap one failing sample would make
            # every sample run all of its stages
            tip, unknowns, code, _ = rigs._batch(fitted, servos, guesses, dataclasses.replace(solver, stages=(1,)))
        r = (tip - measured).ravel()
        return r, (r, unknowns, code)

    J, (r, unknowns, codes) = jax.jacfwd(residual, has_aux=True)(x)
    return r, J, unknowns, codes


@dataclasses.dataclass(frozen=True)
class RigCalibration:
    """Result of ``tdct.calibrate`` on a rig recording; SI units (m, N, Pa, rad).

    Attributes:
        params: the fitted names (``rig.py``). initial, values: their start and fitted values.
        std_errors: standard errors, s^2 (J^T J)^+ with s^2 the residual variance per coordinate
            (delta method for values fitted in log space).
        correlation: their correlation matrix (p, p): entries near +-1 mark values the data
            cannot tell apart.
        rig: the starting rig with the fitted values.
        before, after: tip errors on the fitted recording before and after (``rig.errors``).
        history: the tip RMSE [m] (registration as fitted, no offset removed) at the start and
            after each accepted step.
        noise: residual standard deviation per coordinate [m].
        left_out: the file lines of the samples left out of the fit: those that solve neither
            from the straight robot nor from a neighbour in the sequence at the starting values
            (with tendon friction, also those the fit's in-order chain does not reach from the
            sample kept before them).
        geometry: the geometry step's findings (``identify_geometry``), or None without pulls;
            ``initial`` holds the values after it.
        iterations, result, message: Levenberg-Marquardt's outcome (``converged``: result ==
            SUCCESS); an unconverged fit keeps its best values.
        seconds: wall time, compiles included.
    """

    params: tuple
    initial: dict
    values: dict
    std_errors: dict
    correlation: np.ndarray
    rig: rigs.Rig
    before: dict
    after: dict
    history: tuple
    noise: float
    left_out: tuple
    geometry: Geometry | None
    iterations: int
    result: int
    message: str
    seconds: float

    @property
    def converged(self) -> bool:
        return self.result == status.SUCCESS

    def to_dict(self) -> dict:
        """JSON-ready: values and standard errors in SI units, errors in mm."""
        return {
            "params": list(self.params),
            "initial": self.initial,
            "values": self.values,
            "std_errors": self.std_errors,
            "correlation": np.round(self.correlation, 4).tolist(),
            "before_mm": _mm(self.before),
            "after_mm": _mm(self.after),
            "history_rmse_mm": [1e3 * h for h in self.history],
            "noise_mm": 1e3 * self.noise,
            "left_out_lines": list(self.left_out),
            "geometry": None if self.geometry is None else self.geometry.to_dict(),
            "iterations": self.iterations,
            "converged": self.converged,
            "message": self.message,
            "seconds": self.seconds,
        }

    def summary(self) -> str:
        """A text table: values with standard errors, the strongest correlations, the tip errors."""
        w = max(20, *(len(p) + 2 for p in self.params))
        lines = []
        if self.geometry is not None:
            g = self.geometry
            found = ", ".join("-" if np.isnan(a) else f"{np.degrees(a):.1f}" for a in g.angles)
            lines.append(f"geometry from single-tendon pulls: tendon angles [deg] {found}; servo sign {g.sign:+.0f}\n")
        lines.append(f"{'value':<{w}}{'initial':>13}{'fitted':>13}{'std error':>12}")
        stepped = self.iterations > 0 or self.converged  # a fit that never stepped has no errors to show
        lines += [
            f"{p:<{w}}{self.initial[p]:>13.6g}{self.values[p]:>13.6g}"
            + (f"{self.std_errors[p]:>12.3g}" if stepped else f"{'-':>12}")
            for p in self.params
        ]
        i, j = np.triu_indices(len(self.params), 1)
        strong = sorted(zip(np.abs(self.correlation[i, j]), i, j, strict=True), reverse=True)[:5]
        if strong:
            lines.append(
                "\nstrongest correlations: "
                + ", ".join(f"{self.params[a]} ~ {self.params[b]} {self.correlation[a, b]:+.2f}" for _, a, b in strong)
            )
        b, a = self.before, self.after
        lines.append(
            f"\ntip error, mean offset removed: RMSE {1e3 * b['rmse']:.2f} -> {1e3 * a['rmse']:.2f} mm "
            f"(median {1e3 * a['median']:.2f}, 95th percentile {1e3 * a['p95']:.2f} mm, {a['n']} samples)"
        )
        if self.left_out:
            shown = ", ".join(map(str, self.left_out[:10])) + (", ..." if len(self.left_out) > 10 else "")
            lines.append(f"left out {len(self.left_out)} samples that did not solve at the starting values (lines {shown})")
        state = "converged" if self.converged else f"NOT converged: {self.message}"
        lines.append(f"{state} after {self.iterations} steps in {self.seconds:.1f} s")
        return "\n".join(lines)


def _mm(errors: dict) -> dict:
    return {k: (np.round(1e3 * np.asarray(v), 4).tolist() if k != "n" else v) for k, v in errors.items()}


def _servos(rig: rigs.Rig, rec: Recording) -> np.ndarray:
    """The recording's servo readings [m], (n, n_t), checked against the rig: each pull shorter
    than its tendon's rest length to its anchor (a reading beyond it is a unit slip, e.g. mm
    read as m), named by file, line, column and value."""
    check_tendons(rec, rig.robot.n_tendons)
    if rec.displacements is None or rec.tip is None:
        raise ValueError(f"{rec.path}: a rig calibration needs displacement columns and tip columns")
    pulls = np.asarray(jax.vmap(rig.displacements)(jnp.asarray(rec.displacements)))
    rest = np.asarray(rod.rest_lengths(rig.robot))
    beyond = np.argwhere(np.abs(pulls) >= rest)
    if beyond.size:
        row, k = beyond[0]
        column, unit = [(name, u) for role, name, u in rec.columns if role == "displacements"][k]
        raise _error(
            rec.path,
            int(rec.lines[row]),
            f"column {column}: {1e3 * rec.displacements[row, k]:g} mm moves tendon {k + 1} by {1e3 * pulls[row, k]:g} mm, "
            f"beyond its rest length {1e3 * rest[k]:g} mm to its anchor ({len(beyond)} such values): "
            f"check the column's unit (read as {unit or 'm'})",
        )
    return rec.displacements


PULL_MARGIN = 0.5e-3
"""A sample is a single-tendon pull when its pulled tendon's servo reading exceeds every other
tendon's by more than this [m]."""


@dataclasses.dataclass(frozen=True)
class Geometry:
    """What ``identify_geometry`` found (SI units, angles in rad).

    Attributes:
        angles: each tendon's angle identified from its pulls, (n_t,), NaN for a tendon pulled
            alone fewer than twice (its angle kept).
        before: the angles the rig had.
        sign: the servo sign, +1 where a positive reading pulls, -1 where a negative one does.
        samples: how many samples pulled each tendon alone, (n_t,).
    """

    angles: np.ndarray
    before: np.ndarray
    sign: float
    samples: np.ndarray

    def to_dict(self) -> dict:
        deg = lambda a: [None if np.isnan(x) else round(float(np.degrees(x)), 3) for x in a]  # noqa: E731
        return {
            "angles_deg": deg(self.angles),
            "before_deg": deg(self.before),
            "sign": self.sign,
            "samples": self.samples.tolist(),
        }


def identify_geometry(rig: rigs.Rig, pulls: Recording) -> tuple[rigs.Rig, Geometry]:
    """The geometry step of a rig calibration, from a recording of single-tendon pulls: each
    tendon's angle and the servo sign, with no solve and no start to be near (angles wrong by
    180 degrees are found as readily as right ones).

    A tendon pulled alone bends the robot toward its own side, so the tip moves, across the
    robot's axis, in the direction of the tendon's angle. For each sign of the servo readings, the
    samples where one tendon's reading exceeds every other's by ``PULL_MARGIN`` are its pulls; the
    sign whose pulls move the tip farthest is the servo's (relative to the rig's ``sign``). Each
    tendon's angle is the direction of the sum of its pulls' tip motions from its least pull (two
    pulls at least: a rest pose would carry the pretensions' own bend), taken in the robot's base
    frame through the rig's registration ``rotation`` (so a rotation about the axis is carried by
    the angles). Gravity across the robot tilts the motions a little: the calibration that follows
    refines the angles it fits.

    Returns:
        The rig with those angles and its servo sign, and the Geometry found.
    """
    servos, tips = _servos(rig, pulls), np.asarray(pulls.tip)
    R = np.asarray(rigs.rotation_matrix(jnp.asarray(rig.rotation)))
    across = (tips @ R)[:, :2]  # R^T tip, across the axis
    n, k = servos.shape
    found = []
    for sign in (1.0, -1.0):
        s = sign * servos
        pulled = np.argmax(s, axis=1)
        others = np.where(np.arange(k)[None] == pulled[:, None], -np.inf, s).max(axis=1)
        amount = s[np.arange(n), pulled]
        alone = amount - others > PULL_MARGIN
        spread = sum(np.ptp(across[m], axis=0).sum() for m in (alone & (pulled == i) for i in range(k)) if m.any())
        found.append((spread, sign, pulled, alone, amount))
    _, sign, pulled, alone, amount = max(found, key=lambda f: f[0])
    before = np.array([float(t.angle) for t in rig.robot.tendons])
    angles, samples = np.full(k, np.nan), np.zeros(k, int)
    for i in range(k):
        mine = alone & (pulled == i)
        samples[i] = np.count_nonzero(mine)
        if samples[i] > 1:
            least = np.flatnonzero(mine)[np.argmin(amount[mine])]
            v = (across[mine] - across[least]).sum(axis=0)
            angles[i] = np.arctan2(v[1], v[0])
    values = {f"tendons[{i}].angle": float(angles[i]) for i in range(k) if samples[i] > 1}
    return dataclasses.replace(rigs.replace(rig, values), sign=sign * float(rig.sign)), Geometry(angles, before, sign, samples)


def fit_recording(
    rig: rigs.Rig,
    recording: Recording,
    params: Sequence[str] | None = None,
    *,
    pulls: Recording | None = None,
    bounds: Mapping[str, tuple] | None = None,
    max_steps: int = 40,
    xtol: float = 1e-6,
    ftol: float = 1e-8,
    solver: SolverOptions = RIG_SOLVER,
    progress: bool = True,
    throw: bool = True,
) -> RigCalibration:
    """Fits rig and robot values to a recording by bounded Levenberg-Marquardt with exact Jacobians
    (``tdct.calibrate(rig, recording)``).

    Args:
        rig: the robot on its rig with the starting values and every value not fitted.
        recording: servo readings (``displacements``) and measured tips (``recording.py``).
        params: names to fit (``rig.py``; robot fields as in ``fields.py``, ranges ``[a-b]``);
            None: ``default_params(rig)``. Fitted ``translation`` components start at the mean
            offset between the measured tips and the model's at the start (their least-squares
            value there).
        pulls: (optional) a recording of single-tendon pulls: the geometry step
            (``identify_geometry``: each tendon's angle and the servo sign) comes first, so the
            fit may start from a nominal description whose angles are far off.
        bounds: {name: (lo, hi)} in SI units; pretensions and friction coefficients are kept >= 0
            unless given.
        max_steps: most Levenberg-Marquardt trial steps. xtol: converged when the bounded
            Gauss-Newton step moves no coordinate by more than this (relative for values fitted
            in log space); ftol: or when a step lowers the squared error by at most this
            fraction (values the data cannot tell apart let the steps stay long).
        solver: SolverOptions for every sample.
        progress: show a progress bar (the first step includes the compile).
        throw: raise ConvergenceError when the fit does not converge; with False check ``converged``.

    Raises:
        ValueError: unknown or repeated names, bounds that do not hold the start, a recording that
            does not fit the robot.
    """
    params = default_params(rig) if params is None else (params,) if isinstance(params, str) else tuple(params)
    if not params or len(set(params)) != len(params):
        raise ValueError(f"params = {params!r} must name at least one value, each once")
    for p in params:
        rigs.check_name(rig, p)
    max_steps = check_integer("max_steps", max_steps)
    geometry = None
    if pulls is not None:
        rig, geometry = identify_geometry(rig, pulls)
    servos, measured = jnp.asarray(_servos(rig, recording)), jnp.asarray(recording.tip)  # checked with the rig's sign
    start = perf_counter()
    bar = tqdm(desc="calibrating", unit="step", disable=not progress, leave=False)
    bar.set_postfix_str("solving along the recording (compiling)")
    tip, unknowns, codes, _ = _from_neighbours(rig, servos, solver)
    keep = np.flatnonzero(codes == status.SUCCESS)
    while rig.robot.has_friction and keep.size:  # the fit solves in order: what that chain cannot reach stays out
        reached = np.asarray(rigs.along(rig, servos[keep], solver)[2]) == status.SUCCESS
        if reached.all():
            break
        keep = keep[reached]
    left_out = tuple(int(line) for line in np.delete(np.asarray(recording.lines), keep))
    if keep.size == 0:
        raise status.ConvergenceError(
            f"{recording.path}: no sample solves at the starting values (first code {int(codes[0])}): "
            "check the robot file and the servo units",
            int(codes[0]),
        )
    servos, measured, tip, unknowns = servos[keep], measured[keep], tip[keep], unknowns[keep]
    guesses = [unknowns]
    offset = np.mean(np.asarray(measured) - np.asarray(tip), axis=0)
    shifted = {f"translation[{i}]": float(rig.translation[i] + offset[i]) for i in range(3)}
    rig = rigs.replace(rig, {k: v for k, v in shifted.items() if k in params})
    initial = {p: rigs.value(rig, p) for p in params}
    lo, hi = _bounds(params, initial, bounds or {})
    history, first, cost = [], [], [np.inf]

    def side_by_side(x):
        """Every sample from its last solution; a lost one reached along the recording."""
        r, J, unknowns, codes = _fit_step(jnp.asarray(x), rig, servos, guesses[0], measured, params, solver)
        codes = np.asarray(codes)
        solved = np.repeat(codes == status.SUCCESS, 3)
        promising = np.sum(np.where(solved, np.asarray(r), 0.0) ** 2) < cost[0]  # else the step fails anyway
        if not solved.all() and promising and (trial := _trial(rig, x, params)) is not None:
            # lost from their last solutions: reached along the recording instead
            fresh = _from_neighbours(trial, servos, solver)[1]
            retry = jnp.asarray(np.where((codes != status.SUCCESS)[:, None], fresh, np.asarray(guesses[0])))
            r, J, unknowns, codes = _fit_step(jnp.asarray(x), rig, servos, retry, measured, params, solver)
        return r, J, unknowns, codes

    def evaluate(x):
        if rig.robot.has_friction:  # in order: no lost sample to reach another way
            out = _fit_step(jnp.asarray(x), rig, servos, guesses[0], measured, params, solver)
        else:
            out = side_by_side(x)
        r, J, unknowns, codes = (np.asarray(a) for a in out)
        if np.all(codes == status.SUCCESS):
            guesses[0] = unknowns
            cost[0] = min(cost[0], float(r @ r))  # the cost of the point the fit stands at
        first[:] = first or [r]
        history[:] = history or [float(np.sqrt(np.mean(r**2) * 3))]
        return r, J, status.first_failure(codes), r

    def report(it, r, step):
        history.append(float(np.sqrt(np.mean(r**2) * 3)))
        bar.update(it - bar.n)
        bar.set_postfix_str(f"tip rms {1e3 * history[-1]:.3f} mm, step {np.abs(step).max():.1e}")

    x0 = _coordinates(initial.values(), params)
    fit = levenberg_marquardt(evaluate, x0, lower=lo, upper=hi, max_steps=max_steps, xtol=xtol, ftol=ftol, callback=report)
    bar.close()
    values = {p: float(v) for p, v in _values(fit.x, params).items()}
    _, se_x, correlation, s2 = covariance(fit, measured.size)
    scale = np.array([1.0 if rigs.is_linear(p) else values[p] for p in params])
    fitted = rigs.replace(rig, values)
    measured = np.asarray(measured)
    result = RigCalibration(
        params=params,
        initial=initial,
        values=values,
        std_errors={p: float(scale[i] * se_x[i]) for i, p in enumerate(params)},
        correlation=correlation,
        rig=fitted,
        before=rigs.errors(measured + first[0].reshape(-1, 3), measured),
        after=rigs.errors(measured + fit.aux.reshape(-1, 3), measured),
        history=tuple(history),
        noise=float(np.sqrt(s2)),
        left_out=left_out,
        geometry=geometry,
        iterations=fit.iterations,
        result=fit.result,
        message=fit.message,
        seconds=perf_counter() - start,
    )
    status.check(fit.result, throw=throw, what=f"the rig calibration of {', '.join(params)}", max_steps=max_steps)
    return result


def calibrate_rig(rig: rigs.Rig, recording: Recording, params: Sequence[str] = RIG_PARAMS, **options) -> RigCalibration:
    """Former name of ``tdct.calibrate(rig, recording, params)``."""
    deprecated("tdct.calibrate_rig", "tdct.calibrate(rig, recording, params)")
    return fit_recording(rig, recording, params, **options)


def _trial(rig: rigs.Rig, x, params):
    """The rig at a trial step's fitted coordinates x, or None where a value there is out of range
    (a step so long that a value fitted in log space underflows: the step fails as it is). Trial
    values get no UnitWarning; the fitted ones do."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UnitWarning)
            return rigs.replace(rig, {p: float(v) for p, v in _values(jnp.asarray(x), params).items()})
    except ValueError:
        return None


def _from_neighbours(rig: rigs.Rig, servos, solver: SolverOptions):
    """``rig.along`` the sequence, then the samples it could not reach along it again: solved from
    the solutions of a pass from the end backward (their neighbour after), each with its memory
    from the forward pass (friction's memory runs forward only): tips, unknowns, codes and tension
    profiles (numpy; profiles None without friction)."""
    out = [None if a is None else np.array(a) for a in rigs.along(rig, servos, solver)]
    failed = np.flatnonzero(out[2] != status.SUCCESS)
    if failed.size:
        _, back, codes, _ = (None if a is None else np.asarray(a)[::-1] for a in rigs.along(rig, servos[::-1], solver))
        failed = failed[codes[failed] == status.SUCCESS]
        back = back[failed]
    if failed.size:
        memory = rigs.memories(out[3])
        again = rigs._batch(rig, servos[failed], jnp.asarray(back), solver, None if memory is None else memory[failed])
        fixed = np.asarray(again[2]) == status.SUCCESS
        for a, b in zip(out, again, strict=True):
            if a is not None:
                a[failed[fixed]] = np.asarray(b)[fixed]
    return tuple(out)


def _bounds(params, initial, bounds):
    """Bounds in the fitted coordinates, (lo, hi) each (p,); ValueError for a bound that does not
    hold the start or names an unfitted value."""
    unknown = set(bounds) - set(params)
    if unknown:
        raise ValueError(f"bounds name {sorted(unknown)}, which are not in params {list(params)}")
    lo, hi = np.full(len(params), -np.inf), np.full(len(params), np.inf)
    for i, p in enumerate(params):
        nonnegative = p.startswith("pretension") or p.endswith(".friction")
        a, b = bounds.get(p, (0.0, np.inf) if nonnegative else (-np.inf, np.inf))
        if not a <= initial[p] <= b:
            raise ValueError(f"bounds[{p!r}] = ({a:g}, {b:g}) must hold the starting value {initial[p]:g}")
        if rigs.is_linear(p):
            lo[i], hi[i] = a, b
        else:
            lo[i] = np.log(a) if a > 0 else -np.inf
            hi[i] = np.log(b) if np.isfinite(b) else np.inf
    return lo, hi


@dataclasses.dataclass(frozen=True)
class Prediction:
    """Result of ``predict``: the model's tips for a recording's servo readings, and their errors.

    Attributes:
        tips, measured: model and measured tips in the measurement frame [m], (n, 3).
        patterns: each sample's motion pattern (``Recording.patterns``).
        codes: each sample's status code; failed samples are left out of the errors.
        errors: tip errors with the mean offset removed (``rig.errors``).
        per_pattern: {pattern family: errors}, the family a pattern without its trailing
            ``_dir<angle>``, the offset removed being the whole recording's.
        seconds_per_pose: wall time of one pass along the recording (compiled before) over its
            samples.
    """

    tips: np.ndarray
    measured: np.ndarray
    patterns: np.ndarray
    codes: np.ndarray
    errors: dict
    per_pattern: dict
    seconds_per_pose: float

    @property
    def families(self) -> np.ndarray:
        """Each sample's pattern family, (n,) str: its pattern without a trailing ``_dir<angle>``."""
        return np.array([_family(p) for p in self.patterns])

    def to_dict(self) -> dict:
        return {
            "errors_mm": _mm(self.errors),
            "per_pattern_mm": {k: _mm(v) for k, v in self.per_pattern.items()},
            "failed_samples": int(np.count_nonzero(self.codes)),
            "seconds_per_pose": self.seconds_per_pose,
        }


def predict(rig: rigs.Rig, recording: Recording, *, solver: SolverOptions = RIG_SOLVER) -> Prediction:
    """The model's tips for a recording's servo readings alone (along the sequence, warm-started
    sample by sample, as a controller would run it), and their errors against its measured tips."""
    servos = jnp.asarray(_servos(rig, recording))
    jax.block_until_ready(rigs.along(rig, servos, solver))
    t = perf_counter()
    tips, _, codes, _ = jax.block_until_ready(rigs.along(rig, servos, solver))
    seconds = (perf_counter() - t) / len(servos)
    tips, codes, measured = np.asarray(tips), np.asarray(codes), np.asarray(recording.tip)
    ok = codes == status.SUCCESS
    errors = rigs.errors(tips[ok], measured[ok])
    per_pattern = {}
    families = np.array([_family(p) for p in recording.patterns()])
    for f in dict.fromkeys(families):
        m = ok & (families == f)
        per_pattern[f] = {k: v for k, v in rigs.errors(tips[m], measured[m], errors["offset"]).items() if k != "offset"}
    return Prediction(tips, measured, recording.patterns(), codes, errors, per_pattern, seconds)


EQUAL_SERVOS = 0.1e-3
"""Two samples have equal servo values when every reading agrees within this [m]."""


def equal_servo_pairs(*recordings: Recording, tol: float = EQUAL_SERVOS) -> np.ndarray:
    """The pairs of samples, over the recordings taken together (indices into their
    concatenation, (k, 2), first < second), whose servo readings all agree within ``tol`` [m]:
    a model without memory gives both one tip, so their measured tip difference is friction's and
    hysteresis's."""
    servos = np.vstack([r.displacements for r in recordings])
    close = np.abs(servos[:, None] - servos[None]).max(axis=-1) < tol
    return np.argwhere(np.triu(close, 1))


def pair_score(predicted, measured, pairs) -> float:
    """How much of the measured tip difference within equal-servo ``pairs`` a model predicts:
    1 - sum |d_measured - d_predicted|^2 / sum |d_measured|^2 (1: all of it; 0: none, as for any
    model without memory, which predicts d = 0)."""
    predicted, measured = np.asarray(predicted), np.asarray(measured)
    d_m = measured[pairs[:, 1]] - measured[pairs[:, 0]]
    d_p = predicted[pairs[:, 1]] - predicted[pairs[:, 0]]
    return float(1 - np.sum((d_m - d_p) ** 2) / np.sum(d_m**2))


def _family(pattern: str) -> str:
    head, _, tail = pattern.rpartition("_dir")
    return head if head and tail.isdigit() else pattern


def synthesize_recording(
    rig: rigs.Rig, servos, *, noise: float = 0.0, seed: int = 0, labels=None, solver: SolverOptions = RIG_SOLVER
) -> Recording:
    """A recording made by the model: the rig's tips for servo readings (n, n_t) [m] along the
    sequence, plus Gaussian noise of standard deviation ``noise`` [m] on every coordinate (numpy's
    generator seeded with ``seed``); for checking a calibration against known values.

    Raises:
        ValueError: bad shapes or noise; ConvergenceError: a sample that did not solve.
    """
    servos = np.asarray(servos, float)
    if servos.ndim != 2 or servos.shape[1] != rig.robot.n_tendons:
        raise ValueError(f"servos has shape {servos.shape}: (samples, {rig.robot.n_tendons}) expected, one per tendon")
    if not (np.isfinite(noise) and noise >= 0):
        raise ValueError(f"noise = {noise!r} must be a finite standard deviation >= 0 [m]")
    tip, _, codes, _ = rigs.along(rig, jnp.asarray(servos), solver)
    status.check(status.first_failure(codes), throw=True, what="synthesize_recording", max_iter=solver.max_iter)
    tip = np.asarray(tip) + noise * np.random.default_rng(seed).standard_normal((len(servos), 3))
    n, k = servos.shape
    labels = np.full(n, "synthetic") if labels is None else np.asarray(labels, dtype=str)
    columns = (("label", "label", ""), *(("displacements", f"d{i + 1}_m", "m") for i in range(k)))
    columns += tuple(("tip", f"tip_{c}_m", "m") for c in "xyz")
    return Recording("synthetic", Path("synthetic"), labels, None, servos, None, None, tip, columns, np.arange(2, n + 2))
