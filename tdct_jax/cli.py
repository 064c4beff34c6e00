"""Command-line tool ``tdct``: millimetres, grams and degrees at the edges, SI inside."""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import os
import sys
from pathlib import Path

import jax
import numpy as np

from .loads import STANDARD_GRAVITY, Actuation, TipLoad
from .mechanics import compliance, compliance_ellipsoid
from .options import MAX_ITER, STEPS, SolverOptions
from .robot import SCALAR_FIELDS, Robot
from .solve import check_solution, solve
from .status import ConvergenceError

COMPILE_CACHE_ENV = "TDCT_COMPILE_CACHE"
"""Environment variable: a folder for the CLI's compilation cache, or 0 / off for none."""
SLURM_TASKS = "SLURM_STEP_NUM_TASKS"
"""Set by srun to the number of tasks (processes) of the job step: ``tdct sweep`` runs distributed above one."""
ON_CPU = ("solve", "compliance", "synth", "calibrate")
"""Verbs that run on the CPU even where an accelerator is the default: single solves and small
batches are faster there (each small operation on a GPU is a kernel launch)."""


def compile_cache_dir() -> Path | None:
    """The CLI's persistent XLA compilation cache: $TDCT_COMPILE_CACHE if set (0 or off: none),
    else $XDG_CACHE_HOME/tdct_jax/xla (XDG_CACHE_HOME defaults to ~/.cache)."""
    chosen = os.environ.get(COMPILE_CACHE_ENV)
    if chosen is not None:
        return None if chosen.strip().lower() in ("", "0", "off") else Path(chosen).expanduser()
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "tdct_jax" / "xla"


def enable_compile_cache(path) -> None:
    """Keeps every compiled XLA program under ``path`` (a folder) and reuses it in later processes,
    so a second ``tdct reproduce`` skips its compiles. Small and fast compiles are cached too."""
    jax.config.update("jax_compilation_cache_dir", str(path))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", -1)


def use_every_cpu_core() -> bool:
    """Splits the CPU into one JAX device per core, so that sweeps shard their chunks over every
    core (a JAX_NUM_CPU_DEVICES the user set wins). Possible only before JAX first computes
    anything; returns whether it took effect."""
    if "JAX_NUM_CPU_DEVICES" in os.environ:
        return False
    try:
        jax.config.update("jax_num_cpu_devices", os.cpu_count() or 1)
    except RuntimeError:  # JAX's backends already run (main called from a program that used JAX)
        return False
    return True


def _floats(n: int | None = None):
    def parse(text: str):
        try:
            values = tuple(float(x) for x in text.split(","))
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected comma-separated numbers, got {text!r}") from None
        if n is not None and len(values) != n:
            raise argparse.ArgumentTypeError(f"expected {n} comma-separated numbers, got {len(values)} in {text!r}")
        return values

    return parse


def _assignment(text: str):
    name, sep, value = text.partition("=")
    if not sep:
        raise argparse.ArgumentTypeError(f"expected FIELD=VALUE (a Robot field in SI units), got {text!r}")
    try:
        return name.strip(), float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{name.strip()}: expected a number, got {value!r}") from None


