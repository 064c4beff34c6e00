"""How a static shape is computed: SolverOptions, accepted as ``solver=`` by every entry point."""

from __future__ import annotations

import itertools

from .checks import check_choice, check_integer, check_iteration
from .tree import pytree, set_fields, static

TRANSITIONS = ("balanced", "paper")
TENDON_MODELS = ("exact", "paper")
ROTATIONS = ("columns", "matrix")
STEPS = 20
"""Default RK4 steps per segment: the fewest that keep every tip within 1 um of the converged
solution over 2,500 envelope points (benchmarks/accuracy_steps.py: worst 0.65 um at 20, 1.5 um at
16, with high tension and a compressive tip force the hardest cases)."""
TOL = 1e-10
"""Default convergence threshold on the scaled tip residual (max norm)."""
MAX_ITER = 50
"""Default limit on Newton steps per load stage."""
STAGES = (1, 4, 16)
"""Default load continuation: numbers of equal load stages tried in turn when Newton fails."""


@pytree
class SolverOptions:
    """The discrete model and the Newton shooting iteration (docs/model.md).

    ``steps``, ``transition`` and ``tendon_model`` shape the compiled program (each distinct value
    compiles once); ``tol`` and ``max_iter`` are leaves, so changing them does not recompile.

    Attributes:
        steps: RK4 steps per breakpoint interval (the paper's robot: backbone [0, d] and
            silicone-only [d, L]).
        transition: "balanced" (total rod + tendon force and moment continuous at s = d) or
            "paper" (rod force and moment continuous, eqs. 31-32 as printed).
        tendon_model: tendon load in the backbone segment, "exact" (Rucker-Webster, tangents
            tilted by u x r_t) or "paper" (eqs. 21-22 as printed).
        tol: convergence threshold on the scaled tip residual (force / typical force, moment /
            (typical force x L)), max norm; finite and > 0.
        max_iter: most Newton steps per load stage (``Solution.iterations`` counts all steps).
        stages: load continuation, the numbers of equal load stages tried in turn, each ramp
            from the straight rod when the one before fails (increasing positive integers).
        intervals: shooting intervals K (static): 1 integrates from the base to the tip in one
            chain of RK4 steps (single shooting); K > 1 splits the chain into K intervals of equal
            step count integrated side by side, their start states unknowns too (multiple
            shooting, docs/performance.md). The chain is the robot's P * steps steps (P breakpoint
            intervals, ``steps`` each: the paper's robot has two; every breakpoint an interval
            boundary when K = P q, q dividing ``steps``); K must divide it, checked
            when a solve is traced (ValueError naming the allowed values).
        rotation: how RK4 carries the rotation R (static; the same numbers to round-off):
            "columns", R's three columns as three arrays, or "matrix", R whole. Columns keep a
            Jacobian pass in more than 7 directions (the IK's) running each RK4 step in sequence
            on XLA:CPU, and run GPU batches faster; the matrix runs CPU batches faster. None
            (default): "matrix" in a sweep or batched IK on a CPU, "columns" everywhere else
            (benchmarks/README.md, "R by its columns in the RK4 scan").
    """

    steps: int = static(default=STEPS)
    transition: str = static(default="balanced")
    tendon_model: str = static(default="exact")
    tol: float = TOL
    max_iter: int = MAX_ITER
    stages: tuple = static(default=STAGES)
    intervals: int = static(default=1)
    rotation: str | None = static(default=None)

    def __post_init__(self):
        set_fields(self, steps=check_integer("steps", self.steps), intervals=check_integer("intervals", self.intervals))
        check_choice("transition", self.transition, TRANSITIONS)
        check_choice("tendon_model", self.tendon_model, TENDON_MODELS)
        if self.rotation is not None:
            check_choice("rotation", self.rotation, ROTATIONS)
        stages = tuple(self.stages) if isinstance(self.stages, (tuple, list)) else None
        if not stages or any(isinstance(k, bool) or not isinstance(k, int) for k in stages):
            raise ValueError(f"stages = {self.stages!r}: expected a non-empty tuple of positive integers, e.g. {STAGES}")
        if stages[0] < 1 or any(b <= a for a, b in itertools.pairwise(stages)):
            raise ValueError(f"stages = {stages}: expected positive integers in increasing order, e.g. {STAGES}")
        set_fields(self, stages=stages)
        check_iteration(self, "tol", "max_iter")


DEFAULT_SOLVER = SolverOptions()
"""The defaults of every entry point's ``solver=``."""
