"""Command-line tool ``tdct``: millimetres, grams and degrees at the edges, SI inside."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from .loads import STANDARD_GRAVITY, Actuation, TipLoad
from .mechanics import compliance, compliance_ellipsoid
from .robot import Robot
from .shooting import MAX_ITER, TOL, ConvergenceError, raise_if_failed, solve


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


def _parser() -> argparse.ArgumentParser:
    common = argparse.ArgumentParser(add_help=False)
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
    common.add_argument("--no-gravity", action="store_true", help="ignore the robot's own weight")
    common.add_argument("--robot", metavar="robot.toml", help="TOML file of Robot fields in SI units")
    common.add_argument("--steps", type=int, default=50, help="RK4 steps per segment (default 50)")
    common.add_argument("--json", action="store_true", help="print one JSON object instead of text")

    parser = argparse.ArgumentParser(prog="tdct", description="Statics of the TDCT soft robot (tdct_jax).")
    verbs = parser.add_subparsers(dest="verb", required=True)
    p = verbs.add_parser("solve", parents=[common], help="solve one static shape and print the tip pose")
    p.add_argument("--plot", metavar="shape.png", help="save a side view and a 3D view of the shape")
    p.add_argument("--csv", metavar="shape.csv", help="save the shape as s_mm,x_mm,y_mm,z_mm")
    c = verbs.add_parser("compliance", parents=[common], help="exact tip compliance matrix (eq. 41) and its ellipsoid")
    c.add_argument("--plot", metavar="ellipse.png", help="save the ellipsoid projected on its two largest axes")
    r = verbs.add_parser("reproduce", help="regenerate the paper's simulation figures and headline numbers")
    r.add_argument("--out", default="tdct-reproduce", metavar="DIR", help="output folder (default tdct-reproduce)")
    r.add_argument("--quick", action="store_true", help="coarse grids and no parameter fit (about a minute)")
    r.add_argument("--robot", metavar="robot.toml", help="TOML file of Robot fields in SI units")
    r.add_argument("--quiet", action="store_true", help="no progress output")
    return parser


def _robot(args) -> Robot:
    return Robot.from_toml(args.robot) if args.robot else Robot()


def _inputs(args):
    """Robot, actuation, load and solve options from the shared flags, in SI units."""
    robot = _robot(args)
    act = Actuation(tensions=args.tensions, insertion=args.insertion_mm * 1e-3)
    if args.tip_mass_g is not None:
        load = TipLoad(force=TipLoad.from_mass(args.tip_mass_g * 1e-3).force, moment=args.tip_moment)
    else:
        load = TipLoad(force=args.tip_force or (0.0, 0.0, 0.0), moment=args.tip_moment)
    options = dict(steps=args.steps, gravity=None if args.no_gravity else STANDARD_GRAVITY)
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
    sol = solve(robot, act, load, **options)
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
    raise_if_failed(sol, TOL, MAX_ITER)
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


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit code (0 ok, 1 not converged, 2 bad input)."""
    args = _parser().parse_args(argv)
    command = {"solve": _solve_command, "compliance": _compliance_command, "reproduce": _reproduce_command}[args.verb]
    try:
        return command(args)
    except ValueError as e:
        print(f"tdct: error: {e}", file=sys.stderr)
        return 2
    except ConvergenceError as e:
        print(f"tdct: error: {e}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