def _parser() -> argparse.ArgumentParser:
    cached = argparse.ArgumentParser(add_help=False)
    cached.add_argument(
        "--no-compile-cache",
        action="store_true",
        help=f"do not read or write the compilation cache (default: {COMPILE_CACHE_ENV} or ~/.cache/tdct_jax/xla)",
    )
    described = argparse.ArgumentParser(add_help=False, parents=[cached])
    described.add_argument("--robot", metavar="robot.toml", help="TOML file of Robot fields in SI units")
    described.add_argument(
        "--set",
        type=_assignment,
        action="append",
        default=[],
        metavar="FIELD=VALUE",
        help="override one Robot field, SI units (e.g. E_silicone=1.1e6); repeatable, applied after --robot",
    )
    described.add_argument("--steps", type=int, default=STEPS, help=f"RK4 steps per segment (default {STEPS})")
    described.add_argument(
        "--max-iter", type=int, default=MAX_ITER, help=f"most Newton steps per load stage of each solve (default {MAX_ITER})"
    )
    described.add_argument("--no-gravity", action="store_true", help="ignore the robot's own weight")

    common = argparse.ArgumentParser(add_help=False, parents=[described])
    common.add_argument(
        "--tensions", type=_floats(), default=(0.0, 0.0, 0.0, 0.0), help="tendon tensions in N, tendon 1 first (default 0,0,0,0)"
    )
    common.add_argument("--insertion-mm", type=float, default=0.0, help="Nitinol tube insertion depth in mm (default 0)")
    tip = common.add_mutually_exclusive_group()
    tip.add_argument("--tip-mass-g", type=float, help="tip mass in grams, hanging under standard gravity (-y)")
    tip.add_argument("--tip-force", type=_floats(3), metavar="FX,FY,FZ", help="tip force in N, world frame")
    common.add_argument(
        "--tip-moment", type=_floats(3), default=(0.0, 0.0, 0.0), metavar="MX,MY,MZ", help="tip moment in N m, world frame"
    )
    common.add_argument("--json", action="store_true", help="print one JSON object instead of text")

    parser = argparse.ArgumentParser(prog="tdct", description="Statics of the TDCT soft robot (tdct_jax).")
    verbs = parser.add_subparsers(dest="verb", required=True)
    p = verbs.add_parser("solve", parents=[common], help="solve one static shape and print the tip pose")
    p.add_argument("--plot", metavar="shape.png", help="save a side view and a 3D view of the shape")
    p.add_argument("--csv", metavar="shape.csv", help="save the shape as s_mm,x_mm,y_mm,z_mm")
    c = verbs.add_parser("compliance", parents=[common], help="exact tip compliance matrix (eq. 41) and its ellipsoid")
    c.add_argument("--plot", metavar="ellipse.png", help="save the ellipsoid projected on its two largest axes")
    r = verbs.add_parser("reproduce", parents=[cached], help="regenerate the paper's simulation figures and headline numbers")
    r.add_argument("--out", default="tdct-reproduce", metavar="DIR", help="output folder (default tdct-reproduce)")
    r.add_argument("--quick", action="store_true", help="coarse grids and no parameter fit (about a minute)")
    r.add_argument("--robot", metavar="robot.toml", help="TOML file of Robot fields in SI units")
    r.add_argument("--quiet", action="store_true", help="no progress output")
    y = verbs.add_parser("synth", parents=[described], help="write synthetic FBG-like shape files from the model")
    y.add_argument("--out", required=True, metavar="DIR", help="folder for the shape files (one CSV per experiment)")
    which = y.add_mutually_exclusive_group(required=True)
    which.add_argument(
        "--preset", choices=["paper"], help="paper: Sec. III.B's protocol, tendon 1 at 2, 4, 6, 8, 10 N, no tube, no load"
    )
    which.add_argument(
        "--tensions", type=_floats(), action="append", help="tendon tensions in N, tendon 1 first; repeat for more experiments"
    )
    y.add_argument("--insertion-mm", type=float, default=0.0, help="tube insertion depth in mm for every experiment (default 0)")
    y.add_argument("--tip-mass-g", type=float, default=0.0, help="tip mass in grams for every experiment (default 0)")
    y.add_argument("--noise-mm", type=float, default=0.1, help="Gaussian noise per coordinate in mm (default 0.1)")
    y.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    y.add_argument("--points", type=int, default=33, help="points per shape, base to tip (default 33)")
    k = verbs.add_parser("calibrate", parents=[described], help="fit Robot fields to measured shape files (Sec. III.B)")
    k.add_argument("files", nargs="+", metavar="FILE", help="shape files (CSV, see tdct_jax.data) or folders of them")
    k.add_argument("--params", default="E_silicone", help="comma-separated Robot fields to fit (default E_silicone)")
    k.add_argument("--max-steps", type=int, default=30, help="most Levenberg-Marquardt steps (default 30)")
    k.add_argument("--json", action="store_true", help="print one JSON object instead of the table")
    k.add_argument("--plot", metavar="fit.png", help="save model over measured shapes (side view and 3D)")
    k.add_argument("--quiet", action="store_true", help="no progress bar")
    w = verbs.add_parser(
        "sweep", parents=[cached], help="solve a grid or batch from a TOML spec into an .npz; a rerun resumes where it stopped"
    )
    w.add_argument("spec", metavar="SPEC.toml", help="what to solve, SI units (format: tdct_jax.spec)")
    w.add_argument(
        "--out",
        required=True,
        metavar="FILE.npz",
        help="the results (tdct.gather reads them); work in progress in <stem>.partial/",
    )
    w.add_argument("--overwrite", action="store_true", help="discard a partial folder left by a different sweep")
    w.add_argument("--quiet", action="store_true", help="no progress bar")
    w.add_argument(
        "--distributed",
        action="store_true",
        help=f"call jax.distributed.initialize() and write one part per process (automatic when {SLURM_TASKS} > 1, under srun)",
    )
    return parser


