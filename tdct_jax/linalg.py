"""Small dense linear algebra written out for XLA: no physics.

A 6x6 solve inside every right-hand-side evaluation is too small for LAPACK: the call overhead
dominates, and under ``vmap`` each matrix is a separate call. Unrolled into scalar operations,
the solve becomes elementwise arithmetic that XLA fuses and vectorises across a batch.
"""

import jax.numpy as jnp


def solve_spd(A, b):
    """Solves A x = b for a symmetric positive definite A (..., n, n) by LDL^T without pivoting.

    Unrolled over the static n; b has shape (..., n). Only the lower triangle of A is read.
    """
    n = A.shape[-1]
    return jnp.stack(solve_spd_entries(A, [b[..., i] for i in range(n)]), axis=-1)


def solve_spd_entries(A, b: list) -> list:
    """``solve_spd`` on the entries of b, a list of n arrays (...,), returning x's entries: no array
    holds a whole b or x (under ``vmap``, each would be one array with the batch inside)."""
    n = A.shape[-1]
    L = [[None] * n for _ in range(n)]
    D = [None] * n
    for j in range(n):
        D[j] = A[..., j, j] - sum(L[j][k] ** 2 * D[k] for k in range(j))
        for i in range(j + 1, n):
            L[i][j] = (A[..., i, j] - sum(L[i][k] * L[j][k] * D[k] for k in range(j))) / D[j]
    z = [None] * n
    for i in range(n):
        z[i] = b[i] - sum(L[i][k] * z[k] for k in range(i))
    x = [None] * n
    for i in reversed(range(n)):
        x[i] = z[i] / D[i] - sum(L[k][i] * x[k] for k in range(i + 1, n))
    return x
