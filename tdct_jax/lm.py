"""Levenberg-Marquardt on the host for a least-squares model evaluated elsewhere (a compiled
residual and Jacobian): no physics."""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from . import status


class LeastSquares(NamedTuple):
    """Outcome of ``levenberg_marquardt``: the last accepted point and what was evaluated there;
    ``result`` is a ``tdct_jax.status`` code (SUCCESS, OUTER_LIMIT, or the model's own failure at
    the start)."""

    x: np.ndarray
    residual: np.ndarray
    jacobian: np.ndarray
    aux: object
    iterations: int
    result: int
    message: str

    @property
    def converged(self) -> bool:
        return self.result == status.SUCCESS


def levenberg_marquardt(
    evaluate: Callable, x0, *, max_steps: int = 30, xtol: float = 1e-8, callback: Callable | None = None
) -> LeastSquares:
    """Minimises |r(x)|^2 by Levenberg-Marquardt with Marquardt's diagonal scaling.

    Args:
        evaluate: x -> (r (m,), J (m, p), code, aux) in numpy; ``code`` is the model's
            ``status`` code there (0: it converged).
        x0: starting point, (p,).
        max_steps: most trial steps.
        xtol: converged when the undamped Gauss-Newton step moves no component more than this.
        callback: called as callback(iteration, r, step) after each accepted step.

    A trial is accepted when the model converged there and the cost fell; the damping then
    shrinks tenfold (towards Gauss-Newton), otherwise it grows tenfold.
    """
    x = np.asarray(x0, dtype=float)
    r, J, code, aux = evaluate(x)
    if code != status.SUCCESS:
        return LeastSquares(x, r, J, aux, 0, code, "the model did not converge at the starting values")
    mu = 1e-3
    for it in range(max_steps):
        if np.abs(np.linalg.lstsq(J, -r, rcond=None)[0]).max() <= xtol:
            return LeastSquares(x, r, J, aux, it, status.SUCCESS, "converged")
        A = J.T @ J
        step = np.linalg.solve(A + mu * np.diag(np.maximum(np.diag(A), 1e-300)), -J.T @ r)
        r_t, J_t, code_t, aux_t = evaluate(x + step)
        if code_t == status.SUCCESS and np.all(np.isfinite(r_t)) and r_t @ r_t < r @ r:
            x, r, J, aux = x + step, r_t, J_t, aux_t
            mu = max(mu / 10, 1e-12)
            if callback is not None:
                callback(it + 1, r, step)
        else:
            mu *= 10
    message = f"hit max_steps = {max_steps}; raise it or start nearer the optimum"
    return LeastSquares(x, r, J, aux, max_steps, status.OUTER_LIMIT, message)