def _robot(args) -> Robot:
    robot = Robot.from_toml(args.robot) if args.robot else Robot()
    fields = dict(getattr(args, "set", []))
    unknown = sorted(set(fields) - set(SCALAR_FIELDS))
    if unknown:
        raise ValueError(f"--set: unknown Robot field(s) {unknown}; allowed: {list(SCALAR_FIELDS)}")
    return dataclasses.replace(robot, **fields)


def _gravity(args):
    return None if args.no_gravity else STANDARD_GRAVITY


def _solver(args) -> SolverOptions:
    return SolverOptions(steps=args.steps, max_iter=args.max_iter)


def _inputs(args):
    """Robot, actuation, load and solve options from the shared flags, in SI units."""
    robot = _robot(args)
    act = Actuation(tensions=args.tensions, insertion=args.insertion_mm * 1e-3)
    if args.tip_mass_g is not None:
        load = TipLoad(force=TipLoad.from_mass(args.tip_mass_g * 1e-3).force, moment=args.tip_moment)
    else:
        load = TipLoad(force=args.tip_force or (0.0, 0.0, 0.0), moment=args.tip_moment)
    options = dict(gravity=_gravity(args), solver=_solver(args))
    return robot, act, load, options


def _compliance_command(args) -> int:
    robot, act, load, options = _inputs(args)
    CM = np.asarray(compliance(robot, act, load, **options))
    e = compliance_ellipsoid(CM)
    mm = dict(
        compliance_mm_per_N=(CM * 1e3).tolist(),
        eigenvalues_mm_per_N=(np.asarray(e.eigenvalues) * 1e3).tolist(),
        eigenvectors=np.asarray(e.eigenvectors).tolist(),
        semi_axes_mm_per_N=(np.asarray(e.semi_axes) * 1e3).tolist(),
        axes=np.asarray(e.axes).tolist(),
    )
    if args.json:
        print(json.dumps(mm))
    else:
        with np.printoptions(precision=4, suppress=True):
            print(f"compliance matrix CM [mm/N] (world x, y, z):\n{CM * 1e3}")
            print(f"eigenvalues lambda_1..3 [mm/N]: {np.asarray(e.eigenvalues) * 1e3}")
            print(f"ellipsoid semi-axes [mm/N]:     {np.asarray(e.semi_axes) * 1e3}")
            print(f"ellipsoid axes (columns):\n{np.asarray(e.axes)}")
    if args.plot:
        from .plotting import plot_compliance_ellipses

        plot_compliance_ellipses({f"insertion {args.insertion_mm:g} mm": CM}, args.plot)
    return 0


def _solve_command(args) -> int:
    robot, act, load, options = _inputs(args)
    sol = solve(robot, act, load, **options, throw=False)
    tip_mm = np.asarray(sol.tip_position) * 1e3
    angle = float(np.degrees(sol.tip_angle))
    converged, res, iters = bool(sol.converged), float(sol.residual_norm), int(sol.iterations)
    if args.json:
        shape = {"s_mm": (np.asarray(sol.s) * 1e3).tolist(), "position_mm": (np.asarray(sol.position) * 1e3).tolist()}
        out = dict(
            tip_position_mm=tip_mm.tolist(),
            tip_angle_deg=angle,
            converged=converged,
            residual_norm=res,
            iterations=iters,
            shape=shape,
        )
        print(json.dumps(out))
    else:
        print(f"tip position [mm]: x = {tip_mm[0]:.3f}, y = {tip_mm[1]:.3f}, z = {tip_mm[2]:.3f}")
        print(f"tip angle [deg]:   {angle:.3f}")
        print(f"converged:         {'yes' if converged else 'NO'} (scaled residual {res:.2e}, {iters} Newton iterations)")
    if args.csv:
        table = np.column_stack([np.asarray(sol.s), np.asarray(sol.position)]) * 1e3
        np.savetxt(args.csv, table, delimiter=",", header="s_mm,x_mm,y_mm,z_mm", comments="", fmt="%.9g")
    if args.plot:
        from .plotting import plot_shape

        title = f"tensions {', '.join(f'{t:g}' for t in args.tensions)} N, insertion {args.insertion_mm:g} mm"
        plot_shape(sol, act.insertion, args.plot, title=title)
    check_solution(sol, options["solver"], True)
    return 0


