"""Shared pieces of the seed-001 parametrisations (discrete $B/A$, $b$ on a chart)."""

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float

from .._types import Params, Signal
from ..models import DiscreteTransferFunction
from ._parametrisation import AbstractParametrisation


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


class AbstractDiscreteParametrisation(AbstractParametrisation):
    """$\\theta = (a, \\delta, \\text{map})$ of a discrete plant of order $n$ =
    `len(b_ref)`: the $n$ coefficients of $A$, the $n - 1$ chart coordinates
    $\\delta$ of $b$ at `b_ref`, then the parameters of the map."""

    b_ref: eqx.AbstractVar[Float[Array, " n"]]

    @property
    def order(self) -> int:
        return self.b_ref.shape[0]

    def _ab_names(self) -> tuple[str, ...]:
        """`a1..an, b1..bn`: the names of the physical $(a, b)$."""
        n = self.order
        return tuple(f"a{i + 1}" for i in range(n)) + tuple(
            f"b{i + 1}" for i in range(n)
        )

    def _split(self, theta: Params):
        n = self.order
        return theta[:n], theta[n : 2 * n - 1], theta[2 * n - 1 :]
