"""Rank-1 decomposition $M = b d^T$ by SVD with the uniqueness rule of seed 001.

Proposition 3.1, (3.10)-(3.13), applied to estimates as in (4.3)-(4.5c).
"""

import jax.numpy as jnp
from jaxtyping import Array, Float


def first_largest(x: Float[Array, " n"], *, rtol: float = 1e-12) -> Float[Array, ""]:
    r"""$\rho(x)$ of (3.10): the first component with the greatest magnitude.

    Components within a relative `rtol` of the maximum count as ties, so that
    round-off cannot move the choice to a later one.
    """
    mag = jnp.abs(x)
    index = jnp.argmax(mag >= jnp.max(mag) * (1.0 - rtol))
    return x[index]


def rank_one_decomposition(
    m: Float[Array, "n 4"],
) -> tuple[Float[Array, " n"], Float[Array, " 4"], Float[Array, " k"]]:
    r"""Eq. (4.5a-c): $\hat b = \operatorname{sign}(\gamma)\, \Gamma e_1 \sigma_1 /
    \|\Gamma e_1 \sigma_1\|$ and $\hat d = \operatorname{sign}(\gamma)\,
    \|\Gamma e_1 \sigma_1\|\, e_1^T \Sigma$, with $\gamma = \rho(\Gamma e_1
    \sigma_1)$.

    This is the unique factorisation $M = b d^T$ with $\sum_i b_i^2 = 1$ and
    $\rho(b) > 0$ (3.13) when $M$ has rank 1; for a noisy $\hat M$ it is the best
    rank-1 approximation (the singular values after $\sigma_1$ are dropped,
    Proposition 4.2).

    **Arguments:**

    - `m`: the matrix $M$ of (3.9), shape `(n, 4)`.

    **Returns:** `(b, d, singular_values)`; `singular_values` lets the caller
    judge how far $\hat M$ is from rank 1.
    """
    if m.ndim != 2 or m.shape[1] != 4:
        raise ValueError(f"M must have shape (n, 4) (3.9); got {m.shape}")
    gamma_mat, sigma, sigma_rows = jnp.linalg.svd(m, full_matrices=False)
    column = gamma_mat[:, 0] * sigma[0]  # Gamma [sigma_1 0 .. 0]^T
    norm = jnp.linalg.norm(column)  # equals sigma_1 (Gamma is orthogonal)
    sign = jnp.where(first_largest(column) >= 0, 1.0, -1.0)  # Eq. (4.5c)
    safe = jnp.where(norm > 0, norm, 1.0)
    b = sign * column / safe  # Eq. (4.5a)
    d = sign * norm * sigma_rows[0]  # Eq. (4.5b)
    return b, d, sigma