def _reproduce_command(args) -> int:
    from .reproduce import reproduce

    robot = _robot(args)
    summary = reproduce(args.out, quick=args.quick, robot=robot, progress=not args.quiet)
    print((Path(args.out) / "summary.md").read_text())
    failed = [r for r in summary["headlines"] if "NOT converged" in r["note"]]
    if failed:
        print(f"tdct: error: {len(failed)} headline result(s) did not converge (see summary.md)", file=sys.stderr)
        return 1
    return 0


def _synth_command(args) -> int:
    from . import paper
    from .calibrate import synthesize
    from .data import write_experiment

    robot = _robot(args)
    if args.preset == "paper":
        acts = paper.calibration_conditions(robot)
    else:
        acts = [Actuation(t, args.insertion_mm * 1e-3) for t in args.tensions]
    experiments = synthesize(
        robot,
        acts,
        tip_masses=[args.tip_mass_g * 1e-3] * len(acts),
        n_points=args.points,
        noise=args.noise_mm * 1e-3,
        seed=args.seed,
        gravity=_gravity(args),
        solver=_solver(args),
    )
    for i, e in enumerate(experiments, start=1):
        print(write_experiment(Path(args.out) / f"{i:02d}_{e.name}.csv", e))
    return 0


def _calibrate_command(args) -> int:
    from .calibrate import calibrate
    from .data import read_experiments

    robot = _robot(args)
    experiments = read_experiments(args.files, robot)
    params = tuple(p.strip() for p in args.params.split(",") if p.strip())
    options = dict(gravity=_gravity(args), solver=_solver(args))
    fit = calibrate(robot, experiments, params, max_steps=args.max_steps, progress=not args.quiet, throw=False, **options)
    print(json.dumps(fit.to_dict()) if args.json else fit.summary())
    if args.plot:
        from .plotting import plot_calibration
        from .results import unit_of

        fitted = ", ".join(f"{p} = {fit.values[p]:.4g} {unit_of(p).replace('_per_', '/')}" for p in params)
        plot_calibration(fit.solutions, experiments, args.plot, title=f"calibrated: {fitted}")
    if not fit.converged:
        raise ConvergenceError(f"calibration did not converge: {fit.message}", fit.result)
    return 0


def _sweep_command(args) -> int:
    from .spec import read_spec
    from .sweep import sweep

    spec = read_spec(args.spec)
    if args.distributed or int(os.environ.get(SLURM_TASKS, "1")) > 1:
        jax.distributed.initialize()
    print(sweep(**spec, out=args.out, overwrite=args.overwrite, progress=not args.quiet))
    return 0


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit code (0 ok, 1 not converged, 2 bad input)."""
    args = _parser().parse_args(argv)
    command = {
        "solve": _solve_command,
        "compliance": _compliance_command,
        "reproduce": _reproduce_command,
        "synth": _synth_command,
        "calibrate": _calibrate_command,
        "sweep": _sweep_command,
    }[args.verb]
    use_every_cpu_core()
    cache = None if args.no_compile_cache else compile_cache_dir()
    if cache is not None:
        enable_compile_cache(cache)
    on_cpu = args.verb in ON_CPU and jax.default_backend() != "cpu"
    try:
        with jax.default_device(jax.local_devices(backend="cpu")[0]) if on_cpu else contextlib.nullcontext():
            return command(args)
    except ValueError as e:
        print(f"tdct: error: {e}", file=sys.stderr)
        return 2
    except ConvergenceError as e:
        print(f"tdct: error: {e}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
