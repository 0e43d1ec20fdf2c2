"""Saturation: the input clipped to [lower, upper]."""

import jax.numpy as jnp
from jaxtyping import Array, Float

from ..._checks import concrete
from ._base import AbstractBandNonlinearity


class Saturation(AbstractBandNonlinearity):
    """$F(v) = \\min(\\max(v, \\text{lower}), \\text{upper})$.

    ```python
    >>> Saturation(lower=-1.0, upper=2.0)(jnp.array([-3.0, 0.5, 3.0]))
    Array([-1. ,  0.5,  2. ], dtype=float64)
    ```
    """

    def __check_init__(self):
        lo, up = concrete(self.lower), concrete(self.upper)
        if lo is not None and up is not None and not lo < up:
            raise ValueError(f"Saturation needs lower < upper; got {lo}, {up}")

    def __call__(self, v: Float[Array, "*shape"]) -> Float[Array, "*shape"]:
        return jnp.clip(v, self.lower, self.upper)
