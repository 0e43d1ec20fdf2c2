"""Small dense linear algebra in plain `jax.numpy` (no LAPACK custom calls)."""

import jax.numpy as jnp
from jaxtyping import Array, Float


def cholesky_solve(
    A: Float[Array, " n n"], b: Float[Array, " n *k"]
) -> Float[Array, " n *k"]:
    """Solve $A x = b$ for a symmetric positive-definite `A` by an unrolled Cholesky
    factorisation and two triangular sweeps.

    For the small systems of a damped Gauss-Newton step (n <= ~20). Written with
    `jax.numpy` arithmetic only: XLA's CPU LAPACK custom calls (`getrf`, `potrf`,
    `syevd`) were seen to hang when two devices ran them at once under jax 0.10,
    and under `vmap` this form is also faster for tiny n. A matrix that is not
    positive definite gives NaN, never a silent wrong answer.
    """
    n = A.shape[0]
    L = jnp.zeros_like(A)
    for j in range(n):
        col = A[j:, j] - L[j:, :j] @ L[j, :j]
        L = L.at[j:, j].set(col / jnp.sqrt(col[0]))
    x = b[:, None] if b.ndim == 1 else b
    y = jnp.zeros_like(x)
    for i in range(n):
        y = y.at[i].set((x[i] - L[i, :i] @ y[:i]) / L[i, i])
    z = jnp.zeros_like(x)
    for i in reversed(range(n)):
        z = z.at[i].set((y[i] - L[i + 1 :, i] @ z[i + 1 :]) / L[i, i])
    return z[:, 0] if b.ndim == 1 else z
