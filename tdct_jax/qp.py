"""The box-constrained quadratic program, solved exactly by enumerating active sets: no physics."""

from __future__ import annotations

import itertools

import jax
import jax.numpy as jnp
import numpy as np

from .linalg import solve_spd


def _patterns(n: int) -> np.ndarray:
    """Every active set of n box-constrained variables: 0 free, 1 at its lower, 2 at its upper bound."""
    return np.array(list(itertools.product((0, 1, 2), repeat=n)), dtype=np.int8).reshape(-1, n)


def box_qp(H, g, lo, hi, J=None, c=None):
    """argmin 1/2 s^T H s + g^T s over lo <= s <= hi (and J s = c when given), H positive
    definite, exactly: every active set is solved (fixed variables at their bounds) and the best
    feasible solution kept. Returns (s, multipliers of J s = c, whether a feasible one exists)."""
    n = g.shape[0]
    m = 0 if J is None else J.shape[0]
    tol = 1e-12 * (1.0 + jnp.max(jnp.abs(hi - lo)))

    def one(p):
        fixed = p > 0
        value = jnp.where(p == 1, lo, hi) * fixed
        keep = ~fixed
        A = jnp.where(keep[:, None] & keep[None, :], H, 0.0) + jnp.diag(fixed.astype(H.dtype))
        rhs = jnp.where(fixed, value, -(g + H @ value))
        if m:
            Jf = J * keep[None, :]
            K = jnp.block([[A, Jf.T], [Jf, -1e-14 * jnp.eye(m)]])
            sol = jnp.linalg.solve(K, jnp.concatenate([rhs, c - J @ value]))
            s, lam = sol[:n], sol[n:]
            consistent = jnp.max(jnp.abs(J @ s - c)) <= 1e-9 * (1.0 + jnp.max(jnp.abs(c)))
        else:
            s, lam, consistent = solve_spd(A, rhs), jnp.zeros(0), True
        ok = jnp.all(jnp.isfinite(s)) & jnp.all(s >= lo - tol) & jnp.all(s <= hi + tol) & consistent
        return s, lam, ok, 0.5 * s @ H @ s + g @ s

    s, lam, ok, q = jax.vmap(one)(jnp.asarray(_patterns(n)))
    k = jnp.argmin(jnp.where(ok, q, jnp.inf))
    return jnp.clip(s[k], lo, hi), lam[k], jnp.any(ok)
