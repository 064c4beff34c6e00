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
    evaluate: Callable,
    x0,
    *,
    lower=None,
    upper=None,
    max_steps: int = 30,
    xtol: float = 1e-8,
    ftol: float = 0.0,
    callback: Callable | None = None,
) -> LeastSquares:
    """Minimises |r(x)|^2 by Levenberg-Marquardt with Marquardt's diagonal scaling.

    Args:
        evaluate: x -> (r (m,), J (m, p), code, aux) in numpy; ``code`` is the model's
            ``status`` code there (0: it converged).
        x0: starting point, (p,), within the bounds.
        lower, upper: bounds on x, (p,) (None or +-inf: unbounded).
        max_steps: most trial steps.
        xtol: converged when the undamped Gauss-Newton step, kept within the bounds, moves no
            component more than this.
        ftol: converged, too, when an accepted step lowers the cost by at most this fraction
            (a flat valley of values the data cannot tell apart, where steps stay long).
        callback: called as callback(iteration, r, step) after each accepted step.

    A trial is accepted when the model converged there, the residual and Jacobian are finite and
    the cost fell; the damping then shrinks tenfold (towards Gauss-Newton), otherwise it grows
    tenfold. Bounds: a component at a
    bound whose descent direction leaves the box is held there for the step; the others' step is
    cut back to the box (a projected Levenberg-Marquardt step).

    Raises:
        ValueError: x0 outside the bounds, or bounds of the wrong shape.
    """
    x = np.asarray(x0, dtype=float)
    lo, hi = (
        np.broadcast_to(np.asarray(b, float), x.shape)
        for b in (-np.inf if lower is None else lower, np.inf if upper is None else upper)
    )
    outside = np.flatnonzero((x < lo) | (x > hi))
    if outside.size:
        i = outside[0]
        raise ValueError(f"x0[{i}] = {x[i]:g} is outside its bounds [{lo[i]:g}, {hi[i]:g}]")
    r, J, code, aux = evaluate(x)
    if code != status.SUCCESS:
        return LeastSquares(x, r, J, aux, 0, code, "the model did not converge at the starting values")
    if not (np.all(np.isfinite(r)) and np.all(np.isfinite(J))):
        return LeastSquares(
            x, r, J, aux, 0, status.NONFINITE, "the residual or its Jacobian is not finite at the starting values"
        )
    mu = 1e-3
    for it in range(max_steps):
        g = J.T @ r
        free = ~(((x <= lo) & (g > 0)) | ((x >= hi) & (g < 0)))
        Jf = J[:, free]
        gauss_newton = np.zeros_like(x)
        gauss_newton[free] = np.linalg.lstsq(Jf, -r, rcond=None)[0]
        if np.abs(np.clip(x + gauss_newton, lo, hi) - x).max() <= xtol:
            return LeastSquares(x, r, J, aux, it, status.SUCCESS, "converged")
        A = Jf.T @ Jf
        step = np.zeros_like(x)
        step[free] = np.linalg.solve(A + mu * np.diag(np.maximum(np.diag(A), 1e-300)), -g[free])
        step = np.clip(x + step, lo, hi) - x
        r_t, J_t, code_t, aux_t = evaluate(x + step)
        finite = np.all(np.isfinite(r_t)) and np.all(np.isfinite(J_t))
        if code_t == status.SUCCESS and finite and r_t @ r_t < r @ r:
            flat = r @ r - r_t @ r_t <= ftol * (r @ r)
            x, r, J, aux = x + step, r_t, J_t, aux_t
            mu = max(mu / 10, 1e-12)
            if callback is not None:
                callback(it + 1, r, step)
            if flat:
                return LeastSquares(x, r, J, aux, it + 1, status.SUCCESS, "converged (the cost no longer falls)")
        else:
            mu *= 10
    message = f"hit max_steps = {max_steps}; raise it or start nearer the optimum"
    return LeastSquares(x, r, J, aux, max_steps, status.OUTER_LIMIT, message)


def covariance(fit: LeastSquares, n_data: int, rcond: float = 1e-10):
    """The Gauss-Newton covariance s^2 (J^T J)^+ of the fitted x, with s^2 = |r|^2 / (n_data - p)
    the residual variance per datum; (covariance (p, p), standard errors (p,), correlation
    matrix (p, p), s^2). The pseudo-inverse comes from the SVD of J with its columns scaled to
    unit length, singular values below ``rcond`` times the largest dropped: positive
    semi-definite, so correlations stay within [-1, 1] where the data cannot tell values apart."""
    p = fit.x.size
    s2 = float(fit.residual @ fit.residual) / max(n_data - p, 1)
    norms = np.linalg.norm(fit.jacobian, axis=0)
    norms = np.where(norms > 0, norms, 1.0)
    _, sv, vt = np.linalg.svd(fit.jacobian / norms, full_matrices=False)
    keep = sv > rcond * sv[0]
    cov = s2 * (vt[keep].T / sv[keep] ** 2) @ vt[keep] / np.outer(norms, norms)
    se = np.sqrt(np.maximum(np.diag(cov), 0.0))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(se, se)
    return cov, se, corr, s2
