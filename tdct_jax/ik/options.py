"""How the inverse kinematics computes: ``IKOptions``, accepted as ``ik=`` by ``inverse_kinematics``
and ``track`` beside ``solver=``."""

from __future__ import annotations

from ..checks import check_choice, check_iteration
from ..tree import pytree, static

TOL = 1e-10
"""Default tolerance on the scaled task residual: position error / L (and orientation error [rad])."""
MAX_STEPS = 60
"""Default limit on IK steps: from each start of phase 1, and in phase 2."""
METHODS = ("augmented", "nested")


@pytree
class IKOptions:
    """The IK iteration. ``method`` shapes the compiled program; ``tol`` and ``max_steps`` are
    leaves, so changing them does not compile a new one.

    Attributes:
        method: how phase 1 evaluates a step: "augmented" (shooting unknowns and inputs iterated
            together, one Jacobian pass of their own a step) or "nested" (a converged forward
            solve at every step, through the forward solve the phases share: no pass of its own
            in the program). None (default): nested for the stiffness objective, whose program
            holds a second-order pass already (it compiles in about four fifths of the time,
            with the same warm time for a reachable target), augmented otherwise (its steps are
            about half the cost).
        tol: tolerance on the scaled task residual (position error / L; orientation error [rad]),
            > 0.
        max_steps: most IK steps from each start of phase 1 (the given start, then fresh ones
            while the target is missed), and most steps of phase 2; an integer >= 1.
    """

    method: str | None = static(default=None)
    tol: float = TOL
    max_steps: int = MAX_STEPS

    def __post_init__(self):
        check_choice("IKOptions.method", self.method, (*METHODS, None))
        check_iteration(self, "tol", "max_steps", prefix="IKOptions.")


DEFAULT_IK = IKOptions()
"""The defaults of ``ik=``."""
