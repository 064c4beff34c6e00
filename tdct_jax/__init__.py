"""tdct_jax: differentiable statics of the tendon-driven concentric-tube (TDCT) soft robot."""

import jax

jax.config.update("jax_enable_x64", True)

from .loads import STANDARD_GRAVITY as STANDARD_GRAVITY  # noqa: E402
from .loads import Actuation as Actuation  # noqa: E402
from .loads import TipLoad as TipLoad  # noqa: E402
from .robot import Robot as Robot  # noqa: E402
from .shooting import ConvergenceError as ConvergenceError  # noqa: E402
from .shooting import Solution as Solution  # noqa: E402
from .shooting import SolverOptions as SolverOptions  # noqa: E402
from .shooting import solve as solve  # noqa: E402

__version__ = "0.1.0"
