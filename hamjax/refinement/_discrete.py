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
    r"""All roots of $A(z) = 1 + a_1 z^{-1} + \dots$ inside the unit circle (the
    block's own traced `stable`)."""
    den = jnp.concatenate([jnp.ones(1), a])
    return DiscreteTransferFunction(jnp.ones(1), den).stable()
