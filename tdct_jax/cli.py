"""Command-line tool ``tdct``: millimetres, grams and degrees at the edges, SI inside."""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import difflib
import json
import math
import os
import re
import sys
import time
import warnings
from pathlib import Path
from typing import NamedTuple

import jax
import numpy as np

from . import fields, rod, status
from .checks import UnitWarning, check_output, interval, target_note
from .data import _error, _number
from .description import CalibrationWarning, Robot
from .dynamics import ALPHA, INTERVALS, default_solver, simulate
from .dynamics import check as check_dynamics
from .ik import MAX_STEPS as IK_MAX_STEPS
from .ik.starts import STARTS as IK_STARTS
from .inputs import STANDARD_GRAVITY, Actuation, Loads
from .mechanics import compliance, compliance_and_solution, compliance_ellipsoid
from .options import MAX_ITER, STEPS, SolverOptions
from .recording import _table
from .scene import read_scene
from .solve import check_solution, solve
from .status import ConvergenceError
from .version import __version__

COMPILE_CACHE_ENV = "TDCT_COMPILE_CACHE"
"""Environment variable: a folder for the CLI's compilation cache, or 0 / off for none."""
SLURM_TASKS = "SLURM_STEP_NUM_TASKS"
"""Set by srun to the number of tasks (processes) of the job step: ``tdct sweep`` runs distributed above one."""
ON_CPU = ("solve", "compliance", "synth", "calibrate", "ik", "simulate")
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


NUMBER_LIST = re.compile(r"^-(\d|\.\d)[\d.eE+\-:]*(,\s*-?(\d|\.\d)[\d.eE+\-:]*)*$")
"""A token that starts with '-' but is a (list of) number(s) (or S:F pairs), never a flag."""


def _negative_values_attached(argv: list[str]) -> list[str]:
    """``--tensions -5,0,0,0`` as ``--tensions=-5,0,0,0``: argparse would read the value as a flag."""
    out: list[str] = []
    for token in argv:
        if out and NUMBER_LIST.match(token) and out[-1].startswith("--") and "=" not in out[-1]:
            out[-1] = f"{out[-1]}={token}"
        else:
            out.append(token)
    return out


def _floats(n: int | None = None):
    def parse(text: str):
        try:
            values = tuple(float(x) for x in text.split(","))
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected comma-separated numbers, got {text!r}") from None
        if n is not None and len(values) != n:
            raise argparse.ArgumentTypeError(f"expected {n} comma-separated numbers, got {len(values)} in {text!r}")
        if not all(math.isfinite(v) for v in values):
            raise argparse.ArgumentTypeError(f"expected finite numbers, got {text!r}")
        return values

    return parse


