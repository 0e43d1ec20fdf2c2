"""Batch least squares on the regression (3.8a): the closed-form comparator."""

import jax.numpy as jnp
from jaxtyping import Array, Float

from ..._types import Signal


def batch_least_squares(phi: Float[Array, "time p"], y: Signal) -> Float[Array, " p"]:
    r"""$\hat\Theta = \arg\min_\Theta \sum_t (y(t) - \Phi(t)^T \Theta)^2$ on the
    regressors of (3.8b).

    Solved by the column-equilibrated normal equations plus one step of
    iterative refinement: $O(N p^2)$ like a QR, but far faster than XLA's CPU
    SVD/QR of a tall matrix under `vmap`, and accurate to round-off for the
    condition numbers of a persistently exciting $\Phi$. A rank-deficient $\Phi$
    (input not exciting) gives non-finite values.

    With noise this is the equation-error estimate: $\Phi$ holds past noisy
    outputs, so it is biased unless $\eta = A(q^{-1}) z$ is uncorrelated with them.
    """
    if phi.ndim != 2 or y.shape != phi.shape[:1]:
        raise ValueError(
            f"need phi (time, p) and y (time,); got {phi.shape}, {y.shape}"
        )
    scale = jnp.sqrt(jnp.sum(phi**2, axis=0))
    scale = jnp.where(scale > 0, scale, 1.0)
    scaled = phi / scale[None, :]
    gram = scaled.T @ scaled
    x = jnp.linalg.solve(gram, scaled.T @ y)
    x = x + jnp.linalg.solve(gram, scaled.T @ (y - scaled @ x))  # refinement
    return x / scale
