"""A static map scaled at its output: $k F(v)$."""

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ._base import AbstractStaticNonlinearity


class Scaled(AbstractStaticNonlinearity):
    """$v \\mapsto \\text{gain} \\cdot F(v)$ (the $kF$ of seed 000's normalisation).

    ```python
    >>> Scaled(inner=Identity(), gain=2.0)(jnp.array([1.0]))
    Array([2.], dtype=float64)
    ```
    """

    inner: AbstractStaticNonlinearity
    gain: Float[Array, ""]

    def __init__(
        self, *, inner: AbstractStaticNonlinearity, gain: Float[ArrayLike, ""]
    ):
        self.inner = inner
        self.gain = jnp.asarray(gain, dtype=float)

    def __call__(self, v: Float[Array, "*shape"]) -> Float[Array, "*shape"]:
        return self.gain * self.inner(v)
