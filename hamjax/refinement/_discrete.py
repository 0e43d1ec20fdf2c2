"""Shared pieces of the seed-001 parametrisations (discrete $B/A$, $b$ on a chart)."""

import jax.numpy as jnp
from jaxtyping import Array, Bool, Float

from .._types import Signal
from ..models import DiscreteTransferFunction


def discrete_response(
    a: Float[Array, " n"], b: Float[Array, " n"], u: Signal
) -> Signal:
    """$y = B(q^{-1})/A(q^{-1})\\,u$ with $B = b_1 q^{-1} + \\dots$, Eq. (2.1a)."""
    num = jnp.concatenate([jnp.zeros(1), b])
    den = jnp.concatenate([jnp.ones(1), a])
    return DiscreteTransferFunction(num, den).response(u)


def discrete_stable(a: Float[Array, " n"]) -> Bool[Array, ""]:
    """All roots of $A(z)$ inside the unit circle (companion-matrix eigenvalues)."""
    n = a.shape[0]
    companion = jnp.zeros((n, n)).at[0, :].set(-a)
    if n > 1:
        companion = companion.at[1:, :-1].set(jnp.eye(n - 1))
    return jnp.all(jnp.abs(jnp.linalg.eigvals(companion)) < 1.0) & jnp.all(
        jnp.isfinite(a)
    )
