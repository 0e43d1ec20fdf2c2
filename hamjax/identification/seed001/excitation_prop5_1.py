"""Persistent excitation of the regressors (3.8b): Proposition 5.1 of seed 001."""

import jax.numpy as jnp
from jaxtyping import Array, Float


def information_matrix(phi: Float[Array, "time p"]) -> Float[Array, "p p"]:
    r"""$\frac1N \sum_{t} \Phi(t) \Phi(t)^T$ over the rows of `phi`."""
    return phi.T @ phi / phi.shape[0]


def excitation_level(phi: Float[Array, "time p"]) -> Float[Array, ""]:
    r"""$\lambda_{\min}$ of the information matrix, normalised by $\lambda_{\max}$.

    Positive (well above round-off, $\sim 10^{-12}$) over a window of the
    sequence (5.1) when $\Phi$ is persistently exciting (Proposition 5.1);
    zero up to round-off for an input that does not excite $\Theta^*$.
    """
    eig = jnp.linalg.eigvalsh(information_matrix(phi))
    return eig[0] / jnp.where(eig[-1] > 0, eig[-1], 1.0)
