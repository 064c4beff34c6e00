"""Result codes: how an iteration ended, computed inside the compiled program (so they work under
jit and vmap), the message that says what to do about each, and the one place ``throw`` applies."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from .checks import is_concrete

SUCCESS = 0
"""Converged: the residual met the tolerance."""
NEWTON_LIMIT = 1
"""Newton used its ``max_iter`` steps in a load stage and the last load ramp without converging."""
CONTINUATION_EXHAUSTED = 2
"""Newton stalled (its damping grew without lowering the residual) in every load ramp."""
NONFINITE = 3
"""The residual is NaN or infinite at every point Newton could try."""
OUTER_LIMIT = 4
"""An outer iteration (load capacity, insertion optimum, inverse kinematics, calibration) used its
``max_steps`` without meeting its own tolerance."""
UNREACHABLE = 5
"""Inverse kinematics: no input within the bounds puts the tip on the target; the nearest pose
found is the answer (not a failure: ``throw`` does not raise for it). Load capacity: even the
unloaded tip stays below the height (mass 0; ``throw`` raises, there is no capacity)."""
CONTACT_UNCONVERGED = 6
"""With a scene: Newton found no contact set (forces and gaps) that meets the tolerance."""
PENETRATION = 7
"""With a scene: converged, but the body lies inside an obstacle by more than 2 tol x L at a
contact candidate (each candidate's Fischer-Burmeister row within tol holds its gap above -tol x L
to first order: the check guards what is reported, not between candidates)."""

NAMES = {
    SUCCESS: "converged",
    NEWTON_LIMIT: "Newton limit reached",
    CONTINUATION_EXHAUSTED: "load continuation exhausted",
    NONFINITE: "non-finite residual",
    OUTER_LIMIT: "outer iteration limit reached",
    UNREACHABLE: "target unreachable",
    CONTACT_UNCONVERGED: "contact set did not converge",
    PENETRATION: "penetration beyond tolerance",
}

_ADVICE = {
    NEWTON_LIMIT: (
        "Newton used its limit of max_iter = {max_iter} steps per load stage without bringing the scaled tip residual "
        "({residual_norm:.3g}) below tol = {tol:g} ({iterations} steps in all; the loads were ramped in up to {stages} "
        "stages). {raise_max_iter}."
    ),
    CONTINUATION_EXHAUSTED: (
        "Newton stalled (its damping grew without lowering the scaled tip residual {residual_norm:.3g} below tol = {tol:g}) "
        "even with the loads ramped in {stages} stages ({iterations} steps in all). The configuration is probably beyond "
        "what the model can reach (a looped or buckled shape), or tol is below what float64 round-off allows: "
        "{check_inputs}."
    ),
    NONFINITE: (
        "the shooting residual is not finite (NaN or inf) after {iterations} Newton steps: the inputs are probably extreme "
        "(check the robot fields, tensions and loads)."
    ),
    OUTER_LIMIT: "{what} used its max_steps = {max_steps} without meeting its tolerance; {raise_max_steps}.",
    UNREACHABLE: "{unreachable}",
    CONTACT_UNCONVERGED: (
        "with the scene's obstacles, Newton did not bring the scaled residual ({residual_norm:.3g}; tip, and a "
        "Fischer-Burmeister row per contact candidate and obstacle) below tol = {tol:g} ({iterations} steps in all, loads "
        "ramped in up to {stages} stages). The contact set probably changes abruptly here (an obstacle grazing the body, "
        "or pushing it past a snap): {contact_advice}."
    ),
    PENETRATION: (
        "converged, but the body lies inside an obstacle by more than 2 tol x L at a contact candidate; tighten tol or "
        "check that the obstacles leave the robot room (a robot pinned between obstacles cannot satisfy them all)."
    ),
}
HINTS = {
    False: dict(
        raise_max_iter="Raise max_iter (SolverOptions(max_iter=...)), or start from a nearby solution (guess=)",
        check_inputs="check the inputs and tol, or approach the configuration from a nearby converged solution (guess=)",
        raise_max_steps="raise max_steps or start nearer the answer",
        keep_failures="throw=False keeps them as result codes",
        contact_advice="approach the configuration from a nearby converged solution (guess=), raise max_iter, or "
        "refine the candidates (Scene(every=...)) or move the obstacle slightly",
    ),
    True: dict(
        raise_max_iter="Raise --max-iter",
        check_inputs="check the inputs (tensions, tip load, robot fields) and the spec's [solver] tol",
        raise_max_steps="raise --max-steps or start nearer the answer",
        keep_failures="their result codes are kept",
        contact_advice="raise --max-iter, refine the candidates (the scene file's every) or move the obstacle slightly",
    ),
}
"""What to do, in the words of the Python API (False) and of the ``tdct`` command line (True)."""
DEFAULTS = dict(unreachable="no inputs within the bounds put the tip on the target; the nearest pose found is returned")
"""Context a caller may override (e.g. what UNREACHABLE means for a load capacity)."""


class ConvergenceError(RuntimeError):
    """An iteration did not converge (raised with ``throw=True``); ``result`` is its code;
    ``cli_message`` says the same with the command line's flags for the Python arguments."""

    def __init__(self, message: str, result: int, cli_message: str | None = None):
        super().__init__(message)
        self.result = result
        self.cli_message = message if cli_message is None else cli_message