def _finite(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
    return value


def _assignment(text: str):
    name, sep, value = text.partition("=")
    if not sep:
        raise argparse.ArgumentTypeError(f"expected FIELD=VALUE (a robot field in SI units), got {text!r}")
    try:
        return name.strip(), float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{name.strip()}: expected a number, got {value!r}") from None


def _displacements(text: str):
    """``2:1.5,5:-0.5`` as ((2, 1.5), (5, -0.5)): tendon numbers (from 1) and displacements [mm]."""
    pairs = []
    for item in text.split(","):
        number, sep, value = item.partition(":")
        try:
            pair = (int(number), float(value))
        except ValueError:
            pair = None
        if not sep or pair is None or not math.isfinite(pair[1]):
            raise argparse.ArgumentTypeError(
                f"expected TENDON:MM pairs, comma-separated (tendons numbered from 1, e.g. 1:2.5,4:-1), got {text!r}"
            )
        pairs.append(pair)
    return tuple(pairs)


def _point_load(text: str):
    """``300:0,-0.1,0`` as (300.0, (0.0, -0.1, 0.0)): arc length [mm] and world force [N]."""
    where, sep, force = text.partition(":")
    try:
        return _finite(where), _floats(3)(force)
    except argparse.ArgumentTypeError:
        raise argparse.ArgumentTypeError(f"expected S_MM:FX,FY,FZ (arc length in mm, force in N), got {text!r}") from None


def check_flag(flag: str, value, lo=0.0, hi=math.inf, unit="", *, lo_open=False) -> None:
    """A ValueError in the user's own terms (``--insertion-mm 200 is outside [0, 160] mm``) unless
    every number of a flag's value lies in [lo, hi]."""
    values = np.atleast_1d(np.asarray(value, dtype=float))
    bad = (values <= lo if lo_open else values < lo) | (values > hi)
    if np.any(bad):
        typed = ",".join(f"{v:g}" for v in values)
        which = f" (value {int(np.argmax(bad)) + 1}: {values[np.argmax(bad)]:g})" if values.size > 1 else ""
        raise ValueError(f"{flag} {typed}{which} is outside the allowed range {interval(lo, hi, lo_open)}{unit}")


def check_count(flag: str, value, n: int, what: str) -> None:
    if len(value) != n:
        raise ValueError(f"{flag} {','.join(f'{v:g}' for v in value)} has {len(value)} values: {what}")


LISTS_HELP = "Lists are comma-separated; negative values may be typed as they are (--tip-force -0.15,0,0)."
SCENE_HELP = (
    "obstacles the robot rests on or presses against, SI units (docs/contact.md): frictionless contact along the body "
    "and at the tip"
)

TIME_COLUMN = "t_s"
"""The input table's time column [s] (``tdct simulate``)."""
TIP_FORCE_COLUMNS = ("tip_force_x_N", "tip_force_y_N", "tip_force_z_N")
"""The input table's optional tip force columns [N], world frame."""
FRAMES = 60
"""Frames of ``tdct simulate --gif`` by default (at 20 frames a second: 3 s)."""
MAX_TIME_STEPS = 100_000
"""Most time steps ``tdct simulate`` takes in one run: beyond, a table in milliseconds read as
seconds (or --dt-ms typed in seconds) would run for hours and fill the memory."""


def _depth_flags(parser, held: str = "") -> None:
    """--insertion-mm (one tube) or --insertions-mm (each tube), read by ``_depths_typed``."""
    depth = parser.add_mutually_exclusive_group()
    depth.add_argument(
        "--insertion-mm", type=_finite, help=f"tube insertion depth in mm, for a robot with one tube{held} (default 0)"
    )
    depth.add_argument(
        "--insertions-mm",
        type=_floats(),
        metavar="D1,D2,...",
        help=f"insertion depth of each tube in mm, tube 1 first{held} (default all 0)",
    )


def _parser() -> argparse.ArgumentParser:
    cached = argparse.ArgumentParser(add_help=False)
    cached.add_argument(
        "--no-compile-cache",
        action="store_true",
        help=f"do not read or write the compilation cache (default: {COMPILE_CACHE_ENV} or ~/.cache/tdct_jax/xla)",
    )
    described = argparse.ArgumentParser(add_help=False, parents=[cached])
    described.add_argument(
        "--robot",
        metavar="robot.toml",
        help="robot file, SI units: the paper's robot with Table II values by name (E_silicone = 1.1e6), or any robot "
        "described by [[sections]] (docs/robot-file.md)",
    )
    described.add_argument(
        "--set",
        type=_assignment,
        action="append",
        default=[],
        metavar="FIELD=VALUE",
        help="override one robot field by its name, SI units but angles in degrees as in robot files "
        "(sections[*].E=1.1e6, tendons[0].offset=0.012, tendons[0].angle_deg=90, tubes[0].E=60e9, length=0.2; "
        "items count from 0: tendons[0] is tendon 1); repeatable, applied after --robot",
    )
    described.add_argument("--steps", type=int, default=STEPS, help=f"RK4 steps per segment (default {STEPS})")
    described.add_argument(
        "--max-iter", type=int, default=MAX_ITER, help=f"most Newton steps per load stage of each solve (default {MAX_ITER})"
    )
    described.add_argument("--no-gravity", action="store_true", help="ignore the robot's own weight")

    common = argparse.ArgumentParser(add_help=False, parents=[described])
    common.add_argument(
        "--tensions",
        type=_floats(),
        metavar="T1,T2,...",
        help="tendon tensions in N, one per tendon of the robot, tendon 1 first (default all 0); "
        "for a displacement-driven tendon, where the search for its tension starts",
    )
    common.add_argument(
        "--displacements-mm",
        type=_displacements,
        metavar="TENDON:MM,...",
        help="drive these tendons by displacement: the length pulled at the base in mm, tendons numbered from 1 "
        "(e.g. 1:2.5,4:-1); each must be less than the tendon's length from the base to its anchor; "
        "a tendon that would have to push goes slack",
    )
    _depth_flags(common)
    tip = common.add_mutually_exclusive_group()
    tip.add_argument("--tip-mass-g", type=_finite, help="tip mass in grams, hanging under standard gravity (-y)")
    tip.add_argument("--tip-force", type=_floats(3), metavar="FX,FY,FZ", help="tip force in N, world frame")
    common.add_argument(
        "--tip-moment", type=_floats(3), default=(0.0, 0.0, 0.0), metavar="MX,MY,MZ", help="tip moment in N m, world frame"
    )
    common.add_argument(
        "--point-load",
        type=_point_load,
        action="append",
        default=[],
        metavar="S_MM:FX,FY,FZ",
        help="a force in N, world frame, at arc length S_MM in mm from the base, in [0, L]; repeatable",
    )
    common.add_argument("--json", action="store_true", help="print one JSON object instead of text")

    parser = argparse.ArgumentParser(
        prog="tdct",
        description="Statics of the TDCT soft robot (tdct_jax). " + LISTS_HELP,
        epilog="Exit codes: 0 done, 1 not converged (the reason on stderr), 2 bad input, 3 internal error.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    verbs = parser.add_subparsers(dest="verb", required=True)
    p = verbs.add_parser("solve", parents=[common], help="solve one static shape and print the tip pose", epilog=LISTS_HELP)
    p.add_argument("--plot", metavar="shape.png", help="save a side view and a 3D view of the shape")
    p.add_argument("--csv", metavar="shape.csv", help="save the shape as s_mm,x_mm,y_mm,z_mm")
    p.add_argument("--scene", metavar="scene.toml", help=SCENE_HELP + ", the contacts printed and drawn")
    c = verbs.add_parser(
        "compliance", parents=[common], help="exact tip compliance matrix (eq. 41) and its ellipsoid", epilog=LISTS_HELP
    )
    c.add_argument("--plot", metavar="ellipse.png", help="save the ellipsoid projected on its two largest axes")
    c.add_argument(
        "--scene",
        metavar="scene.toml",
        help=SCENE_HELP + ": the compliance in contact (the touching candidates held on their obstacles), the contacts printed",
    )
    r = verbs.add_parser("reproduce", parents=[cached], help="regenerate the paper's simulation figures and headline numbers")
    r.add_argument("--out", default="tdct-reproduce", metavar="DIR", help="output folder (default tdct-reproduce)")
    r.add_argument(
        "--quick",
        action="store_true",
        help="coarse grids; no Sec. V.A as inverse kinematics, stiffness map or parameter fit (about 1.5 minutes)",
    )
    r.add_argument(
        "--robot", metavar="robot.toml", help="robot file (docs/robot-file.md), a robot with a tube; default: the paper's robot"
    )
    r.add_argument("--quiet", action="store_true", help="no progress output")
    y = verbs.add_parser(
        "synth", parents=[described], help="write synthetic FBG-like shape files from the model", epilog=LISTS_HELP
    )
    y.add_argument(
        "--out",
        required=True,
        metavar="DIR",
        help="folder for the shape files (one CSV per experiment); refused if it holds .csv files already "
        "(tdct calibrate DIR would fit them too), unless --overwrite",
    )
    y.add_argument(
        "--overwrite", action="store_true", help="delete the .csv files already in DIR (nothing else) before writing the new ones"
    )
    which = y.add_mutually_exclusive_group(required=True)
    which.add_argument(
        "--preset", choices=["paper"], help="paper: Sec. III.B's protocol, tendon 1 at 2, 4, 6, 8, 10 N, no tube, no load"
    )
    which.add_argument(
        "--tensions",
        type=_floats(),
        action="append",
        metavar="T1,T2,...",
        help="tendon tensions in N, tendon 1 first; repeat for more experiments",
    )
    y.add_argument(
        "--insertion-mm", type=_finite, default=0.0, help="insertion depth in mm of every tube, every experiment (default 0)"
    )
    y.add_argument("--tip-mass-g", type=_finite, default=0.0, help="tip mass in grams for every experiment (default 0)")
    y.add_argument("--noise-mm", type=_finite, default=0.1, help="Gaussian noise per coordinate in mm (default 0.1)")
    y.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    y.add_argument("--points", type=int, default=33, help="points per shape, base to tip (default 33)")
    i = verbs.add_parser(
        "ik",
        parents=[described],
        help="inverse kinematics: tensions and insertion that put the tip at a target (Secs. V.A, V.B)",
        epilog=LISTS_HELP + " Exit codes: 0 reached, 1 unreachable or failed (the nearest pose is printed), 2 bad input.",
    )
    i.add_argument("--target-mm", type=_floats(3), required=True, metavar="X,Y,Z", help="target tip position in mm, world frame")
    i.add_argument(
        "--axes",
        default="xyz",
        metavar="AXES",
        help="the target components that count, e.g. y for a tip height or yz for the z-y plane (default xyz)",
    )
    i.add_argument(
        "--tip-angle-deg",
        type=_finite,
        help="also reach this in-plane tip angle in degrees, in [-180, 180] (z-y plane, toward +y)",
    )
    i.add_argument("--insertion-mm", type=_finite, help="fix the tube insertion at this depth in mm (default: free)")
    i.add_argument("--tendons", type=_floats(), metavar="1,3", help="the free tendons, numbered from 1 (default all)")
    i.add_argument("--max-tension-n", type=_finite, default=10.0, help="largest tension of a free tendon in N (default 10)")
    i.add_argument("--tip-mass-g", type=_finite, default=0.0, help="tip mass in grams held while reaching (default 0)")
    i.add_argument(
        "--objective",
        choices=["stiffness", "tension"],
        help="among redundant solutions (more free inputs than target components), the stiffest or least tension",
    )
    i.add_argument(
        "--max-steps",
        type=int,
        default=IK_MAX_STEPS,
        help=f"most IK steps from each start (up to {IK_STARTS} starts are tried while the target is missed) and, with "
        f"--objective, most steps of the optimisation (default {IK_MAX_STEPS}); the steps printed count them all",
    )
    i.add_argument(
        "--direction", type=_floats(3), metavar="DX,DY,DZ", help="world direction for --objective stiffness (default: along -y)"
    )
    i.add_argument("--json", action="store_true", help="print one JSON object instead of text")
    i.add_argument("--plot", metavar="ik.png", help="save a side view and a 3D view of the shape with the target")
    k = verbs.add_parser(
        "calibrate",
        parents=[described],
        help="fit robot fields to measured shape files (Sec. III.B), or a robot on its rig to a recording (--dataset)",
    )
    k.add_argument("files", nargs="*", metavar="FILE", help="shape files (CSV, see tdct_jax.data) or folders of them")
    k.add_argument(
        "--dataset",
        metavar="dataset.toml",
        help="a recording's description (docs/recordings.md): fit its train file, predict its validation file; "
        "--robot (default: the dataset's robot file) gives the robot and its [rig] table",
    )
    k.add_argument(
        "--params",
        help="comma-separated fields to fit (default sections[*].E; with --dataset the servo scale, each segment's "
        "pretension and tendon stiffness, every tendon angle and the registration; names: docs/recordings.md)",
    )
    k.add_argument("--every", type=int, default=1, help="with --dataset: fit every Nth training sample (default 1: all)")
    k.add_argument(
        "--out",
        metavar="DIR",
        help="with --dataset: write fitted.toml, report.json and prediction.png into the folder DIR (made if missing)",
    )
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
        help="the results, an .npz (tdct.gather reads it); work in progress in <stem>.partial/",
    )
    w.add_argument(
        "--overwrite",
        action="store_true",
        help="discard a partial folder left by a different sweep, and recompute a finished FILE.npz "
        "(without it, the same sweep finished already computes nothing)",
    )
    w.add_argument("--quiet", action="store_true", help="no progress bar")
    w.add_argument(
        "--distributed",
        action="store_true",
        help=f"call jax.distributed.initialize() and write one part per process (automatic when {SLURM_TASKS} > 1, under srun)",
    )
    m = verbs.add_parser(
        "simulate",
        parents=[described],
        help="the robot in motion under tendon tensions or displacements and tip forces given along time (docs/dynamics.md)",
        epilog="The input table: a CSV with the time column t_s (seconds, from 0, increasing), one column per tendon, "
        "tension_1_N, tension_2_N, ... (newtons, tendons numbered from 1) or for a displacement-driven tendon "
        "displacement_1_mm, ... (the length pulled at the base), and optionally tip_force_x_N, tip_force_y_N, "
        "tip_force_z_N (world frame, a missing one 0) and insertion_1_mm, ... (every tube's depth, for tubes that "
        "move; else --insertion-mm); linear between its rows, the last row held after its time "
        "(docs/cli.md). --max-iter limits the Newton steps of each time step.",
    )
    m.add_argument("--inputs", required=True, metavar="inputs.csv", help="the input table (CSV, format below)")
    m.add_argument(
        "--dt-ms",
        type=_finite,
        required=True,
        help="time step in ms (e.g. 1); the simulation's times are 0, dt, 2 dt, ... up to --duration-s",
    )
    m.add_argument(
        "--duration-s",
        type=_finite,
        help="simulated time in s (default: the input table's last time); beyond the table its last row is held",
    )
    m.add_argument(
        "--start",
        choices=["static", "straight"],
        default="static",
        help="static: at rest in the static shape of the table's first row (default); straight: the straight, "
        "unstrained robot at rest",
    )
    m.add_argument(
        "--alpha",
        type=_finite,
        default=ALPHA,
        help=f"BDF-alpha parameter in [-0.5, 0] (default {ALPHA:g}): 0 damps the fastest modes most, -0.5 not at all "
        "(and lets the base force grow: use -0.3 or more)",
    )
    m.add_argument(
        "--intervals",
        type=int,
        help=f"shooting intervals of each time step (default: the most up to {INTERVALS} that divide the robot's RK4 "
        "steps); more where small steps or sudden inputs make a step fail",
    )
    _depth_flags(m, ", held in time (tubes that move: the input table's insertion_i_mm columns)")
    m.add_argument("--scene", metavar="scene.toml", help=SCENE_HELP + " (single shooting), the contact forces in the .npz")
    m.add_argument(
        "--out",
        metavar="DIR",
        help="write trajectory.csv (time, tip in mm, inputs, result code per step) and trajectory.npz (every "
        "trajectory array, SI units) into the folder DIR (made if missing)",
    )
    m.add_argument("--plot", metavar="tip.png", help="save the tip against time and its path (x-y and z-y, mm)")
    m.add_argument("--gif", metavar="robot.gif", help="save an animation of the robot's side view (z-y, mm)")
    m.add_argument("--frames", type=int, default=FRAMES, help=f"frames of the --gif, evenly spaced in time (default {FRAMES})")
    m.add_argument("--quiet", action="store_true", help="no progress output")
    return parser


OUTPUTS = {"plot": "--plot", "csv": "--csv", "gif": "--gif"}
"""File outputs by destination and flag, checked before any computation; folders (--out) are
checked by their verbs."""


def _check_output(dest: str, flag: str, path) -> None:
    """``check_output`` for a file flag; a figure's suffix must be a format matplotlib writes
    (or none: PNG)."""
    if dest == "gif":
        return check_output(flag, path, suffixes=(".gif",), kind="a GIF")
    if dest != "plot":
        return check_output(flag, path)
    from matplotlib.backend_bases import FigureCanvasBase

    formats = ("", *(f".{s}" for s in sorted(FigureCanvasBase.get_supported_filetypes())))
    check_output(flag, path, suffixes=formats, kind="an image format matplotlib writes")


def _robot(args) -> Robot:
    """The robot of --robot (default: the paper's, ``Robot.paper()``) with the --set fields
    replaced (fields.py names)."""
    robot = Robot.from_toml(args.robot) if args.robot else Robot.paper()
    try:
        return fields.replace(robot, dict(fields.typed(*a) for a in getattr(args, "set", [])))
    except ValueError as e:
        raise ValueError(f"--set: {e}") from None


def _gravity(args):
    return None if args.no_gravity else STANDARD_GRAVITY


def _solver(args) -> SolverOptions:
    check_flag("--steps", args.steps, 1)
    check_flag("--max-iter", args.max_iter, 1)
    return SolverOptions(steps=args.steps, max_iter=args.max_iter)


def _check_tensions(flag: str, tensions, robot: Robot) -> None:
    check_count(flag, tensions, robot.n_tendons, f"the robot has {robot.n_tendons} tendons, one tension each")
    check_flag(flag, tensions, 0.0, unit=" N")


def _inputs(args):
    """Robot, actuation, load and solve options from the shared flags, checked in the units typed."""
    robot = _robot(args)
    solver = _solver(args)
    n_t, length_mm = robot.n_tendons, 1e3 * float(robot.length)
    if args.tensions is not None and n_t == 0:
        raise ValueError(f"--tensions {','.join(f'{t:g}' for t in args.tensions)}: the robot has no tendons; leave it out")
    tensions = args.tensions if args.tensions is not None else (0.0,) * n_t
    _check_tensions("--tensions", tensions, robot)
    depths = _depths_typed(args, robot)
    if args.tip_mass_g is not None:
        check_flag("--tip-mass-g", args.tip_mass_g, 0.0, unit=" g")
        tip_force = Loads.from_mass(args.tip_mass_g * 1e-3).tip_force
    else:
        tip_force = args.tip_force or (0.0, 0.0, 0.0)
    options = dict(gravity=_gravity(args), solver=solver)
    pulled = args.displacements_mm or ()
    _check_displacements(pulled, robot)
    for s_mm, force in args.point_load:
        where = f"--point-load {s_mm:g}:{','.join(f'{f:g}' for f in force)}: arc length"
        check_flag(where, s_mm, 0.0, length_mm, " mm")
    act = Actuation(tensions, [d * 1e-3 for d in depths], [d * 1e-3 for _, d in pulled], [i - 1 for i, _ in pulled])
    point_s = [s * 1e-3 for s, _ in args.point_load]
    load = Loads(tip_force, args.tip_moment, point_s, [f for _, f in args.point_load] if point_s else None)
    return robot, act, load, options


def _depths_typed(args, robot: Robot) -> tuple:
    """The tube depths [mm] of --insertion-mm or --insertions-mm (default all 0), one per tube, checked."""
    n_tubes = robot.n_tubes
    if args.insertions_mm is not None:
        flag, depths = "--insertions-mm", args.insertions_mm
        check_count(flag, depths, n_tubes, f"the robot has {n_tubes} tubes, one depth each")
    else:
        flag, depths = "--insertion-mm", (0.0,) * n_tubes if args.insertion_mm is None else (args.insertion_mm,)
        if args.insertion_mm is not None and n_tubes != 1:
            raise ValueError(
                f"--insertion-mm {args.insertion_mm:g}: the robot has {n_tubes} tubes; give --insertions-mm, one depth each"
            )
    check_flag(flag, depths, 0.0, 1e3 * float(robot.length), " mm")
    return tuple(depths)


def _check_displacements(pulled, robot: Robot) -> None:
    """--displacements-mm: known tendons, each once, each less than its length from the base to its
    anchor in the straight robot (``rod.check_arguments`` checks the same in SI units)."""
    if not pulled:
        return
    typed = "--displacements-mm " + ",".join(f"{i}:{d:g}" for i, d in pulled)
    numbers = [i for i, _ in pulled]
    if robot.n_tendons == 0:
        raise ValueError(f"{typed}: the robot has no tendons")
    if not all(1 <= i <= robot.n_tendons for i in numbers) or len(set(numbers)) != len(numbers):
        raise ValueError(f"{typed}: tendon numbers, each once, 1 to {robot.n_tendons}")
    reach = 1e3 * np.asarray(rod.rest_lengths(robot))
    for i, d in pulled:
        if not d < reach[i - 1]:
            raise ValueError(
                f"{typed}: tendon {i}'s {d:g} mm is outside the allowed range {interval(-math.inf, reach[i - 1], True, True)} mm "
                "(less than its length from the base to its anchor in the straight robot)"
            )


def _conditions(args, tensions) -> str:
    """The inputs as typed, for figure titles, with the ``tensions`` [N] as solved (those of the
    displacement-driven tendons are outputs)."""
    parts = [f"tensions {', '.join(f'{t:.4g}' for t in np.asarray(tensions))} N"] if np.size(tensions) else []
    parts += [f"tendon {i} pulled {d:g} mm" for i, d in args.displacements_mm or ()]
    depths = args.insertions_mm or (() if args.insertion_mm is None else (args.insertion_mm,))
    if depths:
        parts.append(f"insertion {', '.join(f'{d:g}' for d in depths)} mm")
    if args.tip_mass_g is not None:
        parts.append(f"tip mass {args.tip_mass_g:g} g")
    if args.tip_force is not None:
        parts.append(f"tip force ({', '.join(f'{f:g}' for f in args.tip_force)}) N")
    if args.point_load:
        parts.append(f"{len(args.point_load)} point load(s)")
    if getattr(args, "scene", None):
        parts.append(f"scene {Path(args.scene).name}")
    return ", ".join(parts) or "no load"


def _scene(args, robot: Robot):
    """The obstacles of --scene (None without), checked against the robot's base."""
    if not args.scene:
        return None
    scene = read_scene(args.scene)
    try:
        scene.check_base(float(robot.sections[0].outer_diameter) / 2)
    except ValueError as e:
        raise ValueError(f"scene file {args.scene}: {e}") from None
    return scene


def _compliance_command(args) -> int:
    robot, act, load, options = _inputs(args)
    scene = _scene(args, robot)
    C, sol = compliance_and_solution(robot, act, load, **options, scene=scene)
    CM = np.asarray(C)[:3, :3]
    e = compliance_ellipsoid(CM)
    mm = dict(
        compliance_mm_per_N=(CM * 1e3).tolist(),
        eigenvalues_mm_per_N=(np.asarray(e.eigenvalues) * 1e3).tolist(),
        eigenvectors=np.asarray(e.eigenvectors).tolist(),
        semi_axes_mm_per_N=(np.asarray(e.semi_axes) * 1e3).tolist(),
        axes=np.asarray(e.axes).tolist(),
    )
    if args.json:
        print(json.dumps(mm | ({} if scene is None else _contacts(sol, scene))))
    else:
        held = "" if scene is None else ", in contact (the touching candidates held on their obstacles)"
        with np.printoptions(precision=4, suppress=True):
            print(f"compliance matrix CM [mm/N] (world x, y, z){held}:\n{CM * 1e3}")
            print(f"eigenvalues lambda_1..3 [mm/N]: {np.asarray(e.eigenvalues) * 1e3}")
            print(f"ellipsoid semi-axes [mm/N]:     {np.asarray(e.semi_axes) * 1e3}")
            print(f"ellipsoid axes (columns):\n{np.asarray(e.axes)}")
        if scene is not None:
            _print_contacts(_contacts(sol, scene))
    if args.plot:
        from .plotting import plot_compliance_ellipses

        plot_compliance_ellipses({"tip compliance": CM}, args.plot, title=_conditions(args, sol.tensions))
    return 0


def _solve_command(args) -> int:
    robot, act, load, options = _inputs(args)
    scene = _scene(args, robot)
    sol = solve(robot, act, load, **options, scene=scene, throw=False)
    for note in sol.notes(robot):  # a converged shape that is not physical
        print(f"tdct: note: {note}", file=sys.stderr)
    tip_mm = np.asarray(sol.tip_position) * 1e3
    angle = float(np.degrees(sol.tip_angle))
    converged, res, iters = bool(sol.converged), float(sol.residual_norm), int(sol.iterations)
    tendons = dict(
        tensions_N=np.asarray(sol.tensions).tolist(),
        displacements_mm=(np.asarray(sol.displacements) * 1e3).tolist(),
        slack=np.asarray(sol.slack).tolist(),
    )
    if args.json:
        i = sol.distinct()
        shape = {"s_mm": (np.asarray(sol.s)[i] * 1e3).tolist(), "position_mm": (np.asarray(sol.position)[i] * 1e3).tolist()}
        out = dict(
            tip_position_mm=tip_mm.tolist(),
            tip_angle_deg=angle,
            converged=converged,
            residual_norm=res,
            iterations=iters,
            **tendons,
            **({} if scene is None else _contacts(sol, scene)),
            shape=shape,
        )
        print(json.dumps(out))
    else:
        print(f"tip position [mm]: x = {tip_mm[0]:.3f}, y = {tip_mm[1]:.3f}, z = {tip_mm[2]:.3f}")
        print(f"tip angle [deg]:   {angle:.3f}")
        print(f"converged:         {'yes' if converged else 'NO'} (scaled residual {res:.2e}, {iters} Newton iterations)")
        if tendons:
            slack = [str(i + 1) for i, s in enumerate(tendons["slack"]) if s]
            print(f"tensions [N]:      {', '.join(f'{t:.4f}' for t in tendons['tensions_N'])}")
            print(f"displacements [mm]: {', '.join(f'{d:.4f}' for d in tendons['displacements_mm'])}")
            print(f"slack tendons:     {', '.join(slack) or 'none'}")
        if scene is not None:
            _print_contacts(_contacts(sol, scene))
    if args.csv:
        i = sol.distinct()
        table = np.column_stack([np.asarray(sol.s)[i], np.asarray(sol.position)[i]]) * 1e3
        np.savetxt(args.csv, table, delimiter=",", header="s_mm,x_mm,y_mm,z_mm", comments="", fmt="%.9g")
    if args.plot:
        from .plotting import plot_robot

        plot_robot(sol, robot, act, load.with_scene(scene), args.plot, title=_conditions(args, sol.tensions))
    check_solution(sol, options["solver"], True)
    return 0


def _contacts(sol, scene) -> dict:
    """The touching candidates (arc length and centreline point in mm, the obstacle's normal, the
    normal force in N, the obstacle's name), candidate by candidate from the base, and the wrench
    the robot exerts on each obstacle (force in N, moment about the base in N m)."""
    c = sol.contact
    touching = [
        dict(
            obstacle=scene.names[o],
            s_mm=1e3 * float(c.s[j]),
            position_mm=(1e3 * np.asarray(c.position[j])).tolist(),
            normal=np.asarray(c.normal[j, o]).tolist(),
            force_N=float(c.force[j, o]),
        )
        for j, o in zip(*np.nonzero(np.asarray(c.active)), strict=True)
    ]
    wrench = np.asarray(c.wrench)
    on = [dict(obstacle=n, force_N=w[:3].tolist(), moment_N_m=w[3:].tolist()) for n, w in zip(scene.names, wrench, strict=True)]
    return dict(contacts=touching, obstacles=on)


def _print_contacts(contacts: dict) -> None:
    """The text output's lines for ``_contacts``: one per touching candidate, one per obstacle."""

    def mm(x):
        return ", ".join(f"{v:.3f}" for v in x)

    lines = [
        f"{c['obstacle']} at s = {c['s_mm']:.1f} mm, ({mm(c['position_mm'])}) mm: {c['force_N']:.4f} N"
        for c in contacts["contacts"]
    ]
    print(f"contacts:          {(chr(10) + ' ' * 19).join(lines) or 'none'}")
    for o in contacts["obstacles"]:
        force, moment = ", ".join(f"{f:.4f}" for f in o["force_N"]), ", ".join(f"{m:.5f}" for m in o["moment_N_m"])
        print(f"{'on ' + o['obstacle'] + ':':<19}force ({force}) N, moment about the base ({moment}) N m")


def _reproduce_command(args) -> int:
    from .reproduce import reproduce

    check_output("--out", args.out, folder=True)
    robot = _robot(args)
    summary = reproduce(args.out, quick=args.quick, robot=robot, progress=not args.quiet)
    print((Path(args.out) / "summary.md").read_text())
    failed = [r for r in summary["headlines"] if "NOT converged" in r["note"]]
    if failed:
        print(f"tdct: {len(failed)} headline result(s) did not converge (see summary.md)", file=sys.stderr)
        return 1
    return 0


def _synth_command(args) -> int:
    from . import paper
    from .calibrate import synthesize
    from .data import write_experiment

    check_output("--out", args.out, folder=True)
    earlier = sorted(Path(args.out).glob("*.csv")) if Path(args.out).is_dir() else []
    if earlier and not args.overwrite:
        raise ValueError(
            f"--out {args.out}: the folder holds {len(earlier)} .csv file(s) already ({earlier[0].name}, ...), which "
            "tdct calibrate would fit together with the new ones: give an empty or new folder, or --overwrite to delete them"
        )
    robot = _robot(args)
    solver = _solver(args)
    check_flag("--insertion-mm", args.insertion_mm, 0.0, 1e3 * float(robot.length), " mm")
    if args.insertion_mm and not robot.n_tubes:
        raise ValueError(f"--insertion-mm {args.insertion_mm:g}: the robot has no tubes; leave it out")
    check_flag("--tip-mass-g", args.tip_mass_g, 0.0, unit=" g")
    check_flag("--noise-mm", args.noise_mm, 0.0, unit=" mm")
    check_flag("--points", args.points, 2)
    if args.preset == "paper":
        acts = paper.calibration_conditions(robot)
    else:
        for t in args.tensions:
            _check_tensions("--tensions", t, robot)
        acts = [Actuation(t, (args.insertion_mm * 1e-3,) * robot.n_tubes) for t in args.tensions]
    experiments = synthesize(
        robot,
        acts,
        tip_masses=[args.tip_mass_g * 1e-3] * len(acts),
        n_points=args.points,
        noise=args.noise_mm * 1e-3,
        seed=args.seed,
        gravity=_gravity(args),
        solver=solver,
    )
    for f in earlier:  # only once the new shapes are computed
        f.unlink()
    for i, e in enumerate(experiments, start=1):
        print(write_experiment(Path(args.out) / f"{i:02d}_{e.name}.csv", e))
    return 0


def _calibrate_command(args) -> int:
    from .calibrate import calibrate
    from .data import read_experiments

    check_flag("--max-steps", args.max_steps, 1)
    if args.dataset:
        return _calibrate_rig_command(args)
    if not args.files or args.out or args.every != 1:
        raise ValueError("tdct calibrate takes shape files (FILE ...), or --dataset with --out and --every")
    robot = _robot(args)
    solver = _solver(args)
    params = _names(args.params or "sections[*].E")
    for p in params:  # before any file is read
        try:
            fields.check(robot, p)
        except ValueError as e:
            raise ValueError(f"--params: {e}") from None
    experiments = read_experiments(args.files, robot)
    options = dict(gravity=_gravity(args), solver=solver)
    fit = calibrate(robot, experiments, params, max_steps=args.max_steps, progress=not args.quiet, throw=False, **options)
    print(json.dumps(fit.to_dict()) if args.json else fit.summary())
    if args.plot:
        from .plotting import plot_calibration
        from .results import unit_of

        fitted = ", ".join(f"{p} = {fit.values[p]:.4g} {unit_of(p).replace('_per_', '/')}" for p in params)
        plot_calibration(fit.solutions, experiments, args.plot, title=f"calibrated: {fitted}")
    if not fit.converged:
        advice = f"hit --max-steps {args.max_steps}; raise it, or start nearer the optimum (--set)"
        message = advice if fit.result == status.OUTER_LIMIT else fit.message
        raise ConvergenceError(f"calibration did not converge: {message}", fit.result)
    return 0


def _names(text: str) -> tuple:
    return tuple(p.strip() for p in text.split(",") if p.strip())


def _calibrate_rig_command(args) -> int:
    """``tdct calibrate --dataset``: the rig fitted to the train file, the validation file predicted."""
    from .calibrate_rig import RIG_SOLVER, fit_recording, predict
    from .plotting import plot_prediction
    from .recording import read_dataset
    from .rig import Rig

    if args.files:
        raise ValueError("tdct calibrate --dataset takes no shape files")
    check_flag("--every", args.every, 1)
    if args.out:
        check_output("--out", args.out, folder=True)
    data = read_dataset(args.dataset)
    robot_file = args.robot or data.robot
    if robot_file is None:
        raise ValueError(f"{data.description}: names no robot file; give one with --robot")
    rig = Rig.from_toml(robot_file)
    solver = dataclasses.replace(RIG_SOLVER, max_iter=args.max_iter)
    params = _names(args.params) if args.params else None
    out = Path(args.out) if args.out else None
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
    train = data.train.subset(slice(None, None, args.every))
    fit = fit_recording(
        rig, train, params, pulls=data.pulls, max_steps=args.max_steps, solver=solver, progress=not args.quiet, throw=False
    )
    report = {"dataset": str(data.description), "robot": str(robot_file), "train_samples": len(train), "fit": fit.to_dict()}
    prediction = None
    if data.validation is not None:
        prediction = predict(fit.rig, data.validation, solver=solver)
        report["validation"] = prediction.to_dict()
    if out is not None:
        (out / "fitted.toml").write_text(fit.rig.to_toml())
        (out / "report.json").write_text(json.dumps(report, indent=1))
        if prediction is not None:
            plot_prediction(prediction, fit, out / "prediction.png", title=f"{data.validation.name} predicted from {train.name}")
    if args.json:
        print(json.dumps(report))
    else:
        print(fit.summary())
        if prediction is not None:
            e = prediction.errors
            print(
                f"\nvalidation {data.validation.name} ({e['n']} samples), mean offset removed: RMSE {1e3 * e['rmse']:.2f} mm, "
                f"median {1e3 * e['median']:.2f} mm, 95th percentile {1e3 * e['p95']:.2f} mm; "
                f"{1e3 * prediction.seconds_per_pose:.1f} ms per pose"
            )
    if not fit.converged:
        raise ConvergenceError(f"calibration did not converge: {fit.message}; its best values are kept", fit.result)
    if prediction is not None and np.any(prediction.codes):
        raise ConvergenceError(f"{int(np.count_nonzero(prediction.codes))} validation samples did not solve", 1)
    return 0


def _depths_mm(act) -> dict:
    """The tube depths of an actuation in mm, for output: ``insertions_mm``, one per tube, and for
    a robot with one tube its depth as ``insertion_mm`` too."""
    depths = (1e3 * np.asarray(act.insertions)).tolist()
    return dict(insertions_mm=depths) | (dict(insertion_mm=depths[0]) if len(depths) == 1 else {})


def _ik_command(args) -> int:
    from . import ik

    robot = _robot(args)
    solver = _solver(args)
    length_mm = 1e3 * float(robot.length)
    check_flag("--max-tension-n", args.max_tension_n, 0.0, unit=" N")
    check_flag("--tip-mass-g", args.tip_mass_g, 0.0, unit=" g")
    if args.insertion_mm is not None:
        check_flag("--insertion-mm", args.insertion_mm, 0.0, length_mm, " mm")
    tendons = None
    if args.tendons is not None:
        check_flag("--tendons", args.tendons, 1, robot.n_tendons)
        if any(t != int(t) for t in args.tendons) or len(set(args.tendons)) != len(args.tendons):
            raise ValueError(
                f"--tendons {','.join(f'{t:g}' for t in args.tendons)}: tendon numbers, each once, 1 to {robot.n_tendons}"
            )
        tendons = tuple(int(t) for t in args.tendons)
    if args.direction is not None and not any(args.direction):
        raise ValueError("--direction 0,0,0: the stiffness direction must be a nonzero vector")
    if args.direction is not None and args.objective != "stiffness":
        raise ValueError("--direction goes with --objective stiffness")
    direction = args.direction or (0.0, -1.0, 0.0)
    if args.tip_angle_deg is not None:
        check_flag("--tip-angle-deg", args.tip_angle_deg, -180.0, 180.0, " deg")
    check_flag("--max-steps", args.max_steps, 1)
    if not args.axes or not set(args.axes) <= set(ik.AXES) or len(set(args.axes)) != len(args.axes):
        raise ValueError(f"--axes {args.axes}: the target components that count, each once, from x, y, z (e.g. y, yz)")
    tip_angle = None if args.tip_angle_deg is None else np.radians(args.tip_angle_deg)
    target = ik.Target(np.asarray(args.target_mm) * 1e-3, tip_angle=tip_angle, axes=args.axes)
    if args.axes == "xyz":
        note = target_note(
            f"--target-mm {','.join(f'{x:g}' for x in args.target_mm)}", target.position, float(robot.length), True
        )
        if note:
            warnings.warn(note, UnitWarning, stacklevel=1)
    n_tubes = robot.n_tubes
    free = (robot.n_tendons if tendons is None else len(tendons)) + n_tubes * (args.insertion_mm is None)
    if args.objective is not None and free <= target.size:
        tubes = "" if not n_tubes else " and the tube" if n_tubes == 1 else f" and the {n_tubes} tubes"
        fixed = f"; --insertion-mm {args.insertion_mm:g} fixes the tube" if args.insertion_mm is not None else tubes
        raise ValueError(
            f"--objective {args.objective}: nothing to choose: {free} free input(s) (tendons "
            f"{','.join(map(str, tendons or range(1, robot.n_tendons + 1)))}{fixed}) for {target.size} target "
            f"component(s) ({ik.describe_task(target)}); an objective needs more free inputs than target components: "
            "give more --tendons, leave out --insertion-mm, or fewer --axes"
        )
    if args.insertion_mm is not None and n_tubes == 0:
        raise ValueError(f"--insertion-mm {args.insertion_mm:g}: the robot has no tubes; leave it out")
    load = Loads.from_mass(args.tip_mass_g * 1e-3)
    result = ik.inverse_kinematics(
        robot,
        target,
        load=load,
        tendons=tendons,
        insertion=None if args.insertion_mm is None else args.insertion_mm * 1e-3,
        bounds=ik.Bounds(tension=(0.0, args.max_tension_n)),
        objective=ik.Stiffness(direction) if args.objective == "stiffness" else args.objective,
        ik=ik.IKOptions(max_steps=args.max_steps),
        gravity=_gravity(args),
        solver=solver,
        throw=False,
    )
    code = int(result.result)
    limited = "each start tried" + (" and the optimisation" if args.objective else "")
    out = dict(
        tensions_N=np.asarray(result.actuation.tensions).tolist(),
        **_depths_mm(result.actuation),
        tip_position_mm=(np.asarray(result.tip_position) * 1e3).tolist(),
        tip_angle_deg=float(np.degrees(result.tip_angle)),
        position_error_mm=1e3 * float(result.position_error),
        status=status.NAMES[code],
    )
    if tip_angle is not None:
        out["orientation_error_deg"] = float(np.degrees(result.orientation_error))
    if args.objective is not None:
        d = np.asarray(direction) / np.linalg.norm(direction)
        CM = np.asarray(
            compliance(
                robot,
                result.actuation,
                load,
                **dict(gravity=_gravity(args), solver=solver),
                throw=False,
            )
        )
        out["compliance_along_direction_mm_per_N"] = 1e3 * float(d @ CM @ d)
    if args.json:
        print(json.dumps(out))
    else:
        steps = f"{int(result.iterations)} IK steps in all; --max-steps {args.max_steps} limits the steps from {limited}"
        print(f"status:            {out['status']} ({steps})")
        print(f"tensions [N]:      {', '.join(f'{t:.4f}' for t in out['tensions_N'])}")
        if "insertion_mm" in out:
            print(f"insertion [mm]:    {out['insertion_mm']:.3f}")
        elif out["insertions_mm"]:
            print(f"insertions [mm]:   {', '.join(f'{d:.3f}' for d in out['insertions_mm'])}")
        tip = out["tip_position_mm"]
        print(
            f"tip position [mm]: x = {tip[0]:.4f}, y = {tip[1]:.4f}, z = {tip[2]:.4f} ({out['position_error_mm']:.2e} mm from the target)"
        )
        print(f"tip angle [deg]:   {out['tip_angle_deg']:.3f}")
        if "compliance_along_direction_mm_per_N" in out:
            print(f"compliance along the direction [mm/N]: {out['compliance_along_direction_mm_per_N']:.3f}")
    if args.plot:
        from .plotting import plot_robot

        title = f"IK to ({', '.join(f'{x:g}' for x in args.target_mm)}) mm: {out['status']}"
        plot_robot(result.solution, robot, result.actuation, load, args.plot, title=title, target=target.position)
    if code == status.SUCCESS:
        return 0
    if code == status.UNREACHABLE:  # an answer, not a failure: the nearest pose, printed
        nearest = "no inputs within the bounds put the tip on the target; the nearest pose found is printed"
        print(f"tdct: {status.message(code, unreachable=nearest)}", file=sys.stderr)
        return 1
    if code == status.OUTER_LIMIT:
        advice = (
            f"the step limit --max-steps {args.max_steps} (on the steps from {limited}) was reached before the "
            f"tolerance was met; raise --max-steps (e.g. --max-steps {2 * args.max_steps})"
        )
    else:
        advice = status.message(code, cli=True, what="the inverse kinematics", max_steps=args.max_steps)
    raise ConvergenceError(f"the inverse kinematics did not converge: {advice}", code)


def _sweep_command(args) -> int:
    from .spec import read_spec
    from .sweep import OUT_KIND, OUT_SUFFIXES, sweep

    check_output("--out", args.out, suffixes=OUT_SUFFIXES, kind=OUT_KIND)
    spec = read_spec(args.spec)
    if args.distributed or int(os.environ.get(SLURM_TASKS, "1")) > 1:
        jax.distributed.initialize()
    print(sweep(**spec, out=args.out, overwrite=args.overwrite, progress=not args.quiet))
    return 0


class InputTable(NamedTuple):
    """``tdct simulate``'s input table in SI units: its times [s] (k,), from 0 and increasing, the
    tendon tensions [N] (k, n_t) (0 for a displacement-driven tendon), the displacement-driven
    tendons' displacements [m] (k, n_d), those tendons (indices from 0), the world-frame tip
    force [N] (k, 3) and the tube depths [m] (k, n_tubes) of each row (None: not in the table)."""

    t: np.ndarray
    tensions: np.ndarray
    displacements: np.ndarray
    driven: tuple
    tip_force: np.ndarray
    insertions: np.ndarray | None = None

    def at(self, times) -> tuple[np.ndarray, ...]:
        """(tensions, displacements, tip force, tube depths or None) at ``times`` [s], linear
        between rows, the last row held after it."""

        def columns(x):
            return np.array([np.interp(times, self.t, c) for c in x.T]).T.reshape(len(times), x.shape[1])

        depths = None if self.insertions is None else columns(self.insertions)
        return columns(self.tensions), columns(self.displacements), columns(self.tip_force), depths


def read_input_table(path, n_tendons: int, n_tubes: int = 0) -> InputTable:
    """Reads ``tdct simulate``'s input table (docs/cli.md): a CSV whose first line names its columns,
    ``t_s``, for each tendon i either ``tension_{i}_N`` or ``displacement_{i}_mm`` (the length
    pulled at the base), optionally ``tip_force_{x,y,z}_N`` (a missing one 0) and, for tubes that
    move, ``insertion_{i}_mm`` for every tube i; blank lines and lines starting with '#' are
    skipped.

    Raises:
        ValueError: ``path:line: ...`` naming the column, the value and what is allowed: what
            ``recording._table`` refuses (an unreadable file, rows of another field count, no
            rows), a missing time column, a first time other than 0, times that do not
            increase, unknown or missing columns (one tension or displacement column per
            tendon, not both; an insertion column for every tube or none), a value that is not a
            finite number, a negative tension, a depth outside [0, L] (``simulate`` checks it).
    """
    path = Path(path)
    table = _table(path, "input table")
    header, names, rows = table.line, table.names, table.rows
    tensions = [f"tension_{i}_N" for i in range(1, n_tendons + 1)]
    pulls = [f"displacement_{i}_mm" for i in range(1, n_tendons + 1)]
    depths = [f"insertion_{i}_mm" for i in range(1, n_tubes + 1)]
    robot = f"the robot has {n_tendons} tendon{'s' * (n_tendons != 1)}"
    allowed = [TIME_COLUMN, *tensions, *pulls, *TIP_FORCE_COLUMNS, *depths]
    said = ", ".join(
        [TIME_COLUMN, *tensions[:1], *(["...", tensions[-1]] if n_tendons > 2 else tensions[1:]), *TIP_FORCE_COLUMNS]
    )
    said += "; displacement_i_mm in place of tension_i_N for a tendon driven by displacement"
    said += "; insertion_i_mm for every tube, to move the tubes" if n_tubes else ""
    for name in names:
        if name in allowed:
            continue
        numbered = re.fullmatch(r"(tension|displacement|insertion)_(\d+)_(N|mm)", name)
        if numbered:
            which = {"tension": tensions, "displacement": pulls, "insertion": depths}[numbered[1]]
            has = robot if numbered[1] != "insertion" else f"the robot has {n_tubes} tube{'s' * (n_tubes != 1)}"
            raise _error(path, header, f"column {name!r}: {has}, so the {numbered[1]} columns are {', '.join(which) or 'none'}")
        close = [TIME_COLUMN] if re.fullmatch(r"t(ime)?(_\w*)?", name, re.I) else difflib.get_close_matches(name, allowed, n=1)
        guess = f" (did you mean {close[0]!r}?)" if close else ""
        hint = "; separate the columns by commas" if ";" in name or "\t" in name else ""
        raise _error(path, header, f"unknown column {name!r}{guess}; the columns are {said}{hint}")
    if TIME_COLUMN not in names:
        raise _error(path, header, f"no time column {TIME_COLUMN!r} (the times in seconds, from 0); columns present: {names}")
    both = [i for i, (a, b) in enumerate(zip(tensions, pulls, strict=True)) if a in names and b in names]
    if both:
        i = both[0]
        raise _error(
            path,
            header,
            f"columns {tensions[i]} and {pulls[i]}: drive tendon {i + 1} by its tension or its displacement, not both",
        )
    missing = [c for c, d in zip(tensions, pulls, strict=True) if c not in names and d not in names]
    if missing:
        raise _error(
            path,
            header,
            f"no column(s) {', '.join(missing)}: {robot}, one tension column each ({tensions[0]} to {tensions[-1]}, in N) "
            "or, for a displacement-driven tendon, displacement_i_mm",
        )
    given = [c for c in depths if c in names]
    if given and len(given) < n_tubes:
        raise _error(path, header, f"columns {', '.join(given)}: give every tube's depth ({', '.join(depths)}, in mm) or none")
    index = {name: names.index(name) for name in names}
    values = {name: np.array([_number(path, line, name, f[index[name]]) for line, f in rows]) for name in names}
    lines = [line for line, _ in rows]
    t = values[TIME_COLUMN]
    if t[0] != 0:
        raise _error(path, lines[0], f"{TIME_COLUMN} = {t[0]:g} s: the table starts at t = 0 (the start of the simulation)")
    back = np.flatnonzero(np.diff(t) <= 0)
    if back.size:
        k = back[0] + 1
        raise _error(
            path, lines[k], f"{TIME_COLUMN} = {t[k]:g} s is not after the row before's {t[k - 1]:g} s; the times must increase"
        )
    for name in (c for c in tensions if c in names):
        negative = np.flatnonzero(values[name] < 0)
        if negative.size:
            k = negative[0]
            raise _error(path, lines[k], f"{name} = {values[name][k]:g} N is outside the allowed range [0, inf) N")
    zeros = np.zeros(len(rows))
    driven = tuple(i for i, c in enumerate(pulls) if c in names)
    return InputTable(
        t,
        np.stack([values.get(c, zeros) for c in tensions], axis=-1).reshape(len(rows), n_tendons),
        1e-3 * np.array([values[pulls[i]] for i in driven]).T.reshape(len(rows), len(driven)),
        driven,
        np.stack([values.get(c, zeros) for c in TIP_FORCE_COLUMNS], axis=-1),
        1e-3 * np.stack([values[c] for c in depths], axis=-1) if given else None,
    )


def _simulate_command(args) -> int:
    from tqdm import tqdm

    check_flag("--dt-ms", args.dt_ms, 0.0, unit=" ms", lo_open=True)
    if args.duration_s is not None:
        check_flag("--duration-s", args.duration_s, 0.0, unit=" s", lo_open=True)
    check_flag("--alpha", args.alpha, -0.5, 0.0)
    check_flag("--frames", args.frames, 2)
    if args.out:
        check_output("--out", args.out, folder=True)
    robot = _robot(args)
    solver = _solver(args)
    scene = _scene(args, robot)
    if args.intervals is None:
        obstacles = Loads() if scene is None else Loads().with_scene(scene)
        solver = default_solver(robot, obstacles, steps=solver.steps, max_iter=solver.max_iter)
    else:
        check_flag("--intervals", args.intervals, 1)
        if scene is not None and args.intervals > 1:
            raise ValueError(
                f"--scene with --intervals {args.intervals}: contact is solved by single shooting; give --intervals 1"
            )
        solver = SolverOptions(steps=solver.steps, max_iter=solver.max_iter, intervals=args.intervals)
    depths = _depths_typed(args, robot)
    try:
        check_dynamics(robot, Actuation.of(None, robot), Loads(), solver)
    except ValueError as e:
        raise ValueError(f"--robot {args.robot}: {e}" if args.robot else str(e)) from None
    table = read_input_table(args.inputs, robot.n_tendons, robot.n_tubes)
    if table.insertions is not None and (args.insertion_mm is not None or args.insertions_mm is not None):
        flag = "--insertion-mm" if args.insertion_mm is not None else "--insertions-mm"
        raise ValueError(f"{flag} and the input table's insertion columns: give the tube depths in one of them")
    dt = args.dt_ms * 1e-3
    duration = float(table.t[-1]) if args.duration_s is None else args.duration_s
    if duration == 0:
        raise ValueError(f"{args.inputs}: one row, at t = 0: give --duration-s, the time to hold it for")
    steps = math.floor(duration / dt + 1e-9)  # the last time: the largest multiple of dt within the duration
    if steps < 1:
        raise ValueError(f"--duration-s {duration:g} is shorter than one time step, --dt-ms {args.dt_ms:g}")
    if steps > MAX_TIME_STEPS:
        raise ValueError(
            f"{duration:g} s ({'--duration-s' if args.duration_s else 'the table'}) in steps of --dt-ms {args.dt_ms:g} is "
            f"{steps} time steps, more than {MAX_TIME_STEPS}: are the table's t_s in seconds and --dt-ms in "
            "milliseconds? Else simulate in parts"
        )
    if duration > table.t[-1]:
        print(f"tdct: note: the table ends at {table.t[-1]:g} s; its last row is held to {duration:g} s", file=sys.stderr)
    times = np.arange(steps + 1) * dt
    tensions, displacements, tip_force, insertions = table.at(times)
    if not args.quiet:
        print(
            f"simulating {steps} steps of {args.dt_ms:g} ms to t = {times[-1]:g} s in one compiled program "
            "(compiling takes about half a minute the first time)",
            file=sys.stderr,
            flush=True,
        )
    started = time.perf_counter()
    traj = simulate(
        robot,
        dt,
        tensions=tensions,
        displacements=displacements,
        driven=table.driven,
        tip_force=tip_force,
        insertions=[d * 1e-3 for d in depths] if insertions is None else insertions,
        scene=scene,
        start=args.start,
        alpha=args.alpha,
        gravity=_gravity(args),
        solver=solver,
        throw=False,
    )
    traj = jax.tree.map(np.asarray, traj)
    seconds = time.perf_counter() - started
    result = traj.result
    failed = np.flatnonzero(result != status.SUCCESS)
    good = int(failed[0]) if failed.size else len(result)  # the rows before the first failure
    newton = f"{np.mean(traj.iterations[1:]):.1f} chord and Newton steps a step"
    state = "every step converged" if not failed.size else f"{failed.size} of {len(result)} steps did NOT converge"
    print(f"simulated {steps} steps of {args.dt_ms:g} ms to t = {times[-1]:g} s in {seconds:.1f} s: {state} ({newton})")
    if good:
        tip, last = 1e3 * traj.tip_position[good - 1], "" if good == len(result) else ", the last converged"
        print(f"tip at t = {times[good - 1]:g} s{last} [mm]: x = {tip[0]:.4f}, y = {tip[1]:.4f}, z = {tip[2]:.4f}")
    written = []
    if args.out:
        written += _write_trajectory(Path(args.out), traj, tip_force, args, dt)
    title = f"{Path(args.robot).stem if args.robot else 'paper robot'}, inputs {Path(args.inputs).name}, dt {args.dt_ms:g} ms"
    shown = jax.tree.map(lambda a: a[:good], traj)
    if good < 2 and (args.plot or args.gif):
        print("tdct: note: no figures: fewer than two times converged", file=sys.stderr)
    if good > 1 and args.plot:
        from .plotting import plot_tip_path

        plot_tip_path(shown, args.plot, title=title)
        written.append(args.plot)
    if good > 1 and args.gif:
        from .plotting import animate_trajectory

        with tqdm(total=min(args.frames, good), desc="animating", unit="frame", disable=args.quiet, leave=False) as bar:
            animate_trajectory(shown, args.gif, frames=args.frames, title=title, progress=lambda i, n: bar.update(1), scene=scene)
        written.append(args.gif)
    if written:
        print(f"wrote {', '.join(map(str, written))}")
    if failed.size:
        raise ConvergenceError(_step_failure(traj, int(failed[0]), solver, args), int(result[failed[0]]))
    return 0


def _step_failure(traj, i: int, solver: SolverOptions, args) -> str:
    """What went wrong at row ``i`` of a trajectory, and what to do, in tdct simulate's flags."""
    code, t = int(traj.result[i]), float(traj.t[i])
    if code == status.NEWTON_LIMIT:
        why = (
            f"Newton used its --max-iter {solver.max_iter} steps without bringing the scaled tip residual "
            f"({float(traj.residual_norm[i]):.3g}) below {solver.tol:g}"
        )
    else:
        why = status.NAMES.get(code, f"result code {code}")
    kept = f"; {args.out}/trajectory.csv and .npz keep every step's result code" if args.out else ""
    kept += "; the figures stop before it" if args.plot or args.gif else ""
    if i == 0:
        return (
            f"the start (the static shape of the table's first row) did not converge: {why}; raise --max-iter, "
            f"or start from the straight robot (--start straight){kept}"
        )
    return (
        f"time step {i} (t = {t:g} s) did not converge: {why}. Raise --intervals (now {solver.intervals}; "
        "it must divide the robot's RK4 steps) or --max-iter, or ramp the inputs where they jump (docs/dynamics.md, "
        f"Limits){kept}"
    )


def _write_trajectory(out: Path, traj, tip_force, args, dt: float) -> list[Path]:
    """trajectory.csv (t_s, tip in mm, the tensions (found for displacement-driven tendons), every
    tendon's displacement in mm, the tip force, every tube's depth in mm, each step's result code) and trajectory.npz
    (every Trajectory array and the tip force [N], SI units, and a JSON ``metadata`` entry with the
    units and the run's settings) in the folder ``out``; returns their paths."""
    out.mkdir(parents=True, exist_ok=True)
    n_t = traj.tensions.shape[1]
    names = [TIME_COLUMN, "tip_x_mm", "tip_y_mm", "tip_z_mm", *(f"tension_{i}_N" for i in range(1, n_t + 1))]
    names += [*(f"displacement_{i}_mm" for i in range(1, n_t + 1)), *TIP_FORCE_COLUMNS]
    names += [*(f"insertion_{i}_mm" for i in range(1, traj.insertions.shape[1] + 1)), "result"]
    table = np.column_stack(
        [traj.t, 1e3 * traj.tip_position, traj.tensions, 1e3 * traj.displacements, tip_force, 1e3 * traj.insertions]
    )
    rows = [",".join([*(f"{v:.12g}" for v in row), str(int(code))]) for row, code in zip(table, traj.result, strict=True)]
    csv_path, npz_path = out / "trajectory.csv", out / "trajectory.npz"
    csv_path.write_text("\n".join([",".join(names), *rows]) + "\n")
    units = dict(
        t="s", s="m", position="m", rotation="1 (world from body)", force="N", moment="N m", velocity="m/s",
        angular_velocity="rad/s", tensions="N", tendon_tension="N", displacements="m", insertions="m", tip_force="N",
        contact_force="N (candidates x obstacles)", contact_gap="m",
        iterations="chord and Newton steps",
        result="tdct_jax.status code, 0 converged", residual_norm="1 (scaled tip residual, max norm)",
    )  # fmt: skip
    metadata = dict(
        units=units,
        frame="world; gravity along -y; force and moment: the total internal force and moment of rod plus tendons",
        dt_s=dt,
        alpha=args.alpha,
        start=args.start,
        gravity=not args.no_gravity,
        rk4_steps=args.steps,
        max_iter=args.max_iter,
        robot=str(args.robot) if args.robot else "the paper's robot (Robot.paper())",
        set={name: value for name, value in args.set},
        inputs=str(args.inputs),
        tdct_jax=__version__,
    )
    arrays = {f.name: getattr(traj, f.name) for f in dataclasses.fields(traj)}
    np.savez(npz_path, **arrays, tip_force=tip_force, metadata=np.array(json.dumps(metadata)))
    return [csv_path, npz_path]


COMMANDS = {
    "solve": _solve_command,
    "compliance": _compliance_command,
    "reproduce": _reproduce_command,
    "synth": _synth_command,
    "calibrate": _calibrate_command,
    "ik": _ik_command,
    "sweep": _sweep_command,
    "simulate": _simulate_command,
}


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit code: 0 done, 1 not converged, 2 bad input (the reason on
    stderr, before any computation where it can be known then), 3 an internal error (a bug:
    TDCT_DEBUG=1 shows its traceback)."""
    try:
        args = _parser().parse_args(_negative_values_attached(sys.argv[1:] if argv is None else list(argv)))
    except SystemExit as e:  # argparse: --help (0) or a usage error (2), already printed
        return int(e.code or 0)
    use_every_cpu_core()
    cache = None if args.no_compile_cache else compile_cache_dir()
    if cache is not None:
        enable_compile_cache(cache)
    on_cpu = args.verb in ON_CPU and jax.default_backend() != "cpu"
    try:
        for dest, flag in OUTPUTS.items():
            if getattr(args, dest, None):
                _check_output(dest, flag, getattr(args, dest))
        with _notes(), jax.default_device(jax.local_devices(backend="cpu")[0]) if on_cpu else contextlib.nullcontext():
            return COMMANDS[args.verb](args)
    except (ValueError, TypeError, OSError) as e:
        return _fail(e, 2)
    except ConvergenceError as e:  # not a bad input: what did not converge, and what to do
        print(f"tdct: {e.cli_message}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        again = "; the finished chunks are kept: rerunning the same command resumes from them" if args.verb == "sweep" else ""
        print(f"tdct: interrupted{again}", file=sys.stderr)
        return 130
    except Exception as e:  # no traceback reaches a user: say what happened and how to learn more
        if os.environ.get("TDCT_DEBUG"):
            raise
        return _fail(f"internal error ({type(e).__name__}: {e}); please report it (TDCT_DEBUG=1 shows the traceback)", 3)


def _fail(error, code: int) -> int:
    if isinstance(error, OSError) and error.filename:
        error = f"{error.filename}: {error.strerror or error}"
    print(f"tdct: error: {error}", file=sys.stderr)
    return code


@contextlib.contextmanager
def _notes():
    """Prints CalibrationWarnings (inputs outside the calibrated range), UnitWarnings (values far
    outside any robot's, as if typed in another unit) and FutureWarnings (a former name typed,
    such as --set E_silicone=...) as one-line notes on stderr."""
    with warnings.catch_warnings():
        warnings.simplefilter("always", CalibrationWarning)
        warnings.simplefilter("always", UnitWarning)
        show, shown = warnings.showwarning, set()

        def note(message, category, *rest, **kw):
            if issubclass(category, (CalibrationWarning, UnitWarning, FutureWarning)):  # FutureWarning: a former name
                if str(message) not in shown:  # once each, though the robot is rebuilt along the way
                    print(f"tdct: note: {message}", file=sys.stderr)
                    shown.add(str(message))
            else:
                show(message, category, *rest, **kw)

        warnings.showwarning = note
        yield


if __name__ == "__main__":
    sys.exit(main())
