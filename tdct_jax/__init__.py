"""tdct_jax: differentiable statics of tendon-driven continuum robots, the TDCT robot first."""

import jax

from . import compiler
from .version import __version__ as __version__

compiler.use_fast_compile_flags()
jax.config.update("jax_enable_x64", True)

from . import checks, inputs, manipulation  # noqa: E402
from . import fields as fields  # noqa: E402
from . import status as status  # noqa: E402
from .calibrate import Calibration as Calibration  # noqa: E402
from .calibrate import calibrate as calibrate  # noqa: E402
from .calibrate import synthesize as synthesize  # noqa: E402
from .calibrate_rig import Prediction as Prediction  # noqa: E402
from .calibrate_rig import RigCalibration as RigCalibration  # noqa: E402
from .calibrate_rig import calibrate_rig as calibrate_rig  # noqa: E402  (former name; warns when called)
from .calibrate_rig import predict as predict  # noqa: E402
from .calibrate_rig import synthesize_recording as synthesize_recording  # noqa: E402
from .checks import UnitWarning as UnitWarning  # noqa: E402
from .contact import Contact as Contact  # noqa: E402
from .data import Experiment as Experiment  # noqa: E402
from .data import read_experiment as read_experiment  # noqa: E402
from .data import read_experiments as read_experiments  # noqa: E402
from .data import write_experiment as write_experiment  # noqa: E402
from .description import CalibrationWarning as CalibrationWarning  # noqa: E402
from .description import PointMass as PointMass  # noqa: E402
from .description import Robot as Robot  # noqa: E402
from .description import Section as Section  # noqa: E402
from .description import Tendon as Tendon  # noqa: E402
from .description import Tube as Tube  # noqa: E402
from .dynamics import Motion as Motion  # noqa: E402
from .dynamics import MotionFit as MotionFit  # noqa: E402
from .dynamics import Trajectory as Trajectory  # noqa: E402
from .dynamics import fit_motion as fit_motion  # noqa: E402
from .dynamics import simulate as simulate  # noqa: E402
from .estimate import ForceEstimate as ForceEstimate  # noqa: E402
from .estimate import TipPose as TipPose  # noqa: E402
from .estimate import estimate_force as estimate_force  # noqa: E402
from .ik import Bounds as Bounds  # noqa: E402
from .ik import IKOptions as IKOptions  # noqa: E402
from .ik import IKResult as IKResult  # noqa: E402
from .ik import LeastTension as LeastTension  # noqa: E402
from .ik import PreferredInsertion as PreferredInsertion  # noqa: E402
from .ik import Stiffness as Stiffness  # noqa: E402
from .ik import Target as Target  # noqa: E402
from .ik import inverse_kinematics as inverse_kinematics  # noqa: E402
from .ik import track as track  # noqa: E402
from .inputs import STANDARD_GRAVITY as STANDARD_GRAVITY  # noqa: E402
from .inputs import Actuation as Actuation  # noqa: E402
from .inputs import Loads as Loads  # noqa: E402
from .manipulation import Capacity as Capacity  # noqa: E402
from .manipulation import Optimum as Optimum  # noqa: E402
from .manipulation import capacity as capacity  # noqa: E402
from .manipulation import optimal_insertion as optimal_insertion  # noqa: E402
from .mechanics import Ellipsoid as Ellipsoid  # noqa: E402
from .mechanics import compliance as compliance  # noqa: E402
from .mechanics import compliance_ellipsoid as compliance_ellipsoid  # noqa: E402
from .mechanics import finite_difference_compliance as finite_difference_compliance  # noqa: E402
from .mechanics import kinematic_jacobian as kinematic_jacobian  # noqa: E402
from .mechanics import parameter_jacobian as parameter_jacobian  # noqa: E402
from .mechanics import positions_at as positions_at  # noqa: E402
from .mechanics import rmse as rmse  # noqa: E402
from .mechanics import tip_error as tip_error  # noqa: E402
from .options import SolverOptions as SolverOptions  # noqa: E402
from .recording import Dataset as Dataset  # noqa: E402
from .recording import Recording as Recording  # noqa: E402
from .recording import read_dataset as read_dataset  # noqa: E402
from .recording import read_recording as read_recording  # noqa: E402
from .results import CapacityResult as CapacityResult  # noqa: E402
from .results import OptimumResult as OptimumResult  # noqa: E402
from .results import SweepChunk as SweepChunk  # noqa: E402
from .results import SweepResult as SweepResult  # noqa: E402
from .results import gather as gather  # noqa: E402
from .rig import Rig as Rig  # noqa: E402
from .scene import Capsule as Capsule  # noqa: E402
from .scene import Distance as Distance  # noqa: E402
from .scene import Plane as Plane  # noqa: E402
from .scene import Scene as Scene  # noqa: E402
from .scene import Sphere as Sphere  # noqa: E402
from .scene import read_scene as read_scene  # noqa: E402
from .solve import Solution as Solution  # noqa: E402
from .solve import solve as solve  # noqa: E402
from .solve import tip_angle as tip_angle  # noqa: E402
from .status import ConvergenceError as ConvergenceError  # noqa: E402
from .sweep import sweep as sweep  # noqa: E402
from .sweep import sweep_chunks as sweep_chunks  # noqa: E402

_RENAMED = {
    "GeneralRobot": ("Robot", Robot),
    "GeneralActuation": ("Actuation", Actuation),
    "GeneralSolution": ("Solution", Solution),
}


_WARN_WHEN_CALLED = {
    "TipLoad": inputs,
    "load_capacity": manipulation,
    "insertion_optimum": manipulation,
}


def __getattr__(name):
    """The former names of merged types (``tdct.GeneralRobot``): the merged type, warning once;
    ``tdct.TipLoad``, ``tdct.load_capacity`` and ``tdct.insertion_optimum``, which warn when called
    (``tdct.calibrate_rig`` too, imported by name: its module shares the name)."""
    if name in _WARN_WHEN_CALLED:
        return getattr(_WARN_WHEN_CALLED[name], name)
    if name in _RENAMED:
        new, obj = _RENAMED[name]
        checks.deprecated(f"tdct.{name}", f"tdct.{new}")
        return obj
    raise AttributeError(f"module 'tdct_jax' has no attribute {name!r}")