def message(result: int, *, cli: bool = False, **context) -> str:
    """What went wrong and what to do, for one result code; ``context`` fills in the numbers;
    ``cli``: the advice names ``tdct``'s flags instead of Python arguments."""
    result = int(result)
    if result == SUCCESS:
        return NAMES[SUCCESS]
    template = _ADVICE.get(result)
    if template is None:
        return f"unknown result code {result}"
    return f"{NAMES[result]}: " + template.format_map(_Context(DEFAULTS | HINTS[cli] | context))


class _Context(dict):
    """Format values; a number the caller could not supply prints as '?'."""

    def __missing__(self, key):
        return _Unknown()


class _Unknown:
    def __format__(self, spec):
        return "?"


def check(result, *, throw: bool, what: str = "the solve", **context) -> None:
    """The one place ``throw`` applies: with ``throw``, raises ConvergenceError for the first
    failing entry of ``result`` (any shape), its message filled in from ``context`` (scalars, or
    arrays shaped like ``result``, e.g. iterations, stages, residual_norm, max_iter, tol).

    On concrete values it raises here. On traced values (inside jit, vmap or grad) the same check
    is compiled into the program and raises when the program runs, as a JAX runtime error that
    carries the message.
    """
    if not throw:
        return
    if is_concrete(result) and all(is_concrete(v) for v in context.values() if not isinstance(v, str)):
        _raise_first(np.asarray(result), what, context)
        return
    static = {k: v for k, v in context.items() if isinstance(v, str)}
    arrays = {k: v for k, v in context.items() if not isinstance(v, str)}
    jax.debug.callback(lambda r, a: _raise_first(np.asarray(r), what, dict(static, **a)), result, arrays)


def _raise_first(result: np.ndarray, what: str, context: dict) -> None:
    failed = np.flatnonzero(result.ravel() != SUCCESS)
    if failed.size == 0:
        return
    i = int(failed[0])
    values = {}
    for k, v in context.items():
        a = np.asarray(v)
        values[k] = v if isinstance(v, str) else (a.ravel()[i] if a.shape == result.shape and a.ndim else a.item())
    code = int(result.ravel()[i])
    where = ""
    if result.ndim:
        index = np.unravel_index(i, result.shape)
        where = f" at point {index if len(index) > 1 else index[0]} ({failed.size} of {result.size} failed)"

    def text(cli: bool) -> str:
        try:  # ``what`` may hold a hint, e.g. {keep_failures}
            said = what.format_map(_Context(HINTS[cli]))
        except (ValueError, IndexError):
            said = what
        return f"{said} did not converge{where}: {message(code, cli=cli, what=said, **values)}"

    raise ConvergenceError(text(False), code, text(True))


def contact_result(result, gap, depth):
    """A solve's code with a scene: a Newton failure (its limit, a stall) is CONTACT_UNCONVERGED;
    a converged one with some gap below -depth [m] (2 tol x L) is PENETRATION."""
    failed = (result == NEWTON_LIMIT) | (result == CONTINUATION_EXHAUSTED)
    inside = (result == SUCCESS) & (jnp.min(gap) < -depth)
    return jnp.where(failed, CONTACT_UNCONVERGED, jnp.where(inside, PENETRATION, result)).astype(result.dtype)


def first_failure(codes) -> int:
    """The first nonzero code of ``codes`` (any shape), or SUCCESS."""
    codes = np.asarray(codes).ravel()
    bad = np.flatnonzero(codes)
    return int(codes[bad[0]]) if bad.size else SUCCESS
